r"""Any diffrax solver on a constrained Lagrangian, projected onto the constraints.

The index-reduced equations $M\ddot q = f + A^T\lambda$, $A\ddot q = -\beta$
(`lagjax.mechanics.constraints`) keep the constraints only at the acceleration
level: a Runge–Kutta step lets $g(q, t)$ and $c(q, \dot q, t)$ drift with its local
error, and the drift grows over a run. After every step the state is therefore
moved back onto the constraint manifold by the smallest change in the kinetic
metric $M$ (Hairer, Lubich & Wanner §IV.4):

- positions: $q \leftarrow q + M^{-1}G^T\nu$ with ν solved from
  $g(q + M^{-1}G^T\nu, t) = 0$ by `optimistix.Newton` (G, M frozen at the step's
  end — a few iterations from ν = 0, as the defect is the local error);
- velocities: $\dot q \leftarrow \dot q + \delta$, the least correction with
  $A(q, t)(\dot q + \delta) + b = 0$, one saddle-point solve.

Both changes are of the size of the local error, so the solver's order, its error
estimate and a first-same-as-last derivative stay valid to that order, and $g$ and
$c$ stay at round-off for the whole run.

`AbstractProjectedSolver` is the general wrapper — any diffrax solver, with a
projection after every step — that `ConstraintProjection` (here) and the rigid
body's `QuaternionProjection` (`lagjax.solvers.lie_poisson`) specialise. It
delegates everything to the wrapped solver (so `isinstance` checks for adaptivity
are the wrapped solver's) and only replaces `y1`, in the state and the dense
output, by its projection.

References: Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed.,
Springer (2006), §IV.4 (projection methods) and §VII.1; Ascher & Petzold,
*Computer Methods for ODEs and DAEs* (1998), §10.3 (stabilization by projection).
"""

from __future__ import annotations

import abc
from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx
from jax.flatten_util import ravel_pytree

from lagjax._core.batch_branch import any_in_batch
from lagjax._core.precision import match_dtypes, newton_for
from lagjax._core.solver_kinds import AbstractConstraintKeeping
from lagjax._core.system_protocols import LagrangianLike
from lagjax._core.terms import ConstrainedLagrangianTerm, unwrap_term
from lagjax._linalg.in_step_root_find import root_find_in_step
from lagjax._linalg.singular_verdicts import singular_check
from lagjax._linalg.small_solves import solve_dense, solve_dense_in_step
from lagjax.mechanics.constraints import apply_rank_check, least_correction
from lagjax.mechanics.scalar_constraints import (
    scalar_constraints_apply,
    scalar_position_projection,
    scalar_velocity_correction,
)


class AbstractProjectedSolver(diffrax.AbstractWrappedSolver):
    """Delegates to `solver` and projects each step's end state with `project`."""

    solver: eqx.AbstractVar[diffrax.AbstractSolver]

    @property
    def term_structure(self):  # pyright: ignore[reportIncompatibleVariableOverride]
        return self.solver.term_structure

    @property
    def interpolation_cls(self):  # pyright: ignore[reportIncompatibleVariableOverride]
        return self.solver.interpolation_cls

    @property
    def root_finder(self):
        """The wrapped implicit solver's: diffrax forwards `isinstance` through a
        wrapped solver, then reads and sets the root finder's tolerances on the
        wrapper (an implicit solver projected raised AttributeError)."""
        return self.solver.root_finder  # pyright: ignore[reportAttributeAccessIssue]

    def order(self, terms: Any) -> int | None:
        return self.solver.order(terms)

    def error_order(self, terms: Any):
        return self.solver.error_order(terms)

    def init(self, terms, t0, t1, y0, args):
        return self.solver.init(terms, t0, t1, y0, args)

    @abc.abstractmethod
    def project(
        self, terms: Any, t1: Any, y1: Any, args: Any
    ) -> tuple[Any, diffrax.RESULTS]:
        """The projected end state, and whether the projection succeeded."""

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        y1, error, dense_info, solver_state, result = self.solver.step(
            terms, t0, t1, y0, args, solver_state, made_jump
        )
        y1, projection_result = self.project(terms, t1, y1, args)
        y1 = match_dtypes(y1, y0)  # a float64 constant in g must not widen the state
        result = diffrax.RESULTS.where(
            result == diffrax.RESULTS.successful, projection_result, result
        )
        if "y1" in dense_info:
            dense_info = {**dense_info, "y1": y1}
        return y1, error, dense_info, solver_state, result

    def func(self, terms, t0, y0, args):
        return self.solver.func(terms, t0, y0, args)


