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

References: Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed.,
Springer (2006), §IV.4 (projection methods) and §VII.1; Ascher & Petzold,
*Computer Methods for ODEs and DAEs* (1998), §10.3 (stabilization by projection).
"""

from __future__ import annotations

from typing import Any

import diffrax
import jax
import jax.numpy as jnp
import optimistix as optx
from jax.flatten_util import ravel_pytree

from lagjax.mechanics.constraints import least_correction, raise_if_rank_deficient
from lagjax.mechanics.lagrangian import Lagrangian
from lagjax.mechanics.linalg import solve_dense
from lagjax.precision import match_dtypes, newton_for
from lagjax.solvers.projected import AbstractProjectedSolver


class ConstrainedLagrangianTerm(diffrax.AbstractTerm):
    """The term of a constrained `Lagrangian` on `y = (q, q̇)`.

    `vf` is `(q̇, q̈)` with q̈ including the constraint forces, so any diffrax solver
    integrates it; `ConstraintProjection` reads the constraints from it.
    """

    lagrangian: Lagrangian

    def vf(self, t, y, args):
        q, qdot = y
        qddot = self.lagrangian.acceleration(q, qdot, t, args, check=False)
        return qdot, match_dtypes(qddot, qdot)

    def contr(self, t0, t1, **kwargs):
        del kwargs
        return t1 - t0

    def prod(self, vf, control):
        return jax.tree_util.tree_map(lambda v: v * control, vf)


def unwrap_constrained_term(terms: Any, kind: type) -> tuple[Any, Any]:
    """The term of type `kind` inside diffrax's time-direction wrappers, and the
    direction (diffrax integrates t1 < t0 as forward time in −t)."""
    direction = 1
    # diffrax's WrapTerm is not public API; it holds `term` and `direction`.
    while not isinstance(terms, kind):
        inner = getattr(terms, "term", None)
        if inner is None:
            raise ValueError(
                f"this solver needs a {kind.__name__}, got {type(terms).__name__}"
            )
        direction = direction * terms.direction
        terms = inner
    return terms, direction


def _project_positions(lagrangian, q, qdot, t, args, newton, max_steps):
    """q moved along M⁻¹Gᵀ onto g(q, t) = 0; returns (q, optimistix result)."""
    constraints = lagrangian.constraints
    k_h = constraints.position_residual(q, t, args).shape[0]
    if k_h == 0:
        return q, optx.RESULTS.successful
    q_flat, unravel = ravel_pytree(q)
    mass = lagrangian.mass_matrix(q, qdot, t, args)
    holonomic_jacobian = constraints.jacobian(q, t, args)[:k_h]
    directions, _ = solve_dense(mass, holonomic_jacobian.T)  # M⁻¹Gᵀ, (n, k_h)

    def defect(nu, _):
        return constraints.position_residual(unravel(q_flat + directions @ nu), t, args)

    solution = optx.root_find(
        defect,
        newton,
        jnp.zeros(k_h, q_flat.dtype),
        max_steps=max_steps,
        throw=False,
    )
    return unravel(q_flat + directions @ solution.value), solution.result


def _project_velocities(lagrangian, q, qdot, t, args):
    """q̇ + δ with the least δ (metric M) that satisfies c(q, q̇ + δ, t) = 0.

    Returns `(qdot, singular)`; c is linear in q̇, so one solve is exact.
    """
    constraints = lagrangian.constraints
    qdot_flat, unravel = ravel_pytree(qdot)
    mass = lagrangian.mass_matrix(q, qdot, t, args)
    jacobian = constraints.jacobian(q, t, args)
    target = -constraints.velocity_residual(q, qdot, t, args)
    correction, _, singular = least_correction(mass, jacobian, target)
    return unravel(qdot_flat + correction), singular


def project_onto_constraints(
    lagrangian: Lagrangian,
    q: Any,
    qdot: Any,
    t: Any,
    args: Any,
    *,
    rtol: float = 1e-14,
    atol: float = 1e-14,
    max_steps: int = 16,
) -> tuple[tuple[Any, Any], diffrax.RESULTS]:
    """`(q, q̇)` moved onto the constraint manifold of `lagrangian` at time t.

    Raises a run-time error when the constraint Jacobian is rank-deficient there.
    Returns the projected state and whether the position Newton solve converged.
    """
    newton = newton_for(ravel_pytree(q)[0].dtype, rtol, atol)
    q, result = _project_positions(lagrangian, q, qdot, t, args, newton, max_steps)
    qdot, singular = _project_velocities(lagrangian, q, qdot, t, args)
    # A rank-deficient G can also make the Newton solve return NaN, which the
    # velocity step's singularity test would not see.
    leaves = jax.tree_util.tree_leaves((q, qdot))
    finite = jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in leaves]))
    qdot = raise_if_rank_deficient(qdot, singular | ~finite)
    return (q, qdot), diffrax.RESULTS.promote(result)


class ConstraintProjection(AbstractProjectedSolver):
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
        term, direction = unwrap_constrained_term(terms, ConstrainedLagrangianTerm)
        q1, qdot1 = y1
        return project_onto_constraints(
            term.lagrangian,
            q1,
            qdot1,
            direction * t1,
            args,
            rtol=self.rtol,
            atol=self.atol,
        )
