r"""RATTLE: the symplectic Störmer–Verlet method on a holonomic constraint manifold.

For $L = \tfrac12\dot q^T M\dot q - V(q, t)$ with a constant mass matrix, i.e.
$H = \tfrac12 p^T M^{-1} p + V(q, t)$, and holonomic constraints $g(q, t) = 0$
($G = \partial g/\partial q$), one step $(q_0, p_0) \mapsto (q_1, p_1)$ of size h is

$$ p_{1/2} = p_0 - \tfrac h2\big(\nabla V(q_0) + G(q_0)^T\lambda\big), \qquad
   q_1 = q_0 + h M^{-1} p_{1/2}, \qquad 0 = g(q_1, t_1), $$

$$ p_1 = p_{1/2} - \tfrac h2\big(\nabla V(q_1) + G(q_1)^T\mu\big), \qquad
   0 = G(q_1) M^{-1} p_1 + \partial g/\partial t(q_1, t_1). $$

The first line is SHAKE: k nonlinear equations for the multiplier λ, solved here by
`optimistix.Newton` in the scaled unknown $\Lambda = \tfrac{h^2}{2}\lambda$ (a
displacement, so the tolerances mean the same at every step size), starting from
the previous step's Λ. The second line projects the momentum onto the hidden
constraint $\dot g = 0$ — linear in μ, one small solve. The map is symplectic on
the constraint manifold $T^*\mathcal M$, symmetric (time-reversible) and of order 2;
$g$ and $\dot g$ hold to the solver tolerance at every step, so they do not drift.

As in `splitting_engine.py`, the step is formed as small increments Δq, Δp that
are added to the state with Kahan's compensated summation.

References: Andersen, *Rattle*, J. Comput. Phys. 52, 24 (1983); Ryckaert, Ciccotti
& Berendsen, J. Comput. Phys. 23, 327 (1977) (SHAKE); Hairer, Lubich & Wanner,
*Geometric Numerical Integration*, 2nd ed., §VII.1.4 (eq. 1.26, Theorems 1.3–1.4);
Leimkuhler & Reich, *Simulating Hamiltonian Dynamics* (2004), §7.2.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree

from lagjax._core.precision import newton_for
from lagjax._core.solver_kinds import (
    AbstractConstraintKeeping,
    AbstractTimeReversible,
)
from lagjax._core.system_protocols import LagrangianLike
from lagjax._core.terms import RattleTerm, physical_step, unwrap_term
from lagjax._linalg.in_step_root_find import root_find_in_step
from lagjax._linalg.singular_verdicts import raise_if_singular
from lagjax._linalg.small_solves import (
    UNROLLED_SOLVE_LIMIT,
    solve_dense,
    solve_dense_in_step,
    solve_unrolled,
)
from lagjax.mechanics.constraints import Constraints
from lagjax.solvers.compensated import add_to_state, zero_compensation


def _holonomic_constraints(lagrangian: LagrangianLike) -> Constraints:
    """Trace-time check that RATTLE applies; returns the constraints."""
    constraints = lagrangian.constraints
    if constraints is None or constraints.holonomic is None:
        raise ValueError("Rattle needs a Lagrangian with holonomic constraints")
    if constraints.velocity is not None:
        raise ValueError(
            "Rattle handles holonomic constraints g(q, t) = 0 only; integrate "
            "nonholonomic (velocity) constraints with a diffrax solver (projected)."
        )
    if lagrangian.force is not None or lagrangian.dissipation is not None:
        raise ValueError(
            "Rattle integrates conservative systems; this Lagrangian has a "
            "generalized force or dissipation"
        )
    return constraints


# (inverse mass matrix, last Λ as the next Newton guess, Kahan compensation or None)
_RattleState = tuple[jax.Array, jax.Array, Any]


def _raise_if_mass_varies(lagrangian, q0, t0, args, inverse_mass):
    """Refuse a position- or velocity-dependent mass matrix instead of integrating it
    wrongly: RATTLE here reads M once. The test is at the start (∂M/∂q, ∂M/∂q̇ and
    ∂M/∂t vanish there for a constant M), so it cannot miss a generic dependence."""
    q_flat, unravel = ravel_pytree(q0)
    zero = jnp.zeros_like(q_flat)

    def mass(q, qdot, t):
        return lagrangian.mass_matrix(unravel(q), unravel(qdot), t, args)

    rates = jax.jacfwd(mass, argnums=(0, 1, 2))(q_flat, zero, jnp.asarray(t0, float))
    variation = jnp.max(jnp.stack([jnp.max(jnp.abs(rate)) for rate in rates]))
    scale = jnp.max(jnp.abs(mass(q_flat, zero, jnp.asarray(t0, float))))
    return eqx.error_if(
        inverse_mass,
        variation > 1e-12 * scale,
        "Rattle needs a constant mass matrix (L = ½q̇ᵀMq̇ − V); this L's mass matrix "
        "varies with q, q̇ or t. Use the projected solvers (the default) instead.",
    )


class Rattle(
    AbstractConstraintKeeping,
    AbstractTimeReversible,
    diffrax.AbstractSolver[_RattleState],
):
    r"""RATTLE for holonomic constraints (order 2, symplectic, symmetric).

    Use it through `lj.simulate(Lagrangian(L, constraints=g), (q0, qdot0), dt=...,
    solver=Rattle())`, or with `diffrax.diffeqsolve` on a `RattleTerm` and state
    `(q, p)`. L must be $\tfrac12\dot q^TM\dot q - V(q, t)$ with a constant M (read
    once, at the start) and no generalized force. The start should satisfy g = 0 and
    $\dot g = 0$. A failed Newton solve is reported through `RESULTS`; a
    rank-deficient constraint Jacobian makes the state NaN, which `simulate`
    reports as a non-finite state after the loop (no run-time branch in the
    step). Fixed step only.

    **Arguments:**
    - `rtol`, `atol`: of the Newton solve for Λ (a displacement).
    - `max_newton_steps`: per step.
    - `compensated`: Kahan-compensated summation of the increments (default True).

    ??? cite "References"

        - Andersen, *Rattle: a "velocity" version of the Shake algorithm for
          molecular dynamics calculations*, J. Comput. Phys. 52, 24 (1983).
        - Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed.,
          Springer (2006), §VII.1.4.
        - Leimkuhler & Reich, *Simulating Hamiltonian Dynamics*, Cambridge (2004),
          §7.2.
    """

    term_structure: ClassVar = RattleTerm
    interpolation_cls: ClassVar[Callable[..., diffrax.LocalLinearInterpolation]] = (
        diffrax.LocalLinearInterpolation
    )
    rtol: float = 1e-14
    atol: float = 1e-14
    max_newton_steps: int = eqx.field(static=True, default=16)
    compensated: bool = eqx.field(static=True, default=True)

    def order(self, terms: Any) -> int:
        del terms
        return 2

    def init(self, terms, t0, t1, y0, args) -> _RattleState:
        term, direction = unwrap_term(terms, RattleTerm)
        lagrangian = term.lagrangian
        constraints = _holonomic_constraints(lagrangian)
        del t1
        q0, _ = y0
        q_flat, _ = ravel_pytree(q0)
        zero_velocity = jax.tree_util.tree_map(jnp.zeros_like, q0)
        mass = lagrangian.mass_matrix(q0, zero_velocity, direction * t0, args)
        identity = jnp.eye(q_flat.shape[0], dtype=q_flat.dtype)
        inverse_mass, singular = solve_dense(mass, identity)
        inverse_mass = raise_if_singular(inverse_mass, singular, "The mass matrix M")
        inverse_mass = _raise_if_mass_varies(
            lagrangian, q0, direction * t0, args, inverse_mass
        )
        guess = jnp.zeros_like(constraints.position_residual(q0, t0, args))
        compensation = zero_compensation(y0) if self.compensated else None
        return inverse_mass, guess, compensation

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        del made_jump
        term, t0, h = physical_step(terms, RattleTerm, t0, t1)
        lagrangian = term.lagrangian
        inverse_mass, guess, compensation = solver_state
        t1 = t0 + h
        q0, p0 = y0
        increment_q, half_kick, (multiplier, newton_result) = self._shake(
            lagrangian, inverse_mass, guess, q0, p0, t0, t1, h, args
        )
        compensation_q, compensation_p = compensation or (None, None)
        q1, compensation_q = add_to_state(q0, increment_q, compensation_q)
        increment_p = self._rattle_kick(
            lagrangian, inverse_mass, q1, p0, half_kick, t1, h, args
        )
        p1, compensation_p = add_to_state(p0, increment_p, compensation_p)
        if compensation is not None:
            compensation = (compensation_q, compensation_p)
        y1 = (q1, p1)
        result = diffrax.RESULTS.promote(newton_result)
        state = (inverse_mass, multiplier, compensation)
        return y1, None, dict(y0=y0, y1=y1), state, result

    def _shake(self, lagrangian, inverse_mass, guess, q0, p0, t0, t1, h, args):
        """Position half: Δq and the first half kick Δp_{1/2}, with Λ solved."""
        constraints = lagrangian.constraints
        q0_flat, unravel = ravel_pytree(q0)
        p0_flat, _ = ravel_pytree(p0)
        half_kick_free = 0.5 * h * _potential_force(lagrangian, q0, t0, args)
        increment_free = h * inverse_mass @ (p0_flat + half_kick_free)
        jacobian = constraints.jacobian(q0, t0, args)
        directions = inverse_mass @ jacobian.T  # M⁻¹Gᵀ, (n, k)

        def defect(multiplier, _):
            increment = increment_free - directions @ multiplier
            return constraints.position_residual(unravel(q0_flat + increment), t1, args)

        multiplier, result = root_find_in_step(
            defect,
            newton_for(guess.dtype, self.rtol, self.atol),
            guess,
            self.max_newton_steps,
        )
        increment_q = increment_free - directions @ multiplier
        # p_{1/2} = p0 + h/2 F0 − Gᵀλ h/2 with λ h²/2 = Λ.
        half_kick = half_kick_free - jacobian.T @ multiplier / h
        return unravel(increment_q), half_kick, (multiplier, result)

    def _rattle_kick(self, lagrangian, inverse_mass, q1, p0, half_kick, t1, h, args):
        """Momentum half: Δp = p1 − p0 with p1 on the hidden constraint ġ = 0."""
        constraints = lagrangian.constraints
        p0_flat, unravel = ravel_pytree(p0)
        increment = half_kick + 0.5 * h * _potential_force(lagrangian, q1, t1, args)
        jacobian = constraints.jacobian(q1, t1, args)
        velocity = unravel(inverse_mass @ (p0_flat + increment))
        defect = constraints.velocity_residual(q1, velocity, t1, args)
        projector = jacobian @ inverse_mass @ jacobian.T
        multiplier, singular = _solve_symmetric(projector, defect)
        # Detect cheaply, diagnose late: a run-time branch (eqx.error_if) here
        # split the fused step and cost 14x a hand-written RATTLE loop; a NaN
        # state is what `simulate` reports after the loop.
        multiplier = jnp.where(singular, jnp.nan, multiplier)
        return unravel(increment - jacobian.T @ multiplier)

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)


def _solve_symmetric(matrix: jax.Array, rhs: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Solve a small symmetric system; `(x, singular)`.

    Up to 3 constraints in closed form: on CPU an LU call per step for a 1×1 or 2×2
    matrix cost RATTLE about 1.7× in run time (pendulum, 10⁵ steps). More
    constraints by `solve_dense_in_step`, which calls no LAPACK routine inside the
    step on CPU.
    """
    k = rhs.shape[0]
    if k > UNROLLED_SOLVE_LIMIT:
        return solve_dense_in_step(matrix, rhs)
    rows = [[matrix[i, j] for j in range(k)] for i in range(k)]
    x, singular = solve_unrolled(rows, [rhs[i] for i in range(k)])
    return jnp.stack(x), singular


def _potential_force(lagrangian: LagrangianLike, q, t, args) -> jax.Array:
    """−∂V/∂q = ∂L/∂q at q̇ = 0 (L = ½q̇ᵀMq̇ − V), raveled."""
    zero_velocity = jax.tree_util.tree_map(jnp.zeros_like, q)
    gradient = jax.grad(lagrangian, argnums=0)(q, zero_velocity, t, args)
    return ravel_pytree(gradient)[0]