def _project_positions(lagrangian, q, qdot, t, args, newton, max_steps):
    """q moved along M⁻¹Gᵀ onto g(q, t) = 0; returns (q, optimistix result)."""
    constraints = lagrangian.constraints
    k_h = constraints.position_residual(q, t, args).shape[0]
    if k_h == 0:
        return q, optx.RESULTS.successful
    if scalar_constraints_apply(lagrangian, q):
        return _project_positions_scalar(
            lagrangian, q, qdot, t, args, newton, max_steps
        )
    return _project_positions_by_optimistix(
        lagrangian, q, qdot, t, args, newton, max_steps
    )


def _project_positions_scalar(lagrangian, q, qdot, t, args, newton, max_steps):
    """Few coordinates: unrolled simplified Newton in scalar form, and
    `optimistix.Newton` only where it did not converge (a branch taken for the
    whole batch when a member needs it)."""
    fast, converged = scalar_position_projection(
        lagrangian, lagrangian.constraints, q, qdot, t, args,
        rtol=newton.rtol, atol=newton.atol,
    )  # fmt: skip

    def by_optimistix():
        careful, result = _project_positions_by_optimistix(
            lagrangian, q, qdot, t, args, newton, max_steps, in_kernel=True
        )
        chosen = jax.tree_util.tree_map(
            lambda a, b: jnp.where(converged, a, b), fast, careful
        )
        return chosen, optx.RESULTS.where(converged, optx.RESULTS.successful, result)

    def as_computed():
        return fast, optx.RESULTS.successful

    return jax.lax.cond(any_in_batch(~converged), by_optimistix, as_computed)


def _project_positions_by_optimistix(
    lagrangian, q, qdot, t, args, newton, max_steps, *, in_kernel=False
):
    """q moved along M⁻¹Gᵀ onto g(q, t) = 0 by `optimistix.Newton`.

    `in_kernel`: for a branch inside the step. A LAPACK routine anywhere in a
    loop body, even in a branch never taken, keeps XLA on CPU from compiling the
    body as one kernel (Cartesian double pendulum, Tsit5 projected: 1.4 ms
    with this branch free of LAPACK against 3.6 ms with one LU in it). So on CPU
    M⁻¹Gᵀ comes from the in-kernel LU loops and Newton runs by
    `in_step_root_find.root_find_in_step` (its linear solves unrolled or as loops).
    """
    constraints = lagrangian.constraints
    k_h = constraints.position_residual(q, t, args).shape[0]
    q_flat, unravel = ravel_pytree(q)
    mass = lagrangian.mass_matrix(q, qdot, t, args)
    holonomic_jacobian = constraints.jacobian(q, t, args)[:k_h]
    if in_kernel:
        directions = jax.vmap(
            lambda column: solve_dense_in_step(mass, column)[0],
            in_axes=1,
            out_axes=1,
        )(holonomic_jacobian.T)
    else:
        directions, _ = solve_dense(mass, holonomic_jacobian.T)  # M⁻¹Gᵀ, (n, k_h)

    def defect(nu, _):
        return constraints.position_residual(unravel(q_flat + directions @ nu), t, args)

    if in_kernel:
        moved, result = root_find_in_step(
            defect, newton, jnp.zeros(k_h, q_flat.dtype), max_steps
        )
        return unravel(q_flat + directions @ moved), result
    solution = optx.root_find(
        defect, newton, jnp.zeros(k_h, q_flat.dtype), max_steps=max_steps, throw=False
    )
    return unravel(q_flat + directions @ solution.value), solution.result


