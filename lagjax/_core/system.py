"""`AbstractSystem`: the one interface between a mechanical system and the loop.

Every system — `Lagrangian` (constrained or not), the Hamiltonians, `RigidBody` and
every scene — implements it, and `simulate`, `Trajectory`, the action and the
shooting code call nothing else:

| question | method |
|---|---|
| which system and parameters? (a scene is its system with itself as `args`) | `resolve(args)` |
| which method when the caller names none? | `default_method(dt)` |
| must every solver keep constraints? (a constrained L: projected or RATTLE) | `keeps_constraints()` |
| which diffrax terms and start state for that solver, and whose state is it? | `integration(solver, y0, t0, args)` |
| q̇, p and the energy at an integrated state `(q, second)` | `state_velocity`, `state_momentum`, `state_energy` |
| is the second state component q̇ or p? | `second_is_momentum` |
| L along a path (the action) | `path_lagrangian()` |
| the rates (q̇, q̈) or (q̇, ṗ) in the caller's convention (phase-space tools) | `state_rate` |
| is y0 a sound pair for this system? is the start admissible? | `checked_state_pair`, `check_start` |
| which system-specific terms (Lie–Poisson, RATTLE) may its solvers ask for? | `accepted_terms`, `refuse_solver` |
| the span and step of a run that names none | `default_span()` |
| can the phase-space tools take it? | `phase_space_obstacle()` |
| is the energy conserved when autonomous? (divergence checks) | `conserves_energy_if_autonomous()` |
| is it a gravitating separable H (a time-transformed method may suit)? | `gravitation(args)` |

The integrated state is the user's `y0` convention or the canonical one: a
`Lagrangian` integrated by a symplectic method runs on (q, p) of its Legendre
transform, so `integration` returns the system the state belongs to, and the
trajectory asks *that* system for q̇, p and the energy. A new kind of system is one
new class implementing these methods. The solvers a system dispatches on are the
abstract kinds of `lagjax._core.solver_kinds`; which concrete solver a default or a
constraint projection becomes is decided above both, in
`lagjax._integrate.solver_choice`.
"""

from __future__ import annotations

import abc
from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp

from lagjax._core.gravitation import Gravitation
from lagjax._core.solver_kinds import DefaultMethod
from lagjax._core.solver_kinds import is_partitioned as is_partitioned
from lagjax._core.system_protocols import LagrangianLike
from lagjax._core.terms import RattleTerm, RigidBodyTerm

DEFAULT_T1 = 10.0  # the end time of a run that names none, for a plain system


