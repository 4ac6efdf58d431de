"""Compensated (Kahan) summation for long fixed-step runs.

Adding a small increment to a large state loses the low-order bits of the increment
at every step; over 10⁶ steps that round-off accumulates as a random walk in the
state and, worse, as a linear drift of invariants. Carrying the lost bits in a
compensation term (Kahan 1965; Higham, *Accuracy and Stability of Numerical
Algorithms*, §4.3) makes the accumulated error behave like Brouwer's law (∝ √steps).
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp


def compensated_add(y: Any, increment: Any, compensation: Any) -> tuple[Any, Any]:
    """Return `(y + increment, new_compensation)` with Kahan's compensated sum.

    All three arguments are pytrees of the same structure. Start with
    `compensation = zeros_like(y)` and feed back what this returns.
    """

    def add(y_leaf, inc_leaf, comp_leaf):
        corrected = inc_leaf + comp_leaf
        total = y_leaf + corrected
        return total, corrected - (total - y_leaf)

    outer = jax.tree_util.tree_structure(y)
    if outer.num_leaves == 0:  # nothing to add (e.g. parameters with no arrays)
        return y, compensation
    pairs = jax.tree_util.tree_map(add, y, increment, compensation)
    inner = jax.tree_util.tree_structure((0, 0))
    total, new_compensation = jax.tree_util.tree_transpose(outer, inner, pairs)
    return total, new_compensation


def add_to_state(y: Any, increment: Any, compensation: Any) -> tuple[Any, Any]:
    """`(y + increment, compensation)`: Kahan-compensated unless `compensation` is
    None (a solver built with `compensated=False`)."""
    if compensation is None:
        return jax.tree_util.tree_map(jnp.add, y, increment), None
    return compensated_add(y, increment, compensation)


def zero_compensation(y: Any) -> Any:
    """The compensation to start a run with: zeros shaped like `y`."""
    return jax.tree_util.tree_map(jnp.zeros_like, y)
