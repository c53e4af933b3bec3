"""A guard for the loading tests (``test_load_without_init``, the scorer's): torch patched
so that loading fails the moment it touches torch's global random generator."""

from __future__ import annotations

import torch
from torch import nn

RANDOM_FUNCTIONS = ("rand", "randn", "randint", "randperm", "normal", "bernoulli", "multinomial")
RANDOM_METHODS = ("uniform_", "normal_", "random_", "bernoulli_", "exponential_", "geometric_",
                  "cauchy_", "log_normal_")  # fmt: skip


def refuse_global_randomness(monkeypatch) -> list[str]:
    """Patch torch so that forking, saving or restoring its global generator raises, and so
    that a random draw or an ``nn.init`` function on a tensor with data raises too (on the
    meta device they are shapes only: nothing drawn). -> the ``nn.init`` calls seen."""
    seen: list[str] = []
    with torch.device("meta"):  # torch lists its factory functions on first use: before the
        torch.empty(0)  # patches below, so that it knows torch.randn and not the wrapper

    def refused(name):
        def fail(*args, **kwargs):
            raise AssertionError(f"loading called {name}")

        return fail

    for module, name in [(torch.random, "fork_rng"), (torch.random, "set_rng_state"),
                         (torch, "set_rng_state"), (torch.random, "get_rng_state"),
                         (torch, "get_rng_state"), (torch, "manual_seed"),
                         (torch.random, "manual_seed"), (torch, "seed")]:  # fmt: skip
        monkeypatch.setattr(module, name, refused(f"torch.{name}"))

    def meta_only(name, original, tensor_of):
        def wrapper(*args, **kwargs):
            out = original(*args, **kwargs)
            tensor = tensor_of(args, out)
            if kwargs.get("generator") is None and not tensor.is_meta:
                raise AssertionError(f"loading drew from torch's global generator ({name})")
            return out

        return wrapper

    for name in nn.init.__all__:
        original = getattr(nn.init, name)

        def record(*args, __name=name, __original=original, **kwargs):
            seen.append(__name)
            tensors = [t for t in (*args, *kwargs.values()) if isinstance(t, torch.Tensor)]
            if any(not t.is_meta for t in tensors):
                raise AssertionError(f"loading initialised a tensor with data (nn.init.{__name})")
            return __original(*args, **kwargs)

        monkeypatch.setattr(nn.init, name, record)
    for name in RANDOM_FUNCTIONS:
        monkeypatch.setattr(torch, name, meta_only(name, getattr(torch, name),
                                                   lambda args, out: out))  # fmt: skip
    for name in RANDOM_METHODS:
        monkeypatch.setattr(torch.Tensor, name, meta_only(name, getattr(torch.Tensor, name),
                                                          lambda args, out: args[0]))  # fmt: skip
    return seen


def tensors_of(*modules: nn.Module) -> list[tuple[str, torch.Tensor]]:
    """Every parameter and buffer (non-persistent ones included) of ``modules``."""
    return [(f"{i}.{name}", t) for i, m in enumerate(modules)
            for name, t in [*m.named_parameters(), *m.named_buffers()]]  # fmt: skip