class AbstractSystem(eqx.Module):
    """A mechanical system as the integration loop sees it (module docstring)."""

    def resolve(self, args: Any) -> tuple[AbstractSystem, Any]:
        """The system to integrate and its `args` (scenes substitute themselves)."""
        return self, args

    @abc.abstractmethod
    def default_method(self, dt: Any) -> DefaultMethod:
        """The method used when the caller names no solver (fixed step when `dt` is
        set); `lagjax._integrate.solver_choice` makes it a solver."""

    def keeps_constraints(self) -> bool:
        """Whether every solver must keep constraints: plain solvers are then run
        with a projection onto them, and structure-preserving ones refused."""
        return False

    @abc.abstractmethod
    def integration(
        self, solver: diffrax.AbstractSolver, y0: Any, t0: Any, args: Any
    ) -> tuple[Any, Any, AbstractSystem]:
        """`(terms, state0, integrated)`: diffrax terms for `solver`, the start state
        they integrate, and the system that state belongs to. Raises a clear error
        when `solver` cannot integrate this system."""

    @property
    @abc.abstractmethod
    def second_is_momentum(self) -> bool:
        """Whether the second component of the integrated state is p (else q̇)."""

    @abc.abstractmethod
    def state_velocity(self, q: Any, second: Any, t: Any, args: Any) -> Any:
        """q̇ at the integrated state (q, second)."""

    @abc.abstractmethod
    def state_momentum(self, q: Any, second: Any, t: Any, args: Any) -> Any:
        """The second state component's conjugate: p (or the body momentum)."""

    @abc.abstractmethod
    def state_energy(self, q: Any, second: Any, t: Any, args: Any) -> Any:
        """H, or Jacobi's integral h, at the integrated state."""

    def conserves_energy_if_autonomous(self) -> bool:
        """Whether the energy is conserved when nothing depends on t explicitly:
        no generalized forces, dissipation or constraints (`lagjax._integrate.checks.run_verdict`)."""
        return True

    def path_lagrangian(self) -> LagrangianLike:
        """The Lagrangian whose ∫L dt is this system's action along a path."""
        raise TypeError(
            f"{type(self).__name__} has no action functional: it needs a Lagrangian, "
            "a Hamiltonian or a scene"
        )

    @abc.abstractmethod
    def state_rate(self, q: Any, second: Any, t: Any, args: Any) -> tuple[Any, Any]:
        """The time derivative of (q, second) in the caller's convention: (q̇, q̈)
        for a Lagrangian, Hamilton's (q̇, ṗ) for a Hamiltonian."""

    def checked_state_pair(self, first: Any, second: Any) -> tuple[Any, Any]:
        """y0's components checked against each other: q0 and its partner (q̇0 or
        p0) have one entry per coordinate. Raises a clear error otherwise."""
        partner = "p0" if self.second_is_momentum else "qdot0"
        check_partners(first, second, partner)
        return first, second

    def check_start(self, y0: Any, t0: Any, args: Any, dtype: Any) -> None:
        """Refuse, on concrete values in the run's `dtype`, a start the system
        cannot take (a constrained Lagrangian: off its constraints)."""
        del y0, t0, args, dtype

    def accepted_terms(self) -> tuple[type, ...]:
        """The system-specific terms (`RigidBodyTerm`, `RattleTerm`) whose solvers
        can integrate this system."""
        return ()

    def refuse_solver(self, solver: diffrax.AbstractSolver) -> None:
        """Refuse by name a solver written for another kind of system."""
        structure = solver.term_structure
        if not isinstance(structure, type) or issubclass(
            structure, self.accepted_terms()
        ):
            return
        name, kind = type(solver).__name__, type(self).__name__
        if issubclass(structure, RigidBodyTerm):
            raise TypeError(
                f"{name} is a Lie–Poisson solver for a lagjax.RigidBody (state: unit "
                f"quaternion and body angular momentum); {kind} is not one. Use a "
                "solver for generalized coordinates (GaussLegendre, Tsit5, a splitting "
                "method for separable H); a rigid scene gives its body as "
                "scene.rigid_body()"
            )
        if issubclass(structure, RattleTerm):
            raise TypeError(
                f"{name} integrates a constrained Lagrangian, "
                f"lagjax.Lagrangian(L, constraints=g); {kind} has no constraints. Use "
                "StormerVerlet (separable H), GaussLegendre or Tsit5"
            )

    def default_span(self) -> tuple[float, float | None]:
        """`(t1, dt)` of a run that names neither (dt None: adaptive)."""
        return DEFAULT_T1, None

    def gravitation(self, args: Any) -> Gravitation | None:
        """For a separable H = T(p) + V(q) with V < 0 attractive and vanishing at
        infinity, its bodies and dynamical time (`Gravitation`); None otherwise.
        A tolerance run may then pick a time-transformed method
        (`lagjax._integrate.geometric_choice`)."""
        del args
        return None

    def phase_space_obstacle(self) -> str | None:
        """Why the phase-space tools (Lyapunov spectra, sections, indicators) cannot
        take this system, or None when they can."""
        return None


def check_partners(q: Any, second: Any, partner: str) -> None:
    """q0 and its partner must have the same pytree structure and leaf shapes."""
    q_leaves, q_tree = jax.tree_util.tree_flatten(q)
    s_leaves, s_tree = jax.tree_util.tree_flatten(second)
    if q_tree != s_tree:
        raise ValueError(
            f"q0 and {partner} must have the same structure, got {q_tree} and "
            f"{s_tree}: give {partner} one entry per coordinate of q0"
        )
    for a, b in zip(q_leaves, s_leaves):
        if jnp.shape(a) != jnp.shape(b):
            raise ValueError(
                f"q0 and {partner} must have the same shapes, got {jnp.shape(a)} and "
                f"{jnp.shape(b)}: give {partner} one entry per coordinate of q0"
            )
