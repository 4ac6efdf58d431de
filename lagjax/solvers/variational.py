r"""Variational integrators: discretize Hamilton's principle, not the equations.

Replace the action $\int L\,dt$ over one step by the discrete Lagrangian (midpoint
rule)

$$ L_d(q_0, q_1) = h\, L\!\left(\tfrac{q_0 + q_1}{2},\ \tfrac{q_1 - q_0}{h},\
   t_0 + \tfrac h2\right). $$

Stationarity of the discrete action gives the discrete Euler–Lagrange equations; in
position–momentum form one step $(q_0, p_0) \mapsto (q_1, p_1)$ is

$$ p_0 = -D_1 L_d(q_0, q_1) \quad (\text{solved for } q_1), \qquad
   p_1 = D_2 L_d(q_0, q_1). $$

The map is symplectic and momentum-preserving for every symmetry of L (discrete
Noether theorem), symmetric, and of order 2. It needs only L — no Legendre
transform, no vector field — so it works directly from the user's Lagrangian.

References: Marsden & West, "Discrete mechanics and variational integrators", Acta
Numerica 10 (2001), §1.3 and §2.2; Hairer, Lubich & Wanner, *Geometric Numerical
Integration*, §VI.6.
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
from lagjax._core.solver_kinds import AbstractTimeReversible
from lagjax._core.system_protocols import LagrangianLike
from lagjax._core.terms import LagrangianTerm, physical_step
from lagjax._linalg.in_step_root_find import root_find_in_step
from lagjax.solvers.compensated import compensated_add, zero_compensation


def discrete_lagrangian(
    lagrangian: LagrangianLike, q0, increment, t0, h, args
) -> jax.Array:
    """Midpoint-rule discrete Lagrangian h·L(q0 + Δq/2, Δq/h, t0 + h/2), Δq = q1 − q0.

    Written in (q0, Δq) rather than (q0, q1): forming (q1 − q0)/h from two nearby
    large numbers would cost the velocity most of its significant digits.
    """
    midpoint = jax.tree_util.tree_map(lambda a, d: a + 0.5 * d, q0, increment)
    velocity = jax.tree_util.tree_map(lambda d: d / h, increment)
    return h * lagrangian(midpoint, velocity, t0 + 0.5 * h, args)


_State = Any


class VariationalMidpoint(AbstractTimeReversible, diffrax.AbstractSolver):
    """The midpoint variational integrator (order 2, symplectic, symmetric).

    Use it through `lj.simulate(lagrangian, (q0, qdot0), dt=..., solver=
    VariationalMidpoint())`, or with `diffrax.diffeqsolve` on a `LagrangianTerm` and
    state `(q, p)`. Each step solves the discrete Euler–Lagrange equation for q₁ with
    `optimistix.Newton` (Jacobian by autodiff), from the guess q₀ + h·q̇(q₀, p₀).
    The residual is scaled by 1 + |p₀| so the tolerances are relative to the
    momentum. A failed solve is reported through `RESULTS`.
    """

    term_structure: ClassVar = LagrangianTerm
    interpolation_cls: ClassVar[Callable[..., diffrax.LocalLinearInterpolation]] = (
        diffrax.LocalLinearInterpolation
    )
    rtol: float = 1e-13
    atol: float = 1e-13
    max_newton_steps: int = eqx.field(static=True, default=32)

    def order(self, terms: Any) -> int:
        del terms
        return 2

    def init(self, terms, t0, t1, y0, args) -> _State:
        del terms, t0, t1, args
        return zero_compensation(y0)

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        del made_jump
        term, t0, h = physical_step(terms, LagrangianTerm, t0, t1)
        lagrangian = term.lagrangian
        q0, p0 = y0
        _, unravel = ravel_pytree(q0)
        p0_flat, _ = ravel_pytree(p0)
        scale = 1.0 + jnp.max(jnp.abs(p0_flat))

        # In (q0, Δq) coordinates D1 L_d = ∂/∂q0 − ∂/∂Δq and D2 L_d = ∂/∂Δq, so the
        # discrete Euler–Lagrange equation p0 = −D1 L_d reads p1 = p0 + ∂L_d/∂q0.
        def momenta(increment_flat):
            gradients = jax.grad(discrete_lagrangian, argnums=(1, 2))(
                lagrangian, q0, unravel(increment_flat), t0, h, args
            )
            return tuple(ravel_pytree(g)[0] for g in gradients)

        def residual(increment_flat, _):
            dq0, p1 = momenta(increment_flat)
            return (p0_flat + dq0 - p1) / scale

        velocity = lagrangian.to_hamiltonian().velocity(q0, p0, t0, args)
        guess = h * ravel_pytree(velocity)[0]
        value, newton_result = root_find_in_step(
            residual,
            newton_for(guess.dtype, self.rtol, self.atol),
            guess,
            self.max_newton_steps,
        )
        # Δp = ∂L_d/∂q0 directly: no cancellation between p1 and p0.
        momentum_increment, _ = momenta(value)
        increment = (unravel(value), unravel(momentum_increment))
        y1, compensation = compensated_add(y0, increment, solver_state)
        result = diffrax.RESULTS.promote(newton_result)
        return y1, None, dict(y0=y0, y1=y1), compensation, result

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)
