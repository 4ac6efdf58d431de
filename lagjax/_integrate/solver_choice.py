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
# Measured with `benchmarks/tolerance_choice.py` (from pericentre, 100 saves at
# apocentres, one pinned core of the loaded 2-core machine, fastest of five warm
# runs, ratios within one run), e = 0.5 … 0.9999 at rtol = atol = 1e-8, 1e-10,
# 1e-12: the energy stays at round-off (7e-15 … 2e-13 up to e = 0.999; 1.9e-12
# at e = 0.9999, the float64 floor of pericentre passages at speed 141) against
# Dopri8's 2e-10 … 3e-3; the mean anomaly errs 1e2 … 1e5 times less. Over 1000
# periods it is quicker at every e and rtol: 1.2× (e = 0.5, 1e-8) to 2.7×
# (e = 0.5, 1e-12) and 8.2× (e = 0.9999, 1e-12; 235 ms against 1.93 s). Over
# 100 periods (~0.1 s) per-call costs decide: 0.35–1.6× Dopri8's speed, slower
# in 8 of the 15 cases (most at 1e-8). Its first call compiles about twice as long (17 s against 9.6 s on
# the loaded machine). With three or more bodies Dopri8 stays: on the Pythagorean
# problem to t = 70, 41 ms (energy 1.6e-9) against TimeTransformed(Yoshida4) at
# ds = 0.005, 488 ms (5.7e-12; KahanLi8's round-off floor there is 4e-11, and no
# table reached 1e-12); on the outer solar system to 2e4 days Dopri8 takes 190
# steps (energy 6e-10) and WisdomHolman is the method for long runs.
# lj.ChainRegularization(GraggBulirschStoer) at the same rtol (eager, one pinned
# core, loaded machine) keeps the energy 2.6-1500x better but took 1.1-2.7x Dopri8's
# time: the Pythagorean problem at 1e-10 / 1e-12 (1401 saves) 23 / 22 ms against
# 15 / 19 ms, the outer solar system to 2e4 days 9.4 / 11.4 ms against 4.0 / 4.2
# ms (energy 4e-13 against 6e-10 at 1e-12), so it is no default; at equal energy
# on close encounters it is the method (`benchmarks/pythagorean_chain.py`).


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