def _project_velocities(lagrangian, q, qdot, t, args):
    """q̇ + δ with the least δ (metric M) that satisfies c(q, q̇ + δ, t) = 0.

    Returns `(qdot, singular)`; c is linear in q̇, so one solve is exact.
    """
    constraints = lagrangian.constraints
    if scalar_constraints_apply(lagrangian, q):
        return scalar_velocity_correction(lagrangian, constraints, q, qdot, t, args)
    qdot_flat, unravel = ravel_pytree(qdot)
    mass = lagrangian.mass_matrix(q, qdot, t, args)
    jacobian = constraints.jacobian(q, t, args)
    target = -constraints.velocity_residual(q, qdot, t, args)
    correction, _, singular = least_correction(mass, jacobian, target)
    return unravel(qdot_flat + correction), singular


def project_onto_constraints(
    lagrangian: LagrangianLike,
    q: Any,
    qdot: Any,
    t: Any,
    args: Any,
    *,
    rtol: float = 1e-14,
    atol: float = 1e-14,
    max_steps: int = 16,
    check: bool | str | None = None,
) -> tuple[tuple[Any, Any], diffrax.RESULTS]:
    """`(q, q̇)` moved onto the constraint manifold of `lagrangian` at time t.

    When the constraint Jacobian is rank-deficient there, `check` decides as in
    `Lagrangian.acceleration`: by default an error on concrete values and NaN
    velocities under a trace (one select; a run-time error branch at every step
    of a loop would split its fused step), True an error also under `jit`.
    Returns the projected state and whether the position Newton solve converged.
    """
    check = singular_check(check, q, qdot, t)
    newton = newton_for(ravel_pytree(q)[0].dtype, rtol, atol)
    q, result = _project_positions(lagrangian, q, qdot, t, args, newton, max_steps)
    qdot, singular = _project_velocities(lagrangian, q, qdot, t, args)
    # A rank-deficient G can also make the Newton solve return NaN, which the
    # velocity step's singularity test would not see.
    leaves = jax.tree_util.tree_leaves((q, qdot))
    finite = jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in leaves]))
    qdot = apply_rank_check(qdot, singular | ~finite, check)
    return (q, qdot), diffrax.RESULTS.promote(result)


class ConstraintProjection(AbstractConstraintKeeping, AbstractProjectedSolver):
    r"""A diffrax solver on a constrained Lagrangian, projected after every step.

    `lj.simulate` wraps any plain diffrax solver (Tsit5, Dopri8, Kvaerno5, …) in it
    when the `Lagrangian` has constraints; with `diffrax.diffeqsolve`, use it on a
    `ConstrainedLagrangianTerm` and state `(q, q̇)`. `isinstance` checks (adaptive or
    not) are those of the wrapped solver. The start state should satisfy the
    constraints; the first step projects it there if not.

    **Arguments:**
    - `solver`: the wrapped diffrax solver.
    - `rtol`, `atol`: of the position projection's Newton solve (on the multiplier).

    ??? cite "References"

        - Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed.,
          Springer (2006), §IV.4.
    """

    solver: diffrax.AbstractSolver
    rtol: float = 1e-14
    atol: float = 1e-14

    def project(self, terms, t1, y1, args):
        term, direction = unwrap_term(terms, ConstrainedLagrangianTerm)
        q1, qdot1 = y1
        return project_onto_constraints(
            term.lagrangian,
            q1,
            qdot1,
            direction * t1,
            args,
            rtol=self.rtol,
            atol=self.atol,
            check="nan",  # simulate names the non-finite state after the loop
        )
