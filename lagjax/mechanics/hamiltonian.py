r"""Hamiltonian systems: $H(q, p, t)$ and Hamilton's equations.

$$ \dot q = \frac{\partial H}{\partial p}, \qquad
   \dot p = -\frac{\partial H}{\partial q}. $$

Three final forms share one abstract base:

- `Hamiltonian(H)`: a general user function `H(q, p[, t[, args]])`.
- `SeparableHamiltonian(T, V)`: $H = T(p) + V(q)$. Its vector field never forms
  cross derivatives, and it enables the explicit splitting solvers.
- `LegendreHamiltonian(lagrangian)`: what `Lagrangian.to_hamiltonian()` returns. Its
  vector field is evaluated as $\dot q = \dot q(q, p)$ (solved from $p = \partial
  L/\partial \dot q$) and $\dot p = \partial L/\partial q + Q$, with no derivative
  taken through the solve.

References: the course text §6.2 (Hamilton's equations, eq. 6.11–6.13), Goldstein,
*Classical Mechanics* §8.1–8.2.
"""

from __future__ import annotations

import abc
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax

from lagjax._core.system import AbstractSystem, is_partitioned
from lagjax._linalg.small_gradient import small_gradient
from lagjax.mechanics.functions import as_system_function
from lagjax.mechanics.lagrangian import Lagrangian, singular_check
from lagjax.mechanics.legendre import invert_gradient, tree_dot
from lagjax.mechanics.signature import (
    call_with_arity,
    check_same_structure,
    check_scalar,
    positional_arity,
)


class AbstractHamiltonian(AbstractSystem):
    """A Hamiltonian system. Call it as `H(q, p, t=0.0, args=None)` for the value."""

    quadratic_in_momentum: eqx.AbstractVar[bool]

    # -- AbstractSystem: the state is (q, p) for every solver ----------------------
    # Imports are local: the solvers and terms are built on this module.

    @property
    def second_is_momentum(self) -> bool:
        return True

    def default_solver(self, dt: Any) -> Any:
        """`GaussLegendre(stages=2)` with `dt` (`Yoshida4` when separable), else
        adaptive `Tsit5`."""
        import diffrax

        from lagjax.solvers.implicit import GaussLegendre

        return diffrax.Tsit5() if dt is None else GaussLegendre(stages=2)

    def integration(self, solver: Any, y0: Any, t0: Any, args: Any) -> Any:
        """Hamilton's equations as one `ODETerm`, or the (drift, kick) pair of a
        splitting method for a separable H."""
        import diffrax

        from lagjax._core.terms import (
            HamiltonVectorField,
            LagrangianTerm,
            SeparableDrift,
            SeparableKick,
        )
        from lagjax.solvers.splitting import AbstractSplittingSolver

        if solver.term_structure is LagrangianTerm:
            raise ValueError(
                f"{type(solver).__name__} discretizes a Lagrangian; got "
                f"{type(self).__name__}. Use .to_lagrangian() or another solver."
            )
        if not is_partitioned(solver):
            return diffrax.ODETerm(HamiltonVectorField(self)), y0, self
        if not isinstance(self, SeparableHamiltonian):
            raise ValueError(
                f"{type(solver).__name__} is a splitting method and needs a "
                "SeparableHamiltonian(T, V); for a general H use GaussLegendre, "
                "ImplicitMidpoint or an adaptive diffrax solver."
            )
        nystrom = isinstance(solver, AbstractSplittingSolver) and (
            solver.needs_quadratic_kinetic
        )
        if nystrom and not self.quadratic_in_momentum:
            raise ValueError(
                f"{type(solver).__name__} is a Runge–Kutta–Nyström method: it keeps "
                "its order only for a kinetic energy quadratic in p, and this "
                "SeparableHamiltonian has quadratic_in_momentum=False. Use "
                "BlanesMoan6 or another splitting method."
            )
        terms = (
            diffrax.ODETerm(SeparableDrift(self)),
            diffrax.ODETerm(SeparableKick(self)),
        )
        return terms, y0, self

    def state_velocity(self, q: Any, second: Any, t: Any, args: Any) -> Any:
        return self.velocity(q, second, t, args)

    def state_momentum(self, q: Any, second: Any, t: Any, args: Any) -> Any:
        return second

    def state_energy(self, q: Any, second: Any, t: Any, args: Any) -> jax.Array:
        return self(q, second, t, args)

    def path_lagrangian(self) -> Lagrangian:
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

    def to_lagrangian(self) -> Lagrangian:
        """The Legendre-transformed Lagrangian L(q, q̇, t) = p·q̇ − H."""
        return Lagrangian(
            HamiltonianLegendreDual(self),
            quadratic_in_velocity=self.quadratic_in_momentum,
        )


