"""`AbstractSystem`: the one interface between a mechanical system and the loop.

Every system — `Lagrangian` (constrained or not), the Hamiltonians, `RigidBody` and
every scene — implements it, and `simulate`, `Trajectory`, the action and the
shooting code call nothing else:

| question | method |
|---|---|
| which system and parameters? (a scene is its system with itself as `args`) | `resolve(args)` |
| which solver when the caller names none? | `default_solver(dt)` |
| which solver does a request become? (a constrained L wraps it in a projection) | `adapt_solver(solver)` |
| which diffrax terms and start state for that solver, and whose state is it? | `integration(solver, y0, t0, args)` |
| q̇, p and the energy at an integrated state `(q, second)` | `state_velocity`, `state_momentum`, `state_energy` |
| is the second state component q̇ or p? | `second_is_momentum` |
| L along a path (the action) | `path_lagrangian()` |
| is the energy conserved when autonomous? (divergence checks) | `conserves_energy_if_autonomous()` |

The integrated state is the user's `y0` convention or the canonical one: a
`Lagrangian` integrated by a symplectic method runs on (q, p) of its Legendre
transform, so `integration` returns the system the state belongs to, and the
trajectory asks *that* system for q̇, p and the energy. A new kind of system is one
new class implementing these methods.
"""

from __future__ import annotations

import abc
from typing import TYPE_CHECKING, Any

import diffrax
import equinox as eqx

if TYPE_CHECKING:
    from lagjax.mechanics.lagrangian import Lagrangian


def is_partitioned(solver: diffrax.AbstractSolver) -> bool:
    """True for solvers that step (q, p) with two terms (splitting methods)."""
    structure = solver.term_structure
    return isinstance(structure, tuple) and len(structure) == 2


class AbstractSystem(eqx.Module):
    """A mechanical system as the integration loop sees it (module docstring)."""

    def resolve(self, args: Any) -> tuple[AbstractSystem, Any]:
        """The system to integrate and its `args` (scenes substitute themselves)."""
        return self, args

    @abc.abstractmethod
    def default_solver(self, dt: Any) -> diffrax.AbstractSolver:
        """The solver used when the caller names none (fixed step when `dt` is set)."""

    def adapt_solver(self, solver: diffrax.AbstractSolver) -> diffrax.AbstractSolver:
        """The solver that actually runs for a requested one (default: itself)."""
        return solver

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

    def path_lagrangian(self) -> Lagrangian:
        """The Lagrangian whose ∫L dt is this system's action along a path."""
        raise TypeError(
            f"{type(self).__name__} has no action functional: it needs a Lagrangian, "
            "a Hamiltonian or a scene"
        )
