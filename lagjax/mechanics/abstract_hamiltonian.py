r"""`AbstractHamiltonian`: a system $H(q, p, t)$ and Hamilton's equations.

$$ \dot q = \frac{\partial H}{\partial p}, \qquad
   \dot p = -\frac{\partial H}{\partial q}. $$

The base of `Hamiltonian`, `SeparableHamiltonian` (`lagjax.mechanics.hamiltonian`)
and `LegendreHamiltonian` (`lagjax.mechanics.legendre_hamiltonian`): the state is
(q, p) for every solver, and the vector field is Hamilton's equations by autodiff.
It imports no Lagrangian, so a Lagrangian's Legendre transform can subclass it.

References: the course text §6.2 (Hamilton's equations, eq. 6.11–6.13), Goldstein,
*Classical Mechanics* §8.1–8.2.
"""

from __future__ import annotations

import abc
from typing import Any

import diffrax
import equinox as eqx
import jax

from lagjax._core.solver_kinds import DefaultMethod, is_partitioned
from lagjax._core.system import AbstractSystem
from lagjax._core.system_protocols import LagrangianLike
from lagjax._core.terms import HamiltonVectorField, LagrangianTerm


class AbstractHamiltonian(AbstractSystem):
    """A Hamiltonian system. Call it as `H(q, p, t=0.0, args=None)` for the value."""

    quadratic_in_momentum: eqx.AbstractVar[bool]

    # -- AbstractSystem: the state is (q, p) for every solver ----------------------

    @property
    def second_is_momentum(self) -> bool:
        return True

    def default_method(self, dt: Any) -> DefaultMethod:
        """Gauss–Legendre (2 stages) with `dt`, else adaptive `Tsit5`."""
        if dt is None:
            return DefaultMethod.ADAPTIVE
        return DefaultMethod.SYMPLECTIC_RUNGE_KUTTA

    def integration(self, solver: Any, y0: Any, t0: Any, args: Any) -> Any:
        """Hamilton's equations as one `ODETerm` (a separable H also gives the
        (drift, kick) pair of a splitting method)."""
        if solver.term_structure is LagrangianTerm:
            raise ValueError(
                f"{type(solver).__name__} discretizes a Lagrangian; got "
                f"{type(self).__name__}. Use .to_lagrangian() or another solver."
            )
        if is_partitioned(solver):
            raise ValueError(
                f"{type(solver).__name__} is a splitting method and needs a "
                "SeparableHamiltonian(T, V); for a general H use GaussLegendre, "
                "ImplicitMidpoint or an adaptive diffrax solver."
            )
        return diffrax.ODETerm(HamiltonVectorField(self)), y0, self

    def state_velocity(self, q: Any, second: Any, t: Any, args: Any) -> Any:
        return self.velocity(q, second, t, args)

    def state_momentum(self, q: Any, second: Any, t: Any, args: Any) -> Any:
        return second

    def state_energy(self, q: Any, second: Any, t: Any, args: Any) -> jax.Array:
        return self(q, second, t, args)

    def state_rate(self, q: Any, second: Any, t: Any, args: Any) -> tuple[Any, Any]:
        return self.vector_field(q, second, t, args)

    def path_lagrangian(self) -> LagrangianLike:
        return self.to_lagrangian()

    @abc.abstractmethod
    def __call__(self, q: Any, p: Any, t: Any = 0.0, args: Any = None) -> jax.Array:
        """The value of H."""

    def velocity(self, q: Any, p: Any, t: Any = 0.0, args: Any = None) -> Any:
        """q̇ = ∂H/∂p."""
        return jax.grad(self, argnums=1)(q, p, t, args)

    def vector_field(
        self, q: Any, p: Any, t: Any = 0.0, args: Any = None
    ) -> tuple[Any, Any]:
        """Hamilton's equations: `(dq/dt, dp/dt) = (∂H/∂p, −∂H/∂q)`."""
        dh_dq, dh_dp = jax.grad(self, argnums=(0, 1))(q, p, t, args)
        return dh_dp, jax.tree_util.tree_map(lambda x: -x, dh_dq)

    @abc.abstractmethod
    def to_lagrangian(self) -> LagrangianLike:
        """The Legendre-transformed Lagrangian L(q, q̇, t) = p·q̇ − H."""
