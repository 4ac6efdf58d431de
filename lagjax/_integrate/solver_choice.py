"""Which solver runs: the default a system asks for, and what a request becomes.

A system names a `DefaultMethod` (`AbstractSystem.default_method`) and says whether
every solver must keep its constraints (`keeps_constraints`); this module, above
both the systems and the solvers, turns that into a concrete solver. Adding a
default is one entry in `_DEFAULTS`; a new system kind picks from it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import diffrax

from lagjax._core.solver_kinds import (
    AbstractConstraintKeeping,
    AbstractSymplecticRungeKutta,
    DefaultMethod,
    is_partitioned,
)
from lagjax._core.system import AbstractSystem
from lagjax._core.terms import LagrangianTerm
from lagjax.solvers.implicit import GaussLegendre
from lagjax.solvers.lie_poisson import QuaternionProjection, RigidBodyYoshida4
from lagjax.solvers.projection import ConstraintProjection
from lagjax.solvers.splitting import Yoshida4

_DEFAULTS: dict[DefaultMethod, Callable[[], diffrax.AbstractSolver]] = {
    DefaultMethod.ADAPTIVE: diffrax.Tsit5,
    DefaultMethod.ADAPTIVE_UNIT_QUATERNION: lambda: QuaternionProjection(
        diffrax.Tsit5()
    ),
    DefaultMethod.SYMPLECTIC_RUNGE_KUTTA: lambda: GaussLegendre(stages=2),
    DefaultMethod.SPLITTING: Yoshida4,
    DefaultMethod.LIE_POISSON: RigidBodyYoshida4,
}


def default_solver(system: AbstractSystem, dt: Any) -> diffrax.AbstractSolver:
    """The solver that runs `system` when the caller names none (before
    `adapt_solver`): fixed step when `dt` is given, adaptive otherwise."""
    return _DEFAULTS[system.default_method(dt)]()


def adapt_solver(
    system: AbstractSystem, solver: diffrax.AbstractSolver
) -> diffrax.AbstractSolver:
    """The solver that actually runs for a requested one: for a system that keeps
    constraints, a plain diffrax solver projected onto them, and solvers that would
    ignore them refused; otherwise the solver itself."""
    if not system.keeps_constraints() or isinstance(solver, AbstractConstraintKeeping):
        return solver
    structure_preserving = (
        is_partitioned(solver)
        or isinstance(solver, AbstractSymplecticRungeKutta)
        or solver.term_structure is LagrangianTerm
    )
    if structure_preserving or not isinstance(solver.term_structure, type):
        raise ValueError(
            f"{type(solver).__name__} does not enforce constraints. Integrate a "
            "constrained Lagrangian with an (explicit or implicit) diffrax solver, "
            "which simulate projects onto the constraints after each step, or with "
            "Rattle (holonomic constraints, constant mass matrix)."
        )
    return ConstraintProjection(solver)


def chosen_solver(
    system: AbstractSystem, solver: diffrax.AbstractSolver | None, dt: Any
) -> diffrax.AbstractSolver:
    """`adapt_solver` of the requested solver, or of the default when none is."""
    return adapt_solver(
        system, default_solver(system, dt) if solver is None else solver
    )
