r"""Hamiltonian systems: $H(q, p, t)$ and Hamilton's equations.

$$ \dot q = \frac{\partial H}{\partial p}, \qquad
   \dot p = -\frac{\partial H}{\partial q}. $$

Three final forms share one abstract base (`lagjax.mechanics.abstract_hamiltonian`):

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

from collections.abc import Callable
from typing import Any

import diffrax
import equinox as eqx
import jax
from jax.flatten_util import ravel_pytree

from lagjax._core.precision import cast_floats
from lagjax._core.solver_kinds import (
    AbstractSplittingMethod,
    DefaultMethod,
    is_partitioned,
)
from lagjax._core.terms import SeparableDrift, SeparableKick
from lagjax._linalg.small_gradient import small_gradient
from lagjax.mechanics.abstract_hamiltonian import (
    AbstractHamiltonian as AbstractHamiltonian,
)
from lagjax.mechanics.captured_globals import (
    captured_identity,
    warn_captured_numbers,
)
from lagjax.mechanics.declared_structure import check_declared_quadratic
from lagjax.mechanics.functions import as_system_function
from lagjax.mechanics.lagrangian import Lagrangian
from lagjax.mechanics.legendre import (
    invert_gradient,
    is_at_most_quadratic,
    tree_dot,
)
from lagjax.mechanics.legendre_hamiltonian import (
    LegendreHamiltonian as LegendreHamiltonian,
)
from lagjax.mechanics.signature import (
    call_with_arity,
    check_same_structure,
    check_scalar,
    positional_arity,
)


class AbstractUserHamiltonian(AbstractHamiltonian):
    """A Hamiltonian the user wrote (not a Legendre transform): its Lagrangian is
    the Legendre dual L = p·q̇ − H."""

    def check_start(self, y0: Any, t0: Any, args: Any, dtype: Any) -> None:
        """A declared `quadratic_in_momentum` must hold at the start (concrete
        values in the run's `dtype`, before the run)."""
        if not self.quadratic_in_momentum:
            return
        q0, p0 = cast_floats(tuple(y0), dtype)
        check_declared_quadratic(
            lambda fixed, p: self(fixed[0], p, *fixed[1:]),
            (q0, t0, cast_floats(args, dtype)),
            p0,
            key=self,
            flag="quadratic_in_momentum",
            what=f"the {type(self).__name__}'s H as a function of p",
        )

    def to_lagrangian(self) -> Lagrangian:
        """The Legendre-transformed Lagrangian L(q, q̇, t) = p·q̇ − H."""
        return Lagrangian(
            HamiltonianLegendreDual(self),
            quadratic_in_velocity=self.quadratic_in_momentum,
        )


class Hamiltonian(AbstractUserHamiltonian):
    """A general Hamiltonian `H(q, p)`, `H(q, p, t)` or `H(q, p, t, args)`.

    `quadratic_in_momentum=True` declares H at most quadratic in p, making the
    Legendre transform to L a single linear solve.

    H is compiled once and reused: numbers it reads from module globals are frozen
    at their value of the first run (rebinding them later changes nothing for this
    object; their values at construction are part of its identity, the static
    field `captured`, so a `Hamiltonian(H)` built after the rebinding compiles
    anew and reads the new value). Pass
    numbers that vary through `args`; a `CapturedNumberWarning` is raised here when
    H reads a module-level number not named in UPPER_CASE
    (`lagjax.mechanics.captured_globals`). The same holds for `SeparableHamiltonian`'s
    T and V.
    """

    function: Callable = eqx.field(converter=as_system_function)
    arity: int = eqx.field(static=True)
    quadratic_in_momentum: bool = eqx.field(static=True)
    # The module-level numbers H reads, as built (`captured_identity`).
    captured: tuple = eqx.field(static=True)

    def __init__(self, H: Callable, *, quadratic_in_momentum: bool = False):
        self.function = H
        self.arity = positional_arity(H, minimum=2, maximum=4, what="the Hamiltonian H")
        self.captured = captured_identity(warn_captured_numbers(H, "the Hamiltonian H"))
        self.quadratic_in_momentum = quadratic_in_momentum

    def __call__(self, q: Any, p: Any, t: Any = 0.0, args: Any = None) -> jax.Array:
        check_same_structure(q, p, "q", "p")
        value = call_with_arity(self.function, self.arity, q, p, t, args)
        return check_scalar(value, "the Hamiltonian H")


class SeparableHamiltonian(AbstractUserHamiltonian):
    """H = T(p) + V(q), with `T(p[, t[, args]])` and `V(q[, t[, args]])`.

    `quadratic_in_momentum=True` declares T quadratic in p (T = ½pᵀM⁻¹p); it is
    verified at the start of a run. Left False (the default), a T whose program is
    quadratic (`p @ p / (2 * m)`) is found so by reading it; a relativistic T is
    not, and the Runge–Kutta–Nyström splittings, which need a quadratic T to keep
    their order, are then refused.
    """

    kinetic: Callable = eqx.field(converter=as_system_function)
    kinetic_arity: int = eqx.field(static=True)
    potential: Callable = eqx.field(converter=as_system_function)
    potential_arity: int = eqx.field(static=True)
    quadratic_in_momentum: bool = eqx.field(static=True)
    # The module-level numbers T and V read, as built (`captured_identity`).
    captured: tuple = eqx.field(static=True)

    def __init__(
        self, T: Callable, V: Callable, *, quadratic_in_momentum: bool = False
    ):
        self.kinetic = T
        self.kinetic_arity = positional_arity(
            T, minimum=1, maximum=3, what="the kinetic energy T"
        )
        self.potential = V
        self.potential_arity = positional_arity(
            V, minimum=1, maximum=3, what="the potential energy V"
        )
        self.captured = captured_identity(
            warn_captured_numbers(T, "the kinetic energy T"),
            warn_captured_numbers(V, "the potential energy V"),
        )
        self.quadratic_in_momentum = quadratic_in_momentum

    def default_method(self, dt: Any) -> DefaultMethod:
        """`Yoshida4` with `dt` (explicit, symplectic, order 4), else `Tsit5`."""
        return DefaultMethod.ADAPTIVE if dt is None else DefaultMethod.SPLITTING

    def integration(self, solver: Any, y0: Any, t0: Any, args: Any) -> Any:
        """Hamilton's equations as one `ODETerm`, or the (drift, kick) pair of a
        splitting method."""
        if not is_partitioned(solver):
            return super().integration(solver, y0, t0, args)
        nystrom = isinstance(solver, AbstractSplittingMethod) and (
            solver.needs_quadratic_kinetic
        )
        if nystrom and not self._kinetic_is_quadratic(y0[1], t0, args):
            raise ValueError(
                f"{type(solver).__name__} is a Runge–Kutta–Nyström method: it keeps "
                "its order only for a kinetic energy quadratic in p, and this "
                "SeparableHamiltonian's T is not quadratic as written (a "
                "relativistic T, say). Use BlanesMoan6 or another splitting "
                "method; if T is quadratic, declare quadratic_in_momentum=True "
                "(checked at the start of the run)."
            )
        terms = (
            diffrax.ODETerm(SeparableDrift(self)),
            diffrax.ODETerm(SeparableKick(self)),
        )
        return terms, y0, self

    def _kinetic_is_quadratic(self, p0: Any, t0: Any, args: Any) -> bool:
        """Declared (and verified in `check_start`), or proven from T's program."""
        if self.quadratic_in_momentum:
            return True
        flat, unravel = ravel_pytree(p0)
        return is_at_most_quadratic(
            lambda p: self.kinetic_energy(unravel(p), t0, args), flat
        )

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
