r"""Constrained accelerations of a few coordinates, in scalar form.

The equations of `constraints` — $M\ddot q = f + A^T\lambda$, $A\ddot q = -\beta$
(plus Baumgarte's terms) — solved as a hand-written code would solve them when M
is positive definite: with the free acceleration $a = M^{-1}f$ and the columns
$Y = M^{-1}A^T$ from one $LDL^T$ of M, the multipliers solve the k × k Schur
complement system

$$ (A M^{-1} A^T)\,\lambda = -\beta - A a, \qquad \ddot q = a + Y\lambda, $$

which is positive definite exactly when A has full row rank. Every quantity is
built in the scalar formulation of `euler_lagrange` — M and f from nested
forward-mode passes on L re-expressed in scalars (`scalarize`), each row of A as
one pass per velocity on the velocity-level residual c(q, q̇, t) (ġ for a
holonomic g), β and c in one pass along (q̇, 1) — and both factorizations are
unrolled into scalar arithmetic (`unrolled_ldl`). XLA then compiles the whole
constrained step into one kernel, where the dense formulation's Jacobians, Hessian
and saddle-point LU split it into dozens (Cartesian double pendulum in an RK4
scan, `benchmarks/constrained_overhead.py`).

When a pivot of either factorization is not clearly positive — M indefinite or
singular, A rank-deficient, or nearly so — the dense formulation solves the full
saddle-point system (M, Aᵀ; A, 0) by pivoted LU and judges it, in a `lax.cond`
whose predicate is reduced over the batch under `vmap`, as
`linalg.solve_unrolled_symmetric` does for the unconstrained system. The saddle
system is regular for any M positive definite on the motions the constraints
allow, so that case is still solved, only not by the fast path.

References: Golub & Van Loan, *Matrix Computations*, 4th ed., §4.1.2 ($LDL^T$);
Benzi, Golub & Liesen, Acta Numerica 14 (2005), §5 (Schur complement reduction of
saddle-point systems); Hairer, Lubich & Wanner, *Geometric Numerical Integration*,
2nd ed., §VII.1.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree

from lagjax._core.batch_branch import any_in_batch
from lagjax._linalg.scalarize import scalar_argument_function
from lagjax._linalg.small_solves import solve_dense_in_step
from lagjax._linalg.unrolled_ldl import (
    ldl_factor_unrolled,
    ldl_solve_unrolled,
    pivots_sound,
)
from lagjax.mechanics.constraints import (
    Constraints,
    apply_rank_check,
    check_constraint_count,
    least_correction,
)
from lagjax.mechanics.euler_lagrange import (
    SCALAR_COORDINATE_LIMIT,
    apply_singular_check,
    dense_system,
    flat_lagrangian,
    partial_derivative,
    scalar_system,
)


def scalar_constraints_apply(lagrangian: Any, q: Any) -> bool:
    """Whether the scalar formulation takes `lagrangian`'s constrained motion at
    `q`: few coordinates, and not the network formulation (a trained L)."""
    few = ravel_pytree(q)[0].shape[0] <= SCALAR_COORDINATE_LIMIT
    return few and lagrangian.formulation != "network"


def _scalar_components(vector_fn: Callable, count: int, *examples) -> list[Callable]:
    """Each component of `vector_fn(*arrays)` as a function of the arrays' scalars."""

    def component(i):
        return scalar_argument_function(lambda *x: vector_fn(*x)[i], *examples)

    return [component(i) for i in range(count)]


def _residual_rows(constraints, unravel, q, v, t, args, k) -> list[Callable]:
    """Each velocity-level residual c_i(q, q̇, t) as a function of 2n + 1 scalars."""

    def residual(qf, vf, tt):
        return constraints.velocity_residual(unravel(qf), unravel(vf), tt, args)

    return _scalar_components(residual, k, q, v, t)


def _position_rows(constraints, unravel, q, t, args) -> list[Callable]:
    """Each holonomic g_i(q, t) as a function of n + 1 scalars."""
    k_h = jax.eval_shape(constraints.position_residual, unravel(q), t, args).shape[0]

    def residual(qf, tt):
        return constraints.position_residual(unravel(qf), tt, args)

    return _scalar_components(residual, k_h, q, t)


def _position_values(constraints, unravel, q, t, args) -> list[jax.Array]:
    """g_i(q, t) as scalars (only Baumgarte's stabilization needs them)."""
    rows = _position_rows(constraints, unravel, q, t, args)
    return [g(*q, t) for g in rows]


