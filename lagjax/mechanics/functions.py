"""A user's function (L, H, T, V, a force, a constraint) as a field of a system.

A plain Python function is part of a system's *structure*: it is stored static, so
two systems of the same function compare equal and share their compilation. An
equinox Module — a neural network, or any callable with array leaves — is part of
its *data*: its arrays are pytree children of the system, so `eqx.filter_grad`,
`jax.vmap` and `jax.jit` reach them. `eqx.field(converter=as_system_function)` makes both work from one
declaration; before it, every function was static, and a network used as H was
silently frozen (its gradient exactly 0, with equinox's "JAX array set as static"
warning).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx


class StaticFunction(eqx.Module):
    """A plain function held as static structure; calling it calls the function."""

    function: Callable = eqx.field(static=True)

    def __call__(self, *args: Any) -> Any:
        return self.function(*args)


def as_system_function(function: Callable | None) -> Any:
    """`function` as a system stores it: Modules as they are (their arrays are
    trainable leaves), anything else wrapped in a `StaticFunction`."""
    if function is None or isinstance(function, eqx.Module):
        return function
    return StaticFunction(function)
