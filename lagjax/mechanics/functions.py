"""A user's function (L, H, T, V, a force, a constraint) as a field of a system.

A plain Python function is part of a system's *structure*: it is stored static, so
two systems of the same function compare equal and share their compilation. An
equinox Module — a neural network, or any callable with array leaves — is part of
its *data*: its arrays are pytree children of the system, so `eqx.filter_grad`,
`jax.vmap` and `jax.jit` reach them. `eqx.field(converter=as_system_function)` makes
both work from one declaration; before it, every function was static, and a network
used as H was silently frozen (its gradient exactly 0, with equinox's "JAX array set
as static" warning).

A Module that itself marks an array field static (`eqx.field(static=True)`) would be
frozen in the same way — its array is structure, not data, and its gradient is
absent — so such a Module is refused here, with the field named, rather than
accepted with equinox's warning alone.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax


class StaticFunction(eqx.Module):
    """A plain function held as static structure; calling it calls the function."""

    function: Callable = eqx.field(static=True)

    def __call__(self, *args: Any) -> Any:
        return self.function(*args)


def _is_module(value: Any) -> bool:
    return isinstance(value, eqx.Module)


def static_array_field(module: eqx.Module, path: str) -> str | None:
    """The dotted path of the first static field holding a JAX array in `module` or
    any Module inside it, else None."""
    for field in dataclasses.fields(module):
        value = getattr(module, field.name, None)
        where = f"{path}.{field.name}"
        if field.metadata.get("static", False):
            leaves = jax.tree_util.tree_leaves(value)
            if any(isinstance(leaf, jax.Array) for leaf in leaves):
                return where
            continue
        for inner in jax.tree_util.tree_leaves(value, is_leaf=_is_module):
            if _is_module(inner):
                found = static_array_field(inner, where)
                if found is not None:
                    return found
    return None


def as_system_function(function: Callable | None) -> Any:
    """`function` as a system stores it: Modules as they are (their arrays are
    trainable leaves), anything else wrapped in a `StaticFunction`.

    A Module with a JAX array in a static field is refused (`ValueError` naming the
    field): that array would be frozen, its gradient silently absent."""
    if function is None:
        return function
    if isinstance(function, eqx.Module):
        field = static_array_field(function, type(function).__name__)
        if field is not None:
            raise ValueError(
                f"{field} is a JAX array in a static field (eqx.field(static=True)): "
                "as part of a system it would be frozen, its gradient silently "
                "absent. Declare it as an ordinary field (it is then a trainable, "
                "vmappable leaf), or pass it through `args`."
            )
        return function
    return StaticFunction(function)
