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


# Below this relative tolerance a fifth-order method needs thousands of steps per
# unit time (Tsit5 on the double pendulum at 1e-12: 24,000 steps to t = 100);
# an eighth-order one a tenth of that.
HIGH_ORDER_RTOL = 1e-9

# Below it, conservative systems stay with Dopri8 too (issue 30, measured at
# rtol = atol = 1e-12, one core of the loaded machine, one run): lj.Taylor's JAX
# route took 26 s against Dopri8's 0.10 s on the double pendulum to t = 100 (energy
# 3e-11 vs 9e-11) and 9.3 s against 0.04 s on a pendulum (4e-13 vs 5e-11); its
# heyoka route is quicker (61 ms) but runs on concrete values only, and a default
# must run under jit, vmap and grad.
#
# A system that declares itself a gravitating two-body problem
# (`AbstractSystem.gravitation`; the Kepler scene) runs TimeTransformed(KahanLi8)
# instead below rtol 1e-7, its fictitious step derived from rtol
# (`lagjax._integrate.geometric_choice`; simulate asks it before this module).
# Measured (`benchmarks/tolerance_choice.py`, 100 periods from pericentre, saves at
# the apocentres, one pinned core of the loaded 2-core machine, fastest of five
# warm runs): at rtol 1e-12 the energy stays at round-off (2e-15 … 4e-12, the
# last the start state's own rounding at e = 0.9999) against Dopri8's 6e-11 …
# 8.5e-9, the mean anomaly within 3e-10 … 3e-9 rad against 1e-8 … 4e-6, in
# 77–100 ms against Dopri8's 64–150 ms (slower at e = 0.5, 1.25×; quicker from
# e = 0.999 on, 1.5×); at 1e-10, 1.9e-15 … 4e-12 and 3e-8 rad against 6e-9 …
# 4e-6 and 2e-6 … 2e-3 rad. Its first call compiles about twice as long as
# Dopri8's (17 s against 9.6 s on the loaded machine). With three or more bodies
# Dopri8 stays: on the Pythagorean problem to t = 70 it took 66 ms (energy 1.6e-9)
# against TimeTransformed(Yoshida4) at ds = 0.005, 818 ms (5.7e-12; KahanLi8's
# round-off floor there is 4e-11, and no table reached 1e-12); on the outer solar
# system to 2e4 days Dopri8 took 190 steps (energy 6e-10).


def default_solver(
    system: AbstractSystem, dt: Any, rtol: float | None = None
) -> diffrax.AbstractSolver:
    """The solver that runs `system` when the caller names none (before
    `adapt_solver`): fixed step when `dt` is given, adaptive otherwise — `Dopri8`
    instead of `Tsit5` when `rtol` is below `HIGH_ORDER_RTOL`."""
    solver = _DEFAULTS[system.default_method(dt)]()
    if dt is None and rtol is not None and rtol < HIGH_ORDER_RTOL:
        solver = _higher_order(solver)
    return solver


def _higher_order(solver: diffrax.AbstractSolver) -> diffrax.AbstractSolver:
    """Tsit5 → Dopri8, inside a projection wrapper too."""
    if isinstance(solver, diffrax.Tsit5):
        return diffrax.Dopri8()
    if isinstance(solver, QuaternionProjection) and isinstance(
        solver.solver, diffrax.Tsit5
    ):
        return QuaternionProjection(diffrax.Dopri8())
    return solver


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
    system: AbstractSystem,
    solver: diffrax.AbstractSolver | None,
    dt: Any,
    rtol: float | None = None,
) -> diffrax.AbstractSolver:
    """`adapt_solver` of the requested solver, or of the default when none is."""
    if solver is None:
        solver = default_solver(system, dt, rtol)
    return adapt_solver(system, solver)
