"""What terms and solvers need of a system, as structural types.

The terms in `lagjax._core.terms` and the solvers that read a system from its term
(variational, RATTLE, the constraint projection, the Lie–Poisson splittings) call a
few methods of a Lagrangian, a Hamiltonian or a rigid body. They are typed against
these protocols, not against the concrete classes of `lagjax.mechanics` and
`lagjax.rigid`, so the abstractions stay below the systems.
"""

from __future__ import annotations

from typing import Any, Protocol

import jax


class HamiltonianLike(Protocol):
    """A Hamiltonian system: its value, q̇ = ∂H/∂p and Hamilton's equations."""

    @property
    def quadratic_in_momentum(self) -> bool: ...

    def __call__(self, q: Any, p: Any, t: Any = 0.0, args: Any = None) -> jax.Array: ...

    def velocity(self, q: Any, p: Any, t: Any = 0.0, args: Any = None) -> Any: ...

    def vector_field(
        self, q: Any, p: Any, t: Any = 0.0, args: Any = None
    ) -> tuple[Any, Any]: ...


class SeparableLike(HamiltonianLike, Protocol):
    """H = T(p) + V(q): the drift ∂T/∂p and the kick −∂V/∂q apart."""

    def potential_force(self, q: Any, t: Any = 0.0, args: Any = None) -> Any: ...


class LagrangianLike(Protocol):
    """A Lagrangian system as the terms and solvers call it."""

    @property
    def quadratic_in_velocity(self) -> bool: ...

    @property
    def constraints(self) -> Any: ...

    @property
    def force(self) -> Any: ...

    @property
    def dissipation(self) -> Any: ...

    def __call__(
        self, q: Any, qdot: Any, t: Any = 0.0, args: Any = None
    ) -> jax.Array: ...

    def acceleration(
        self, q: Any, qdot: Any, t: Any = 0.0, args: Any = None, *, check: Any = None
    ) -> Any: ...

    def generalized_force(
        self, q: Any, qdot: Any, t: Any = 0.0, args: Any = None
    ) -> Any: ...

    def constraint_force(
        self, q: Any, qdot: Any, t: Any = 0.0, args: Any = None
    ) -> Any: ...

    def momentum(self, q: Any, qdot: Any, t: Any = 0.0, args: Any = None) -> Any: ...

    def mass_matrix(
        self, q: Any, qdot: Any, t: Any = 0.0, args: Any = None
    ) -> jax.Array: ...

    def to_hamiltonian(self) -> HamiltonianLike: ...

    def conserves_energy_if_autonomous(self) -> bool: ...


class RigidBodyLike(Protocol):
    """A rigid body: the vector field of (quaternion, body momentum)."""

    def vector_field(
        self, quaternion: Any, body_momentum: Any, t: Any = 0.0, args: Any = None
    ) -> tuple[Any, Any]: ...
