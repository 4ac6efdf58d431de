"""Calling conventions for user functions.

Users write `L(q, qdot)`, `L(q, qdot, t)` or `L(q, qdot, t, args)` (and likewise for
`H`, forces, observables). lagjax always calls them as `f(x, y, t, args)`; this module
counts a function's positional parameters once, at construction, and adapts the call.
It also holds the trace-time checks shared by every derivation: a scalar result and
matching structures for `q` and its partner (`qdot` or `p`).
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp

from lagjax.mechanics.functions import StaticFunction

_POSITIONAL = (
    inspect.Parameter.POSITIONAL_ONLY,
    inspect.Parameter.POSITIONAL_OR_KEYWORD,
)


def positional_arity(fn: Callable, *, minimum: int, maximum: int, what: str) -> int:
    """Number of leading positional arguments `fn` accepts, clipped to `maximum`.

    `*args` counts as accepting `maximum`. Raises `TypeError` naming `what` when `fn`
    accepts fewer than `minimum`.
    """
    if not callable(fn):
        raise TypeError(f"{what} must be callable, got {type(fn).__name__}")
    try:
        params = inspect.signature(fn).parameters.values()
    except (TypeError, ValueError):
        # Builtins and some C-extension callables hide their signature; assume full.
        return maximum
    if any(p.kind is inspect.Parameter.VAR_POSITIONAL for p in params):
        return maximum
    count = sum(p.kind in _POSITIONAL for p in params)
    if count < minimum:
        raise TypeError(
            f"{what} must accept at least {minimum} positional arguments, "
            f"but its signature is {inspect.signature(fn)}"
        )
    return min(count, maximum)


def call_with_arity(fn: Callable, arity: int, *arguments: Any) -> Any:
    """Call `fn` with the first `arity` of `arguments`.

    lagjax traces user functions with abstract values (under `jit`, `grad`,
    `vmap`), so Python control flow on them and NumPy calls fail inside JAX with a
    long message about tracers. Those errors are re-raised here as a `TypeError`
    that names the user's function and the fix (`jnp.where`/`lax.cond`, `jnp`).
    """
    try:
        return fn(*arguments[:arity])
    except jax.errors.TracerBoolConversionError as error:
        raise TypeError(
            f"{_name_of(fn)} uses a Python `if`, `while`, `and`/`or` or `bool()` on a "
            "value that depends on its arguments (q, q̇, p, t, args); lagjax traces it "
            "with abstract values, so the branch cannot be chosen in Python. Write "
            "the branch as jnp.where(condition, a, b) (both sides are evaluated) or "
            "jax.lax.cond(condition, f_true, f_false, operands)"
        ) from error
    except jax.errors.TracerArrayConversionError as error:
        raise TypeError(
            f"{_name_of(fn)} calls NumPy (np.cos, np.array, math.sin, float(), …) on "
            "a value that depends on its arguments; lagjax differentiates and "
            "compiles it with JAX, so use jax.numpy instead: import jax.numpy as jnp "
            "and write jnp.cos, jnp.array, …"
        ) from error
    except jax.errors.ConcretizationTypeError as error:
        raise TypeError(
            f"{_name_of(fn)} needs the concrete value of one of its arguments (a "
            "float(), int(), math function, shape, Python index or loop bound of q, q̇, p, t or "
            "args); under lagjax's tracing only jax.numpy operations on them work: "
            "use jnp functions and fixed shapes"
        ) from error


def _name_of(fn: Callable) -> str:
    """'the function name (file.py:line)' for messages about a user function."""
    if isinstance(fn, StaticFunction):  # how a system stores a plain function
        fn = fn.function
    name = getattr(fn, "__qualname__", None) or type(fn).__name__
    code = getattr(fn, "__code__", None)
    where = (
        ""
        if code is None
        else f" ({code.co_filename.rsplit('/', 1)[-1]}:{code.co_firstlineno})"
    )
    return f"the function {name}{where}"


def check_scalar(value: Any, what: str) -> jax.Array:
    """Trace-time check that a user function returned one real scalar."""
    if value is None:
        raise ValueError(
            f"{what} returned None: it must return a scalar (is a `return` missing?)"
        )
    try:
        value = jnp.asarray(value)
    except TypeError as error:
        raise ValueError(
            f"{what} must return a real scalar, but returned a {type(value).__name__}"
        ) from error
    if value.shape != ():
        raise ValueError(
            f"{what} must return a scalar, but returned an array of shape {value.shape}"
        )
    if not jnp.issubdtype(value.dtype, jnp.floating):
        raise ValueError(f"{what} must return a real float, but returned {value.dtype}")
    return value


def check_same_structure(x: Any, y: Any, x_name: str, y_name: str) -> None:
    """Trace-time check that two pytrees match in structure and leaf shapes."""
    x_leaves, x_def = jax.tree_util.tree_flatten(x)
    y_leaves, y_def = jax.tree_util.tree_flatten(y)
    if x_def != y_def:
        raise ValueError(
            f"{x_name} and {y_name} must have the same pytree structure, "
            f"got {x_def} and {y_def}"
        )
    for a, b in zip(x_leaves, y_leaves):
        if jnp.shape(a) != jnp.shape(b):
            raise ValueError(
                f"{x_name} and {y_name} must have the same shapes, "
                f"got {jnp.shape(a)} and {jnp.shape(b)}"
            )
