"""trajpref: human trajectory prediction with a diffusion model refined by RL from a
quantified human preference (the diffusion score).

Shape vocabulary used in comments throughout the package:
    B scenes, P agents (per scene), N agents packed across a batch, K samples,
    T time (T_h history, T_f future), D = 2 coordinates.
"""

import os

from trajpref.errors import TrajprefError

# PyTorch runs bfloat16 matrix products on the CPU through oneDNN, which builds (JIT-compiles)
# a kernel for every new shape and keeps the last 1,024 of them. Our batches pack a varying
# number of agents, so a training run meets thousands of shapes and, with the default, keeps
# rebuilding kernels it has built before: with a larger cache, bf16 generator steps ran 1.55x
# (hotel), 1.29x (zara1) and 1.05x (eth) faster on a 2-core CPU (docs/pretraining.md,
# "oneDNN's kernel cache"). It has to be set before the process's first oneDNN product; a
# value the user set is kept.
ONEDNN_CACHE_CAPACITY = 16384
os.environ.setdefault("ONEDNN_PRIMITIVE_CACHE_CAPACITY", str(ONEDNN_CACHE_CAPACITY))

__version__ = "0.1.0"
__all__ = ["ONEDNN_CACHE_CAPACITY", "TrajprefError", "__version__"]
