"""What a singular matrix means to the caller: the message, a run-time error
attached to a value, and which test to run (an error on concrete values, NaN
poisoning under a trace). The solves (`small_solves`) return the verdict; this
module turns it into the library's behaviour."""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
from jax.core import Tracer


def singular_message_for(what: str) -> str:
    """The error message for a singular matrix described by `what`."""
    return (
        f"{what} is singular at this state, so it cannot be inverted. Is the "
        "function degenerate (e.g. L linear in q̇), or is the state at a coordinate "
        "singularity (e.g. Euler-angle gimbal lock)?"
    )


def raise_if_singular(x, singular: jax.Array, what: str):
    """Attach a run-time error to `x` when `singular` is true (works inside jit)."""
    return eqx.error_if(x, singular, singular_message_for(what))


def singular_check(check: bool | str | None, *trees: Any) -> bool | str:
    """The singular-matrix test to run: `check` itself when given, else an error on
    concrete values and NaN poisoning when any leaf is traced (a branch per
    evaluation would split a fused integration step)."""
    if check is not None:
        return check
    traced = any(isinstance(leaf, Tracer) for leaf in jax.tree_util.tree_leaves(trees))
    return "nan" if traced else True
