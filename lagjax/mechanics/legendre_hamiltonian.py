r"""`LegendreHamiltonian`: the Hamiltonian of a Lagrangian, H = p·q̇ − L.

What `Lagrangian.to_hamiltonian()` returns. Its vector field is evaluated as
$\dot q = \dot q(q, p)$ (solved from $p = \partial L/\partial \dot q$,
`lagjax.mechanics.legendre`) and $\dot p = \partial L/\partial q + Q$, with no
derivative taken through the solve. It holds its Lagrangian as a structural type
(`LagrangianLike`), so `lagrangian.py` imports this module and not the reverse.

References: the course text §6.1 (the Legendre transform), Goldstein §8.1.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax

from lagjax._core.system_protocols import LagrangianLike
from lagjax._linalg.singular_verdicts import singular_check
from lagjax.mechanics.abstract_hamiltonian import AbstractHamiltonian
from lagjax.mechanics.legendre import invert_gradient, tree_dot
from lagjax.mechanics.signature import check_same_structure


class LegendreHamiltonian(AbstractHamiltonian):
    """The Hamiltonian of a `Lagrangian`, H(q, p, t) = p·q̇ − L at q̇ = q̇(q, p)."""

    lagrangian: LagrangianLike
    quadratic_in_momentum: bool = eqx.field(static=True)

    def __init__(self, lagrangian: LagrangianLike):
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

    def to_lagrangian(self) -> LagrangianLike:
        """The Lagrangian this Hamiltonian was transformed from (exact round trip)."""
        return self.lagrangian

    def conserves_energy_if_autonomous(self) -> bool:
        return self.lagrangian.conserves_energy_if_autonomous()