class Hamiltonian(AbstractHamiltonian):
    """A general Hamiltonian `H(q, p)`, `H(q, p, t)` or `H(q, p, t, args)`.

    `quadratic_in_momentum=True` declares H at most quadratic in p, making the
    Legendre transform to L a single linear solve.
    """

    function: Callable = eqx.field(converter=as_system_function)
    arity: int = eqx.field(static=True)
    quadratic_in_momentum: bool = eqx.field(static=True)

    def __init__(self, H: Callable, *, quadratic_in_momentum: bool = False):
        self.function = H
        self.arity = positional_arity(H, minimum=2, maximum=4, what="the Hamiltonian H")
        self.quadratic_in_momentum = quadratic_in_momentum

    def __call__(self, q: Any, p: Any, t: Any = 0.0, args: Any = None) -> jax.Array:
        check_same_structure(q, p, "q", "p")
        value = call_with_arity(self.function, self.arity, q, p, t, args)
        return check_scalar(value, "the Hamiltonian H")


class SeparableHamiltonian(AbstractHamiltonian):
    """H = T(p) + V(q), with `T(p[, t[, args]])` and `V(q[, t[, args]])`.

    `quadratic_in_momentum` defaults to True (T = ½pᵀM⁻¹p is the usual case); set it
    to False for a non-quadratic kinetic energy such as the relativistic one.
    """

    kinetic: Callable = eqx.field(converter=as_system_function)
    kinetic_arity: int = eqx.field(static=True)
    potential: Callable = eqx.field(converter=as_system_function)
    potential_arity: int = eqx.field(static=True)
    quadratic_in_momentum: bool = eqx.field(static=True)

    def __init__(self, T: Callable, V: Callable, *, quadratic_in_momentum: bool = True):
        self.kinetic = T
        self.kinetic_arity = positional_arity(
            T, minimum=1, maximum=3, what="the kinetic energy T"
        )
        self.potential = V
        self.potential_arity = positional_arity(
            V, minimum=1, maximum=3, what="the potential energy V"
        )
        self.quadratic_in_momentum = quadratic_in_momentum

    def default_solver(self, dt: Any) -> Any:
        """`Yoshida4` with `dt` (explicit, symplectic, order 4), else `Tsit5`."""
        import diffrax

        from lagjax.solvers.splitting import Yoshida4

        return diffrax.Tsit5() if dt is None else Yoshida4()

    def kinetic_energy(self, p: Any, t: Any = 0.0, args: Any = None) -> jax.Array:
        value = call_with_arity(self.kinetic, self.kinetic_arity, p, t, args)
        return check_scalar(value, "the kinetic energy T")

    def potential_energy(self, q: Any, t: Any = 0.0, args: Any = None) -> jax.Array:
        value = call_with_arity(self.potential, self.potential_arity, q, t, args)
        return check_scalar(value, "the potential energy V")

    def __call__(self, q: Any, p: Any, t: Any = 0.0, args: Any = None) -> jax.Array:
        check_same_structure(q, p, "q", "p")
        return self.kinetic_energy(p, t, args) + self.potential_energy(q, t, args)

    def velocity(self, q: Any, p: Any, t: Any = 0.0, args: Any = None) -> Any:
        """q̇ = ∂T/∂p."""
        return jax.grad(self.kinetic_energy)(p, t, args)

    def potential_force(self, q: Any, t: Any = 0.0, args: Any = None) -> Any:
        """ṗ = −∂V/∂q."""
        gradient = small_gradient(self.potential_energy)(q, t, args)
        return jax.tree_util.tree_map(lambda x: -x, gradient)

    def vector_field(
        self, q: Any, p: Any, t: Any = 0.0, args: Any = None
    ) -> tuple[Any, Any]:
        check_same_structure(q, p, "q", "p")
        return self.velocity(q, p, t, args), self.potential_force(q, t, args)


