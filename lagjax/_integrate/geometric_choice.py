r"""Tolerance runs of a Kepler problem: the logarithmic Hamiltonian at a derived step.

A tolerance run (`rtol` given, no solver, no `dt`) of a system that declares itself
a gravitating two-body problem (`AbstractSystem.gravitation`) runs
`TimeTransformed(KahanLi8())` instead of `Dopri8`, with the fictitious step chosen
from `rtol`:

**The rule.** With the logarithmic Hamiltonian, a composition of position-form
leapfrogs moves exactly on the Kepler orbit: the energy, angular momentum and
Runge–Lenz vector are kept to round-off at any step (Mikkola & Tanikawa 1999;
Preto & Tremaine 1999); only the timing along the orbit errs. In the
dimensionless step $h = ds / (2|E|\tau)$ ($\tau = \sqrt{a^3/\mu}$: $2\pi/h$ steps
per period at any eccentricity), KahanLi8's mean-anomaly error per $\tau$ is
$C h^8$ with $C$ = 3.0–3.2e-7 at every e from 0 to 0.9999 (measured over 10
periods at h = 0.3, 0.4, 0.6) — the transformation makes every orbit alike. The
step keeps it below rtol with a safety factor:

$$h = \left(\frac{\mathrm{rtol}}{\mathrm{SAFETY}\cdot C}\right)^{1/8}
\quad (0.19 \text{ at rtol} = 10^{-12}).$$

**Where it is chosen** (`benchmarks/tolerance_choice.py` has the figures): two
bodies, rtol below `GEOMETRIC_RTOL`, a bound orbit, concrete inputs, and a run that
asks for no option the time-transformed run lacks (`saveat`, `dense`, events,
adjoints, step controllers, `max_steps`). With more bodies the encounters set the
error and `Dopri8` was faster at the same rtol (the Pythagorean problem, the outer
solar system); under `jit`, `vmap` or `grad` the default stays `Dopri8` too, whose
run reverse-mode differentiates without a `max_steps`.

References: Mikkola & Tanikawa, Celest. Mech. Dyn. Astron. 74, 287 (1999); Preto
& Tremaine, Astron. J. 118, 2532 (1999); Kahan & Li, Math. Comp. 66, 1089 (1997).
"""

from __future__ import annotations

from typing import Any

import jax
import numpy as np
from jax.core import Tracer

from lagjax._core.system import AbstractSystem
from lagjax.solvers.splitting import KahanLi8
from lagjax.solvers.time_transformed import TimeTransformed

# KahanLi8's mean-anomaly error per dynamical time, C in C·h⁸ (module docstring:
# 3.0–3.2e-7 for e = 0 … 0.9999).
TIMING_CONSTANT = 3.2e-7
ORDER = 8
SAFETY = 2.0
# Below it TimeTransformed(KahanLi8) was quicker than Dopri8 over 1000 periods of
# Kepler orbits, e = 0.5 … 0.9999 (1.2–8×), at round-off energy against Dopri8's
# 2e-10 … 3e-3 (`lagjax._integrate.solver_choice` has the figures).
GEOMETRIC_RTOL = 1e-7
# Beyond this many steps Dopri8 stays (it would take as long). On a Kepler orbit
# s advances by ∫(−V)dt = 2|E|·t (the virial theorem), so a run takes about
# span·2|E|/ds steps, whatever the units (ds is tiny in AU and days).
MAX_SPAN_IN_STEPS = 1e8


def fictitious_step(rtol: float, energy: float, dynamical_time: float) -> float:
    """ds = h·2|E|τ with h from the rule of the module docstring."""
    h = (rtol / (SAFETY * TIMING_CONSTANT)) ** (1 / ORDER)
    return h * 2 * abs(energy) * dynamical_time


def geometric_default(
    system: AbstractSystem, y0: Any, t0: Any, t1: Any, args: Any, rtol: float
) -> tuple[TimeTransformed, float] | None:
    """`(solver, ds)` for a tolerance run of a gravitating two-body system at
    `rtol`, or None where the current default stays (module docstring). Call it
    only for a plain tolerance run (no solver, dt, or option TimeTransformed
    refuses)."""
    if not isinstance(system, AbstractSystem):
        return None  # simulate names the problem
    if rtol >= GEOMETRIC_RTOL or _traced(y0, args, t0, t1, system):
        return None
    gravitation = system.gravitation(args)
    if gravitation is None or gravitation.bodies != 2:
        return None
    integrated, resolved_args = system.resolve(args)
    try:  # a y0 that does not fit: the run's own checks name the problem
        q0, p0 = y0
        energy = np.asarray(integrated.state_energy(q0, p0, t0, resolved_args))
    except (TypeError, ValueError):
        return None
    tau = np.asarray(gravitation.dynamical_time)
    if energy.size != 1 or tau.size != 1:
        return None  # a batch of scenes: one step would not fit them all
    energy, tau = float(energy.item()), float(tau.item())
    if not (np.isfinite(energy) and energy < 0 and tau > 0):
        return None  # unbound or undefined: the rule is calibrated on ellipses
    ds = fictitious_step(rtol, energy, tau)
    span = (system.default_span()[0] if t1 is None else t1) - t0
    if not span * 2 * abs(energy) / ds < MAX_SPAN_IN_STEPS:
        return None
    return TimeTransformed(KahanLi8()), ds


def _traced(*trees: Any) -> bool:
    return any(isinstance(x, Tracer) for x in jax.tree_util.tree_leaves(trees))
