r"""The Euler–Lagrange equations solved for the generalized accelerations.

For $L(q, \dot q, t)$ with generalized non-conservative force $Q$ (including the
Rayleigh term $-\partial D/\partial \dot q$), $\frac{d}{dt}\partial L/\partial\dot q
- \partial L/\partial q = Q$ expands by the chain rule into the linear system

$$ M\,\ddot q = \frac{\partial L}{\partial q}
      - \frac{\partial^2 L}{\partial \dot q\,\partial q}\,\dot q
      - \frac{\partial^2 L}{\partial \dot q\,\partial t} + Q,
   \qquad M = \frac{\partial^2 L}{\partial \dot q\,\partial \dot q}. $$

All derivatives come from autodiff. Two formulations of the same equations:

- **scalar** (few coordinates): every coordinate is its own scalar and every
  derivative a forward-mode pass with a scalar tangent. XLA then sees only scalar
  arithmetic, common subexpressions of the nested passes merge, and on CPU the whole
  step fuses — the speed of hand-written equations of motion.
- **dense** (many coordinates): gradients, one Jacobian-of-gradient for M and one
  Jacobian–vector product for the mixed terms, on flat arrays.

Terms that vanish (∂/∂t of an autonomous L) are symbolic zeros in JAX's forward
mode and constant-folded by XLA, so they cost nothing.

References: the course text §3 (Lagrange's equations, eq. 3.35 with generalized
forces), Goldstein, *Classical Mechanics* §1.4–1.5.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree

from lagjax._linalg.marked_solves import solves_marked
from lagjax._linalg.scalarize import scalar_argument_function
from lagjax._linalg.singular_verdicts import raise_if_singular
from lagjax._linalg.small_solves import (
    UNROLLED_SOLVE_LIMIT,
    solve_symmetric_system,
    solve_unrolled,
    solve_unrolled_symmetric,
)
from lagjax._linalg.window_cumsum import with_window_cumsums

# Up to this many coordinates the scalar formulation is used; its trace grows as n²
# while the dense one stays compact. Chosen by benchmarks/derivation_overhead.py.
SCALAR_COORDINATE_LIMIT = 6

FlatLagrangian = Callable[[jax.Array, jax.Array, jax.Array], jax.Array]


def partial_derivative(fn: Callable[..., jax.Array], index: int) -> Callable:
    """∂fn/∂z_index for fn(*z) with scalar z, by one forward-mode pass."""

    def derivative(*z):
        def along(x):
            return fn(*z[:index], x, *z[index + 1 :])

        return jax.jvp(along, (z[index],), (jnp.ones_like(z[index]),))[1]

    return derivative


def scalar_system(lag_flat: FlatLagrangian, q, v, t):
    """Mass matrix (upper triangle, nested lists) and right-hand side, scalar form."""
    n = q.shape[0]
    # L of the 2n + 1 scalars (q_1..q_n, q̇_1..q̇_n, t), in pure scalar arithmetic.
    lagrangian_of_scalars = scalar_argument_function(lag_flat, q, v, t)
    z = (*(q[i] for i in range(n)), *(v[i] for i in range(n)), t)
    momenta = [partial_derivative(lagrangian_of_scalars, n + i) for i in range(n)]
    mass = [
        [
            partial_derivative(momenta[i], n + j)(*z) if j >= i else None
            for j in range(n)
        ]
        for i in range(n)
    ]
    rhs = []
    for i in range(n):
        force = partial_derivative(lagrangian_of_scalars, i)(*z)

        def momentum_along_q_and_t(*qt, i=i):
            return momenta[i](*qt[:n], *z[n : 2 * n], qt[n])

        # (∂p_i/∂q)·q̇ + ∂p_i/∂t in one pass: the part of dp_i/dt not due to q̈.
        transport = jax.jvp(
            momentum_along_q_and_t, (*z[:n], t), (*z[n : 2 * n], jnp.ones_like(t))
        )[1]
        rhs.append(force - transport)
    return mass, rhs


def dense_system(lag_flat: FlatLagrangian, q, v, t):
    """Mass matrix and right-hand side as arrays."""
    momentum = jax.grad(lag_flat, argnums=1)
    mass = jax.jacfwd(momentum, argnums=1)(q, v, t)
    force = jax.grad(lag_flat, argnums=0)(q, v, t)
    transport = jax.jvp(
        lambda qq, tt: momentum(qq, v, tt), (q, t), (v, jnp.ones_like(t))
    )[1]
    return mass, force - transport


def _solve_scalar(system: Callable, poison: bool) -> tuple[jax.Array, jax.Array]:
    """Solve the scalar form's system, given as the function that builds it.

    With `poison`, a singular M makes q̈ NaN. Up to 3 coordinates each scalar of
    the solution is selected before they are stacked: a select on the stacked
    array kept XLA from keeping the step in scalars (double pendulum RK4 scan,
    default `acceleration`: 1.42–1.55× the hand-written step against 1.06×).
    """
    mass, rhs = system()
    n = len(rhs)
    if n <= UNROLLED_SOLVE_LIMIT:
        x, singular = solve_unrolled(mass, rhs, poison=poison)
        return jnp.stack(x), singular
    x, singular = solve_unrolled_symmetric(mass, rhs, system)
    return (jnp.where(singular, jnp.nan, x) if poison else x), singular


def euler_lagrange_acceleration(
    lagrangian: Callable[[Any, Any, Any, Any], jax.Array],
    q: Any,
    qdot: Any,
    t: Any,
    args: Any,
    generalized_force: Any = None,
    *,
    check: bool | str = True,
) -> Any:
    """q̈ from the Euler–Lagrange equations.

    **Arguments:**
    - `lagrangian`: `L(q, qdot, t, args) -> scalar`.
    - `q`, `qdot`: matching pytrees of coordinates and velocities.
    - `generalized_force`: `None`, or a pytree like `q` of the non-conservative
      generalized force Q (already including −∂D/∂q̇).

    - `check`: with True, a numerically singular mass matrix raises a run-time
      error (`eqx.error_if`, works inside jit). That test is a branch per call,
      which splits an otherwise fused integration step (2.3–4.8× single, 1.2–1.8×
      batched on CPU, `benchmarks/derivation_overhead.py`). With `"nan"` a singular
      matrix turns q̈ into NaN instead — one select, which fuses — so a loop
      carries the verdict to its end, where the caller checks the state once
      (`simulate` does, naming the singular mass matrix as a likely cause). With
      False no conditioning test is made — an exactly singular matrix still gives
      inf/NaN, never a finite wrong number, but a nearly singular one is not
      flagged. `Lagrangian.acceleration` picks True for concrete inputs and
      `"nan"` under a trace.

    **Returns:** q̈ with the structure of `q`.
    """
    return _compiled_acceleration(
        lagrangian, q, qdot, t, args, generalized_force,
        check=check, marked=solves_marked(),
    )  # fmt: skip


# Compiled so that eager calls do not dispatch the scalar derivation op by op; under
# an outer jit this is inlined. `marked` (whether the Taylor graph's trace marks
# solves, `marked_solves`) is part of the key, so a trace made with the mark on is
# never reused without it, nor one made without it under the mark.
@eqx.filter_jit
def _compiled_acceleration(
    lagrangian, q, qdot, t, args, generalized_force, *, check, marked
) -> Any:
    del marked  # read by `solve_symmetric_system` during the trace
    lag_flat, q_flat, v_flat, t, unravel = flat_lagrangian(lagrangian, q, qdot, t, args)
    force = None if generalized_force is None else ravel_pytree(generalized_force)[0]
    if q_flat.shape[0] <= SCALAR_COORDINATE_LIMIT:

        def build_scalar():
            mass, rhs = scalar_system(lag_flat, q_flat, v_flat, t)
            if force is not None:
                rhs = [r + force[i] for i, r in enumerate(rhs)]
            return mass, rhs

        qddot, singular = _solve_scalar(build_scalar, poison=check == "nan")
        if check == "nan":
            return unravel(qddot)  # poisoned already
    else:
        lag_dense = with_window_cumsums(lag_flat, q_flat, v_flat, t)

        def build_dense():
            mass, rhs = dense_system(lag_dense, q_flat, v_flat, t)
            return mass, (rhs if force is None else rhs + force)

        # Without a check the verdict is discarded, so the factor is not judged.
        qddot, singular = solve_symmetric_system(build_dense, judge=bool(check))
    return unravel(apply_singular_check(qddot, singular, check))


def flat_lagrangian(lagrangian: Callable, q: Any, qdot: Any, t: Any, args: Any):
    """`(L_flat, q_flat, v_flat, t, unravel)`: L of flat coordinate and velocity
    vectors, the flattened point, t in their dtype, and the map back to q's tree."""
    q_flat, unravel = ravel_pytree(q)
    v_flat, _ = ravel_pytree(qdot)
    t = jnp.asarray(t, dtype=q_flat.dtype)

    def lag_flat(qf, vf, tt):
        return lagrangian(unravel(qf), unravel(vf), tt, args)

    return lag_flat, q_flat, v_flat, t, unravel


def apply_singular_check(qddot: jax.Array, singular: jax.Array, check: Any):
    """`check`'s verdict on a singular mass matrix: NaN ("nan"), a run-time error
    (True), or nothing (False)."""
    if check == "nan":
        return jnp.where(singular, jnp.nan, qddot)
    if check:
        return raise_if_singular(qddot, singular, "The mass matrix ∂²L/∂q̇∂q̇")
    return qddot