def _constraint_rows(constraints: Constraints, unravel, q, v, t, args, k):
    """(A as k lists of n scalars, the residuals c, the right-hand side of
    A q̈ = target)."""
    n = q.shape[0]
    z = (*(q[i] for i in range(n)), *(v[i] for i in range(n)), t)
    rate = constraints.baumgarte_rate
    positions = _position_values(constraints, unravel, q, t, args) if rate else []
    jacobian, values, target = [], [], []
    for i, residual in enumerate(
        _residual_rows(constraints, unravel, q, v, t, args, k)
    ):
        jacobian.append([partial_derivative(residual, n + j)(*z) for j in range(n)])

        def along_q_and_t(*qt, residual=residual):
            return residual(*qt[:n], *z[n : 2 * n], qt[n])

        # c and β = ∂c/∂q·q̇ + ∂c/∂t in one pass.
        value, bias = jax.jvp(
            along_q_and_t, (*z[:n], t), (*z[n : 2 * n], jnp.ones_like(t))
        )
        goal = -bias
        if rate and i < len(positions):  # g̈ + 2αġ + α²g = 0
            goal = goal - 2 * rate * value - rate**2 * positions[i]
        elif rate:  # ċ + αc = 0
            goal = goal - rate * value
        values.append(value)
        target.append(goal)
    return jacobian, values, target


def _dot(a: list[jax.Array], b: list[jax.Array]) -> jax.Array:
    total = a[0] * b[0]
    for x, y in zip(a[1:], b[1:]):
        total = total + x * y
    return total


def _schur_factors(mass, jacobian):
    """(LDLᵀ of M, the columns of M⁻¹Aᵀ, LDLᵀ of A M⁻¹Aᵀ), all in scalars."""
    k = len(jacobian)
    factor = ldl_factor_unrolled(mass)
    columns = [ldl_solve_unrolled(factor, row) for row in jacobian]
    schur = [
        [_dot(jacobian[i], columns[j]) if j >= i else None for j in range(k)]
        for i in range(k)
    ]
    return factor, columns, ldl_factor_unrolled(schur)


def _schur_solve(mass, rhs, jacobian, target):
    """(q̈, λ, Aᵀλ) as lists of scalars, and whether both factorizations are sound."""
    n, k = len(rhs), len(target)
    factor, columns, schur_factor = _schur_factors(mass, jacobian)
    free = ldl_solve_unrolled(factor, rhs)
    reduced = [target[i] - _dot(jacobian[i], free) for i in range(k)]
    multipliers = ldl_solve_unrolled(schur_factor, reduced)
    transposed = [[columns[j][m] for j in range(k)] for m in range(n)]
    qddot = [free[m] + _dot(transposed[m], multipliers) for m in range(n)]
    rows_t = [[jacobian[j][m] for j in range(k)] for m in range(n)]
    force = [_dot(rows_t[m], multipliers) for m in range(n)]
    sound = pivots_sound(factor) & pivots_sound(schur_factor)
    return qddot, multipliers, force, sound


# Compiled so that eager calls do not dispatch op by op; inlined under an outer jit.
@eqx.filter_jit
def scalar_constrained_motion(
    lagrangian: Callable,
    constraints: Constraints,
    q: Any,
    qdot: Any,
    t: Any,
    args: Any,
    force: Any,
    *,
    check: bool | str,
) -> tuple[Any, jax.Array, Any]:
    """(q̈, λ, Aᵀλ) of a constrained system in the scalar formulation.

    `lagrangian` is L(q, q̇, t, args) on the user's trees, `force` the generalized
    force (a tree like q, or None). `check` is the verdict on a singular mass
    matrix or saddle-point matrix, as in `Lagrangian.acceleration`.
    """
    check_constraint_count(constraints, q, t, args)
    qddot, multipliers, constraint_force, mass_singular, singular = _solve(
        lagrangian, constraints, q, qdot, t, args, force
    )
    qddot, multipliers, constraint_force = apply_rank_check(
        (qddot, multipliers, constraint_force), singular, check
    )
    qddot = apply_singular_check(qddot, mass_singular, check)
    unravel = ravel_pytree(q)[1]
    return unravel(qddot), multipliers, unravel(constraint_force)


def _solve(lagrangian, constraints, q, qdot, t, args, force):
    """`(q̈, λ, Aᵀλ, mass_singular, saddle_singular)`, q̈ and Aᵀλ flat; the two
    flags are only ever set by the dense fallback."""
    k = jax.eval_shape(constraints.velocity_residual, q, qdot, t, args).shape[0]
    lag_flat, q_flat, v_flat, t, unravel = flat_lagrangian(lagrangian, q, qdot, t, args)
    force_flat = None if force is None else ravel_pytree(force)[0]
    mass, rhs = scalar_system(lag_flat, q_flat, v_flat, t)
    if force_flat is not None:
        rhs = [r + force_flat[i] for i, r in enumerate(rhs)]
    jacobian, _, target = _constraint_rows(
        constraints, unravel, q_flat, v_flat, t, args, k
    )
    qddot, multipliers, constraint_force, sound = _schur_solve(
        mass, rhs, jacobian, target
    )
    fast = (jnp.stack(qddot), jnp.stack(multipliers), jnp.stack(constraint_force))
    no = jnp.zeros((), dtype=bool)

    def by_saddle_lu():
        # Operands are the state, not the scalars above: handing a branch many
        # scalars splits the fused step around it (see solve_unrolled_symmetric).
        dense_mass, dense_rhs = dense_system(lag_flat, q_flat, v_flat, t)
        if force_flat is not None:
            dense_rhs = dense_rhs + force_flat
        free, mass_singular = solve_dense_in_step(dense_mass, dense_rhs)
        dense_jacobian = constraints.jacobian(q, t, args)
        goal = constraints.acceleration_target(q, qdot, t, args) - dense_jacobian @ free
        correction, lam, singular = least_correction(dense_mass, dense_jacobian, goal)
        careful = (free + correction, lam, dense_jacobian.T @ lam)
        chosen = jax.tree_util.tree_map(
            lambda a, b: jnp.where(sound, a, b), fast, careful
        )
        return (*chosen, ~sound & mass_singular, ~sound & singular)

    def as_computed():
        return (*fast, no, no)

    return jax.lax.cond(any_in_batch(~sound), by_saddle_lu, as_computed)


