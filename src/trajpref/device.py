"""Device selection: never hard-code a device."""

from __future__ import annotations

import torch

from trajpref.errors import ConfigError

CHOICES = "use 'auto', 'cpu' or 'cuda[:i]' (a name or a torch.device)"
"""What ``resolve_device`` takes, for its messages."""


def resolve_device(name: str | torch.device = "auto") -> torch.device:
    """``auto`` picks CUDA when available, else the CPU; ``cpu``, ``cuda[:i]`` and ``mps``,
    as names or ``torch.device`` objects, are checked against this machine. A device it
    lacks (no CUDA GPU, no such GPU index, no MPS) or any other value (None, a number, an
    unknown name) is a one-line ``ConfigError``."""
    if isinstance(name, str) and name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if isinstance(name, torch.device):
        device = name
    elif isinstance(name, str):
        try:
            device = torch.device(name)
        except RuntimeError:
            raise ConfigError(f"unknown device {name!r}; {CHOICES}") from None
    else:
        raise ConfigError(f"device: expected a name or a torch.device, got {name!r}; {CHOICES}")
    if device.type == "cpu":
        return device
    if device.type == "cuda":
        if not torch.cuda.is_available():
            raise ConfigError("device 'cuda' requested but no CUDA GPU is available")
        count = torch.cuda.device_count()
        if device.index is not None and device.index >= count:
            raise ConfigError(f"device {str(device)!r} requested but this machine has {count} "
                              f"CUDA GPU(s), cuda:0..cuda:{count - 1}")  # fmt: skip
        return device
    if device.type == "mps":
        mps = getattr(torch.backends, "mps", None)
        if mps is None or not mps.is_available():
            raise ConfigError(f"device 'mps' requested but no MPS (Apple GPU) is available; "
                              f"{CHOICES}")  # fmt: skip
        return device
    raise ConfigError(f"unsupported device {str(device)!r}; {CHOICES}")