class LegendreHamiltonian(AbstractHamiltonian):
    """The Hamiltonian of a `Lagrangian`, H(q, p, t) = p·q̇ − L at q̇ = q̇(q, p)."""

    lagrangian: Lagrangian
    quadratic_in_momentum: bool = eqx.field(static=True)

    def __init__(self, lagrangian: Lagrangian):
        self.lagrangian = lagrangian
        self.quadratic_in_momentum = lagrangian.quadratic_in_velocity

    def velocity(
        self,
        q: Any,
        p: Any,
        t: Any = 0.0,
        args: Any = None,
        *,
        check: bool | str | None = None,
    ) -> Any:
        """q̇ solved from p = ∂L/∂q̇(q, q̇, t).

        A singular mass matrix raises on concrete values and gives NaN under a
        trace (`check` None, as in `Lagrangian.acceleration`: a branch per
        evaluation would split an integration step; `simulate` reports the
        non-finite state after the loop). `check=True` always raises.
        """
        return self._velocity(q, p, t, args, singular_check(check, q, p, t))

    @eqx.filter_jit
    def _velocity(self, q, p, t, args, check):
        check_same_structure(q, p, "q", "p")
        return invert_gradient(
            lambda qdot: self.lagrangian(q, qdot, t, args),
            p,
            quadratic=self.lagrangian.quadratic_in_velocity,
            what="The mass matrix ∂²L/∂q̇∂q̇",
            check=check,
        )

    @eqx.filter_jit
    def __call__(self, q: Any, p: Any, t: Any = 0.0, args: Any = None) -> jax.Array:
        qdot = self.velocity(q, p, t, args)
        return tree_dot(p, qdot) - self.lagrangian(q, qdot, t, args)

    def vector_field(
        self,
        q: Any,
        p: Any,
        t: Any = 0.0,
        args: Any = None,
        *,
        check: bool | str | None = None,
    ) -> tuple[Any, Any]:
        """(q̇, ṗ) = (q̇(q, p), ∂L/∂q + Q − ∂D/∂q̇), non-conservative forces included.

        `check` as in `velocity`."""
        return self._vector_field(q, p, t, args, singular_check(check, q, p, t))

    @eqx.filter_jit
    def _vector_field(self, q, p, t, args, check):
        qdot = self._velocity(q, p, t, args, check)
        pdot = jax.grad(self.lagrangian, argnums=0)(q, qdot, t, args)
        force = self.lagrangian.generalized_force(q, qdot, t, args)
        if force is not None:
            pdot = jax.tree_util.tree_map(lambda a, b: a + b, pdot, force)
        return qdot, pdot

    def to_lagrangian(self) -> Lagrangian:
        """The Lagrangian this Hamiltonian was transformed from (exact round trip)."""
        return self.lagrangian

    def conserves_energy_if_autonomous(self) -> bool:
        return self.lagrangian.conserves_energy_if_autonomous()


class HamiltonianLegendreDual(eqx.Module):
    """L(q, q̇, t, args) = p·q̇ − H with p solved from q̇ = ∂H/∂p (a callable)."""

    hamiltonian: AbstractHamiltonian

    @eqx.filter_jit
    def __call__(self, q: Any, qdot: Any, t: Any, args: Any) -> jax.Array:
        p = invert_gradient(
            lambda p_: self.hamiltonian(q, p_, t, args),
            qdot,
            quadratic=self.hamiltonian.quadratic_in_momentum,
            what="The Hessian ∂²H/∂p∂p",
        )
        return tree_dot(p, qdot) - self.hamiltonian(q, p, t, args)