def scalar_velocity_correction(
    lagrangian: Callable, constraints: Constraints, q: Any, qdot: Any, t: Any, args: Any
) -> tuple[Any, jax.Array]:
    """`(q̇ + δ, singular)`: the least δ in the metric M with c(q, q̇ + δ, t) = 0.

    c is linear in q̇, so δ = M⁻¹Aᵀλ with (A M⁻¹Aᵀ)λ = −c(q, q̇, t): the Schur
    complement solve above with a zero free acceleration, in scalar form; the
    dense saddle-point LU (`least_correction`) when a pivot is unsound.
    """
    k = jax.eval_shape(constraints.velocity_residual, q, qdot, t, args).shape[0]
    lag_flat, q_flat, v_flat, t, unravel = flat_lagrangian(lagrangian, q, qdot, t, args)
    mass, _ = scalar_system(lag_flat, q_flat, v_flat, t)
    jacobian, values, _ = _constraint_rows(
        constraints, unravel, q_flat, v_flat, t, args, k
    )
    zeros = [jnp.zeros_like(t)] * q_flat.shape[0]
    delta, _, _, sound = _schur_solve(mass, zeros, jacobian, [-c for c in values])
    fast = v_flat + jnp.stack(delta)

    def by_saddle_lu():
        dense_mass, _ = dense_system(lag_flat, q_flat, v_flat, t)
        dense_jacobian = constraints.jacobian(q, t, args)
        residual = constraints.velocity_residual(q, qdot, t, args)
        correction, _, singular = least_correction(
            dense_mass, dense_jacobian, -residual
        )
        return jnp.where(sound, fast, v_flat + correction), ~sound & singular

    def as_computed():
        return fast, jnp.zeros((), dtype=bool)

    corrected, singular = jax.lax.cond(any_in_batch(~sound), by_saddle_lu, as_computed)
    return unravel(corrected), singular


# Simplified Newton iterations of the position projection before its verdict: the
# defect after a step is of the size of the local error, and each iteration squares
# it (relative to the constraint's scale), so two reach round-off.
POSITION_ITERATIONS = 2


def scalar_position_projection(
    lagrangian: Callable,
    constraints: Constraints,
    q: Any,
    qdot: Any,
    t: Any,
    args: Any,
    *,
    rtol: float,
    atol: float,
) -> tuple[Any, jax.Array]:
    """`(q + M⁻¹Gᵀν, converged)` with g(q + M⁻¹Gᵀν, t) = 0, in scalar form.

    ν by simplified Newton with the Jacobian frozen at ν = 0, where it is the
    positive definite G M⁻¹Gᵀ (Hairer, Lubich & Wanner §IV.4):
    Δν = −(G M⁻¹Gᵀ)⁻¹ g(q + M⁻¹Gᵀν, t), `POSITION_ITERATIONS` times, unrolled, so
    that the projection fuses into the step. `converged` is false when the last
    update is above `atol + rtol·|ν|` in some component or a pivot of M or of
    G M⁻¹Gᵀ is unsound; the caller then solves again by `optimistix.Newton`.
    """
    lag_flat, q_flat, v_flat, t, unravel = flat_lagrangian(lagrangian, q, qdot, t, args)
    n = q_flat.shape[0]
    mass, _ = scalar_system(lag_flat, q_flat, v_flat, t)
    rows = _position_rows(constraints, unravel, q_flat, t, args)
    k_h = len(rows)
    start = [q_flat[m] for m in range(n)]
    jacobian = [[partial_derivative(g, j)(*start, t) for j in range(n)] for g in rows]
    factor, directions, schur_factor = _schur_factors(mass, jacobian)
    by_coordinate = [[directions[j][m] for j in range(k_h)] for m in range(n)]
    nu = [jnp.zeros_like(t)] * k_h
    position, update = start, nu
    for _ in range(POSITION_ITERATIONS):
        defect = [g(*position, t) for g in rows]
        update = ldl_solve_unrolled(schur_factor, [-d for d in defect])
        nu = [a + b for a, b in zip(nu, update)]
        position = [start[m] + _dot(by_coordinate[m], nu) for m in range(n)]
    converged = pivots_sound(factor) & pivots_sound(schur_factor)
    for step, total in zip(update, nu):
        converged = converged & (jnp.abs(step) <= atol + rtol * jnp.abs(total))
    return unravel(jnp.stack(position)), converged
