"""Refuse a bad initial state before anything is traced, naming what is wrong.

The `y0` half of `simulate`'s input checks (`lagjax._integrate.checks.inputs` has the rest and
its table of refusals): a pair of matching real arrays — q and its partner (q̇ or p)
of one structure and shape, at least one coordinate, finite, float32/64 (integers
converted, half precision refused); a rigid body's (quaternion of shape (4,), nonzero; Π of shape (3,)); a
scene's state of the shapes its `initial_state()` has; a constrained Lagrangian's
start on its constraints. Values are checked only when concrete (not traced).
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.core import Tracer

from lagjax._core.system import AbstractSystem


def check_initial_state(system: AbstractSystem, y0: Any) -> Any:
    """`y0` is a pair of matching real arrays (a rigid body: (quaternion, Π)).

    Returns `y0` with integer leaves converted to the run's float type.
    """
    if not isinstance(y0, (tuple, list)) or len(y0) != 2:
        raise TypeError(
            f"y0 must be a pair: (q0, qdot0) for a Lagrangian, (q0, p0) for a "
            f"Hamiltonian (a rigid body: (quaternion, body momentum)); got "
            f"{_describe(y0)}"
        )
    first, second = y0
    _check_leaf_types(y0)
    _check_has_coordinates(first)
    y0 = system.checked_state_pair(first, second)
    _check_finite(y0)
    return _floated(y0)


def _check_leaf_types(y0: Any) -> None:
    leaves = jax.tree_util.tree_leaves(y0)
    if not leaves:
        raise ValueError("y0 has no numbers in it: pass (q0, qdot0) or (q0, p0)")
    for leaf in leaves:
        dtype = _dtype_of_number(leaf)
        if dtype == jnp.bool_:
            raise TypeError("y0 contains booleans; pass numbers (floats)")
        if jnp.issubdtype(dtype, jnp.complexfloating):
            raise TypeError(
                f"y0 contains complex numbers ({dtype}); coordinates and momenta are "
                "real: split a complex amplitude into two real coordinates"
            )
        if jnp.issubdtype(dtype, jnp.floating) and jnp.finfo(dtype).bits < 32:
            raise TypeError(
                f"y0 is {dtype}, which carries 3 significant digits: no stopping "
                "test of lagjax's solves can be met and is refused (not promoted). "
                "Pass float32 or float64: y0 = jax.tree.map(lambda x: "
                "x.astype(jnp.float32), y0)"
            )
        if not jnp.issubdtype(dtype, jnp.number):
            raise TypeError(f"y0 must hold numbers, got dtype {dtype}")


def _dtype_of_number(leaf: Any) -> Any:
    """The dtype of a numeric leaf; a string ("float32" reads as a dtype name),
    bytes or another object is refused by name."""
    if not isinstance(leaf, (str, bytes)):
        try:
            return jnp.result_type(leaf)
        except TypeError:
            pass
    raise TypeError(
        f"y0 must hold numbers, got {type(leaf).__name__} {leaf!r:.40}; pass floats "
        "or arrays (a number read from text: float(text))"
    )


def _check_has_coordinates(q0: Any) -> None:
    """q0 must hold at least one number: a system of no coordinates has no motion,
    and the loops' reductions (the largest |y|, a matrix of size 0) have no
    identity to start from."""
    sizes = [np.size(leaf) for leaf in jax.tree_util.tree_leaves(q0)]
    if sum(sizes) == 0:
        shapes = [tuple(np.shape(x)) for x in jax.tree_util.tree_leaves(q0)]
        raise ValueError(
            f"q0 has no coordinates (shape {shapes[0] if len(shapes) == 1 else shapes}"
            "): a system needs at least one; pass q0 with one entry per coordinate, "
            "e.g. jnp.array([0.1]) for one (an empty array often comes from slicing "
            "or from jnp.zeros(n) with n = 0)"
        )


def _check_finite(y0: Any) -> None:
    paths = jax.tree_util.tree_flatten_with_path(y0)[0]
    for path, leaf in paths:
        if isinstance(leaf, Tracer):
            continue
        values = np.asarray(leaf)
        if not np.all(np.isfinite(values)):
            name = "y0" + jax.tree_util.keystr(path)
            raise ValueError(
                f"{name} contains a non-finite value (NaN or inf): {values}; the "
                "initial state must be finite"
            )


def _floated(y0: Any) -> Any:
    """Integer leaves as floats: as float as the other leaves, else the default."""
    leaves = jax.tree_util.tree_leaves(y0)
    floats = [x for x in leaves if jnp.issubdtype(jnp.result_type(x), jnp.floating)]
    dtype = jnp.result_type(*floats) if floats else jnp.result_type(float)

    def as_float(x):
        if jnp.issubdtype(jnp.result_type(x), jnp.integer):
            return jnp.asarray(x, dtype=dtype)
        return x

    return type(y0)(jax.tree_util.tree_map(as_float, tuple(y0)))


def _describe(value: Any) -> str:
    if isinstance(value, (tuple, list)):
        return f"a {type(value).__name__} of length {len(value)}"
    shape = getattr(value, "shape", None)
    if shape is not None:
        return f"an array of shape {tuple(shape)} (a pair is needed: split it)"
    return f"a {type(value).__name__}"
