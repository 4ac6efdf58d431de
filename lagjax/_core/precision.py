"""Working precision of a run: the floating dtype of the initial state rules.

A run is as precise as its state. `simulate` reads the floating dtype of `y0`
(float64 for Python numbers with x64 enabled, float32 for float32 arrays) and
carries every floating input — times, the system's array fields, `args` (a scene's
parameters) — in that dtype, so a float32 run stays float32 from end to end instead
of being promoted back to float64 by a float64 time or parameter (diffrax promotes
the state to the dtype of the times; a `lax.scan` refuses the promotion outright).

Constants captured in a user's closure cannot be reached; vector fields cast their
output to the state's dtype (`match_dtypes`) so that such a constant widens one
evaluation, never the state.

References: Goldberg, *What every computer scientist should know about
floating-point arithmetic*, ACM Comput. Surv. 23, 5 (1991); Hairer, Lubich &
Wanner, *Geometric Numerical Integration*, 2nd ed., Springer (2006), §VIII.5
(round-off in long integrations).
"""

from __future__ import annotations

from typing import Any, TypeVar

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx


def working_dtype(y0: Any) -> np.dtype:
    """The floating dtype a run from `y0` works in.

    Integer leaves count as the default float (a start at `q0 = 1` is not an
    integer run); Python floats are weakly typed and give way to arrays.
    """
    leaves = jax.tree_util.tree_leaves(y0)
    if not leaves:
        raise ValueError("y0 has no array leaves: pass (q0, qdot0) or (q0, p0)")
    dtype = jnp.result_type(*leaves, 0.0)
    if not jnp.issubdtype(dtype, jnp.floating):
        raise TypeError(
            f"y0 must be real floating point (or integer) numbers, got dtype {dtype}"
        )
    return np.dtype(dtype)


def _is_float_array(x: Any) -> bool:
    return isinstance(x, (jax.Array, np.ndarray, np.generic)) and jnp.issubdtype(
        x.dtype, jnp.floating
    )


Tree = TypeVar("Tree")


def cast_floats(tree: Tree, dtype: Any) -> Tree:
    """`tree` with every floating array leaf cast to `dtype` (others untouched).

    Works on any pytree, equinox Modules included (a scene, a `RigidBody`): their
    functions and static fields are left alone.
    """
    return jax.tree_util.tree_map(
        lambda x: jnp.asarray(x, dtype=dtype) if _is_float_array(x) else x, tree
    )


def python_floats_as_arrays(tree: Tree, dtype: Any) -> Tree:
    """`tree` with every Python float (and complex) leaf as a 0-d NumPy array of
    `dtype` (complex: its complex partner); ints, bools and everything else as
    they are.

    Why: a compiled call (`equinox.filter_jit`) treats non-array leaves as static,
    so each new Python float in `y0` or `args` compiled a new program (twenty
    amplitudes as floats: 5.0 s; as arrays: 0.28 s). Ints stay: a user's L may use
    one as a shape or a loop count.
    """
    complex_dtype = np.result_type(dtype, np.complex64)

    def convert(x):
        if isinstance(x, bool) or not isinstance(x, (float, complex)):
            return x
        return np.asarray(x, dtype=complex_dtype if isinstance(x, complex) else dtype)

    return jax.tree_util.tree_map(convert, tree)


def match_dtypes(values: Any, like: Any) -> Any:
    """`values` with each floating leaf cast to the dtype of the leaf of `like`.

    Used on a vector field's output: the derivative of a float32 state is float32,
    even when a float64 constant took part in computing it.
    """
    return jax.tree_util.tree_map(
        lambda v, y: v.astype(jnp.result_type(y)) if _is_float_array(v) else v,
        values,
        like,
    )


def reachable_tolerance(tolerance: float, dtype: Any, ulps: float = 45.0) -> Any:
    """`tolerance`, raised to `ulps` units of round-off of `dtype` if below it.

    A stopping test tighter than the arithmetic can resolve never passes: lagjax's
    own iterations (stage equations, Legendre and constraint solves) ask for ≈ 1e-14
    in float64, which is 45 ε; in float32 the same request means 45 ε₃₂ ≈ 5e-6.
    """
    return max(tolerance, ulps * float(jnp.finfo(dtype).eps))


def newton_for(dtype: Any, rtol: float, atol: float) -> optx.Newton:
    """`optimistix.Newton` whose tolerances `dtype` can reach (`reachable_tolerance`)."""
    return optx.Newton(
        rtol=reachable_tolerance(rtol, dtype), atol=reachable_tolerance(atol, dtype)
    )
