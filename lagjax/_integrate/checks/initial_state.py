"""Refuse a bad initial state before anything is traced, naming what is wrong.

The `y0` half of `simulate`'s input checks (`lagjax._integrate.checks.inputs` has the rest and
its table of refusals): a pair of matching real arrays — q and its partner (q̇ or p)
of one structure and shape, finite, float32/64 (integers converted, half precision
refused); a rigid body's (quaternion of shape (4,), nonzero; Π of shape (3,)); a
scene's state of the shapes its `initial_state()` has; a constrained Lagrangian's
start on its constraints. Values are checked only when concrete (not traced).
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.core import Tracer

from lagjax._core.precision import cast_floats
from lagjax._core.system import AbstractSystem
from lagjax.mechanics.constraints import refuse_start_off_constraints
from lagjax.mechanics.lagrangian import Lagrangian
from lagjax.rigid.body import RigidBody
from lagjax.rigid.quaternion import check_nonzero_quaternion
from lagjax.scenes.base import AbstractScene


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
    if isinstance(system, RigidBody):
        y0 = (_checked_quaternion(first, second), second)
    else:
        _check_partners(system, first, second)
    _check_finite(y0)
    return _floated(y0)


def check_constrained_start(
    system: AbstractSystem, y0: Any, t0: Any, args: Any, dtype: Any
) -> None:
    """A constrained Lagrangian's start must lie on its constraints.

    Checked here, on concrete values in the run's `dtype`, because the compiled run
    sees traced values and could only attach the error at run time, without the
    residuals in the message. `system` and `args` are the resolved ones
    (`AbstractSystem.resolve`).
    """
    if not isinstance(system, Lagrangian) or system.constraints is None:
        return
    q0, qdot0 = cast_floats(tuple(y0), dtype)
    constraints = cast_floats(system.constraints, dtype)
    refuse_start_off_constraints(constraints, q0, qdot0, t0, cast_floats(args, dtype))


def check_scene_state(scene: AbstractScene, y0: Any) -> None:
    """A scene knows its state's shapes: those of `scene.initial_state()`."""
    expected = jax.eval_shape(scene.initial_state)
    got = jax.tree_util.tree_map(jnp.shape, tuple(y0))
    want = jax.tree_util.tree_map(lambda x: x.shape, tuple(expected))
    if got != want:
        raise ValueError(
            f"{type(scene).__name__}'s state has shapes {want} (as "
            f"scene.initial_state() gives), got {got}; start from "
            "scene.initial_state() and change its values"
        )


def _check_partners(system: AbstractSystem, q: Any, second: Any) -> None:
    partner = "p0" if system.second_is_momentum else "qdot0"
    q_leaves, q_tree = jax.tree_util.tree_flatten(q)
    s_leaves, s_tree = jax.tree_util.tree_flatten(second)
    if q_tree != s_tree:
        raise ValueError(
            f"q0 and {partner} must have the same structure, got {q_tree} and "
            f"{s_tree}: give {partner} one entry per coordinate of q0"
        )
    for a, b in zip(q_leaves, s_leaves):
        if jnp.shape(a) != jnp.shape(b):
            raise ValueError(
                f"q0 and {partner} must have the same shapes, got {jnp.shape(a)} and "
                f"{jnp.shape(b)}: give {partner} one entry per coordinate of q0"
            )


def _checked_quaternion(quaternion: Any, momentum: Any) -> Any:
    if jnp.shape(quaternion) != (4,) or jnp.shape(momentum) != (3,):
        raise ValueError(
            "a RigidBody's y0 is (quaternion of shape (4,), body angular momentum of "
            f"shape (3,)), got shapes {jnp.shape(quaternion)} and "
            f"{jnp.shape(momentum)}; RigidBody.state_from_angular_velocity builds one"
        )
    return check_nonzero_quaternion(quaternion, "y0's quaternion")


def _check_leaf_types(y0: Any) -> None:
    leaves = jax.tree_util.tree_leaves(y0)
    if not leaves:
        raise ValueError("y0 has no numbers in it: pass (q0, qdot0) or (q0, p0)")
    for leaf in leaves:
        dtype = jnp.result_type(leaf)
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
