"""trajpref: human trajectory prediction with a diffusion model refined by RL from a
quantified human preference (the diffusion score).

Shape vocabulary used in comments throughout the package:
    B scenes, P agents (per scene), N agents packed across a batch, K samples,
    T time (T_h history, T_f future), D = 2 coordinates.
"""

from trajpref.errors import TrajprefError

__version__ = "0.1.0"
__all__ = ["TrajprefError", "__version__"]
