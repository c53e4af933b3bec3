"""Exceptions that the CLI turns into one-line messages and a non-zero exit status."""

from __future__ import annotations

from pathlib import Path


class TrajprefError(Exception):
    """Base class for errors a user can fix (bad input, bad options)."""


class DataError(TrajprefError, ValueError):
    """Malformed or unusable input data. Names the file, and the line when there is one."""

    def __init__(self, message: str, path: str | Path | None = None, line: int | None = None):
        self.path = None if path is None else str(path)
        self.line = line
        where = ""
        if path is not None:
            where = f"{path}:{line}: " if line is not None else f"{path}: "
        super().__init__(where + message)


class ConfigError(TrajprefError, ValueError):
    """An invalid configuration value."""


class RewardError(TrajprefError, ValueError):
    """A fine-tuning reward (``trajpref.rl.register_reward``) returned something other than a
    finite [M, N, T_f] tensor."""
