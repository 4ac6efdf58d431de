r"""Extreme cases with closed forms: near-collision, near-separatrix, and a slow
rotation riding on a fast swing.

- **Kepler, e = 0.999** (`near_collision_kepler_case`): periapsis r_p = 10⁻³ a, where
  the speed √((1 + e)/(1 − e)) ≈ 45 is 45× the circular speed and the time scale
  r_p/v_p ≈ 2·10⁻⁵ is 3·10⁵ times shorter than the period. A fixed step sized for the
  orbit jumps over the encounter; an adaptive one shrinks there. Compared with
  Kepler's equation (`orbit_state`) at periapsis, where a phase error shows most.
- **Pendulum 10⁻⁹ below the separatrix** (`separatrix_pendulum_case`): the period
  grows like ln(1/gap), so an energy error ε shifts it by ~ε/gap — 10⁹ ε. After one
  exact period it must be back at its turning point, 6.3·10⁻⁵ rad below the top.
- **Foucault pendulum** (`FoucaultStudy`): the Earth's rate Ω = 7.3·10⁻⁵ rad/s turns
  the plane of a 1 rad/s swing; after thousands of swings the measured precession
  must match −Ω sin φ (1 − ⅜(a/l)²) (Airy's finite-amplitude correction, −3.9·10⁻⁵,
  is inside the tolerance only when it is included).

References: Goldstein, Poole & Safko, *Classical Mechanics*, 3rd ed., §3.7–3.8;
Landau & Lifshitz, *Mechanics*, §11 problem 1 and §39; DLMF §19.12 (K near m = 1);
G. B. Airy, Mem. R. Astron. Soc. 20, 121 (1851).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

import lagjax as lj
from benchmarks.stability_engine import Attempt, Case, Measured, judged_row
from lagjax import diagnostics
from lagjax.scenes.central import KeplerCartesian
from lagjax.scenes.earth import FoucaultPendulum
from lagjax.scenes.pendulums import SimplePendulum

SEPARATRIX_GAP = 1e-9  # (E_separatrix − E)/(E_separatrix − E_bottom)
SEPARATRIX_CASE = "pendulum 1e-9 below the separatrix, one period"


def near_collision_kepler_case(periods: int) -> Case:
    """e = 0.999 over `periods` orbits, ending at periapsis; Kepler's equation.

    Measured over 10 orbits: every fixed step degrades, even 10⁶ steps an orbit
    (h = 6·10⁻⁶ is still a third of r_p/v_p, and the symplectic methods' bounded
    energy error becomes a large one at the encounter); of the adaptive methods
    only Dopri8 at rtol 10⁻¹³ copes — at 10⁻¹² it is 3·10⁻⁴ off, Tsit5 at 10⁻¹²
    10⁻² — in ~4000 steps.
    """
    orbit = KeplerCartesian(eccentricity=jnp.asarray(0.999))
    t1 = periods * float(orbit.period())
    expected = np.concatenate(
        [np.asarray(x) for x in orbit.orbit_state(jnp.asarray(t1))]
    )
    per_orbit = lambda n: n * periods  # step counts are quoted per orbit
    attempts = [
        Attempt("StormerVerlet, 10⁵ steps/orbit", lj.StormerVerlet(), steps=per_orbit(10**5)),
        Attempt("Yoshida4, 10⁵ steps/orbit", lj.Yoshida4(), steps=per_orbit(10**5), in_quick=False),
        Attempt("StormerVerlet, 10⁶ steps/orbit", lj.StormerVerlet(), steps=per_orbit(10**6), in_quick=False),
        Attempt("Tsit5, rtol 1e-10", diffrax.Tsit5(), rtol=1e-10, in_quick=False),
        Attempt("Tsit5, rtol 1e-12", diffrax.Tsit5(), rtol=1e-12, in_quick=False),
        Attempt("Dopri8, rtol 1e-12", diffrax.Dopri8(), rtol=1e-12, in_quick=False),
        Attempt("Dopri8, rtol 1e-13", diffrax.Dopri8(), rtol=1e-13),
    ]  # fmt: skip
    return Case(
        f"Kepler e = 0.999, {periods} period{'s' * (periods > 1)}", orbit,
        orbit.initial_state(), t1, attempts, tolerance=1e-4, expected=expected,
    )  # fmt: skip


def separatrix_amplitude(gap: float) -> float:
    r"""θ₀ with $E - E_{\rm bottom} = 2mgl(1 - \mathrm{gap})$.

    $2mgl\sin^2(\theta_0/2) = 2mgl(1 - \mathrm{gap})$ gives
    $\cos(\theta_0/2) = \sqrt{\mathrm{gap}}$, so $\theta_0 = \pi - 2\arcsin\sqrt{\mathrm{gap}}$:
    the small distance from the top is computed directly. (`arccos(2 gap − 1)` would
    add 2·10⁻⁹ to −1 and keep only 7 of its digits.)
    """
    return math.pi - 2 * math.asin(math.sqrt(gap))


def separatrix_pendulum_case() -> Case:
    """One exact period (4K(m)/ω₀ by the AGM) from 10⁻⁹ below the separatrix.

    Compared as (π − θ, θ̇/ω₀): the error is relative to the turning point's
    distance from the top, 6.3·10⁻⁵ rad, not to π.

    Measured: the splittings come back to ~10⁻⁸ of that distance with 2·10³ to 10⁶
    steps, the adaptive methods at rtol 10⁻¹² miss by 4·10⁻⁴ (rtol 10⁻¹⁴ is
    needed). A symplectic method conserves a modified energy H + O(hᵖ) that keeps
    the top an equilibrium and shifts it and the nearby turning point alike, so the
    gap to *its* separatrix stays 10⁻⁹ up to a relative O(hᵖ). The gap is 2·10⁻⁹
    of |E|, so Dopri8's energy drift at rtol 10⁻¹², 5·10⁻¹¹ of |E|, is 2% of it.
    """
    pendulum = SimplePendulum(amplitude=separatrix_amplitude(SEPARATRIX_GAP))
    frequency = float(pendulum.small_amplitude_frequency())
    top = math.pi - float(pendulum.amplitude)
    attempts = [
        Attempt("Yoshida4, 2·10⁴ steps", lj.Yoshida4(), steps=20_000),
        Attempt("KahanLi8, 2000 steps", lj.KahanLi8(), steps=2000, in_quick=False),
        Attempt("StormerVerlet, 10⁶ steps", lj.StormerVerlet(), steps=10**6, in_quick=False),
        Attempt("Tsit5, rtol 1e-12", diffrax.Tsit5(), rtol=1e-12, in_quick=False),
        Attempt("Dopri8, rtol 1e-12", diffrax.Dopri8(), rtol=1e-12),
        Attempt("Dopri8, rtol 1e-14", diffrax.Dopri8(), rtol=1e-14, in_quick=False),
    ]  # fmt: skip
    return Case(
        SEPARATRIX_CASE, pendulum,
        pendulum.initial_state(), float(pendulum.period()), attempts, tolerance=1e-4,
        expected=np.array([top, 0.0]),
        comparable=lambda q, qdot: jnp.stack([jnp.pi - q, qdot / frequency]),
    )  # fmt: skip


@dataclass
class PeriodCheck:
    r"""The closed form the separatrix case relies on, checked before it is used.

    `SimplePendulum.period()` (K by the AGM of 1 and cos(θ₀/2)) against DLMF 19.12.1,
    $K = \Lambda + \tfrac{m_1}{4}(\Lambda - 1) + \tfrac{9}{64}m_1^2(\Lambda - \tfrac76)
    + O(m_1^3\Lambda)$, $\Lambda = \ln(4/\sqrt{m_1})$, at the same $m_1 = 1 - m$:
    the truncation is ~10⁻²⁷, so any difference is the AGM's.
    """

    name: str = SEPARATRIX_CASE
    tolerance: float = 1e-14

    def rows(self, timing: dict) -> Iterator[dict]:
        pendulum = SimplePendulum(amplitude=separatrix_amplitude(SEPARATRIX_GAP))

        def periods() -> tuple[jax.Array, jax.Array]:
            complement = jnp.cos(pendulum.amplitude / 2) ** 2
            big = jnp.log(4 / jnp.sqrt(complement))
            series = (big + complement / 4 * (big - 1)
                      + 9 / 64 * complement**2 * (big - 7 / 6))  # fmt: skip
            return pendulum.period(), 4 * series / pendulum.small_amplitude_frequency()

        def measure() -> Measured:
            timed = diagnostics.time_run(periods, **timing)
            agm, series = (float(x) for x in timed.output)
            return Measured(abs(agm / series - 1), timed.run_seconds,
                            timed.compile_seconds,
                            measure=f"T = {agm:.15g} s (series {series:.15g})")  # fmt: skip

        method = "closed form: period() by AGM vs DLMF 19.12.1"
        yield judged_row(self.name, method, self.tolerance, measure)


@dataclass
class FoucaultStudy:
    """The precession rate measured over `hours` of swinging, against Ω sin φ.

    The rate is `FoucaultPendulum.measured_precession_rate` (a tapered fit of the
    plane's angle, sampled 8× per swing); the error is relative to
    −Ω sin φ (1 − ⅜(a/l)²); the angle quoted is that rate times the run's length.

    Over the quarter turn every converged method agrees on a residual of 4.6·10⁻⁶,
    against 2·10⁻⁷ over the first hour: the closed form's, not the integrators'.
    The horizontal component Ω cos φ makes the swing slightly anisotropic, so the
    rate drifts with the plane's azimuth (measured with Dopri8: local rate from 0 to
    +9·10⁻⁶ as the plane turns from south to west at 45°; 6·10⁻¹⁰ at the pole,
    where that component vanishes). The tolerance, 10⁻⁵, sits between it and
    Airy's 3.9·10⁻⁵.
    """

    hours: float
    attempts: list[Attempt]
    tolerance: float = 1e-5
    name: str = field(init=False)

    def __post_init__(self):
        self.name = f"Foucault pendulum, {self.hours:.3g} h (Ω/ω₀ = 7e-5)"

    def rows(self, timing: dict) -> Iterator[dict]:
        scene = FoucaultPendulum()
        t1 = self.hours * 3600
        swings = t1 * float(jnp.sqrt(scene.gravity / scene.length)) / (2 * math.pi)
        ts = jnp.linspace(0.0, t1, math.ceil(8 * swings) + 1)
        expected = float(scene.precession_rate() * (1 + scene.airy_correction()))
        for attempt in self.attempts:
            yield judged_row(
                self.name, attempt.label, self.tolerance,
                lambda attempt=attempt: self._measure(scene, attempt, ts, expected),
            )  # fmt: skip

    def _measure(self, scene, attempt: Attempt, ts, expected: float) -> Measured:
        t1, steps = float(ts[-1]), attempt.steps
        dt, max_steps = (None, 10**6) if steps is None else (t1 / steps, steps + 2)

        def rate_and_energy(y0):
            swinging = lj.simulate(
                scene, y0, t1=t1, dt=dt, solver=attempt.solver, ts=ts,
                rtol=attempt.rtol, atol=attempt.rtol, max_steps=max_steps,
            )  # fmt: skip
            rate = scene.measured_precession_rate(swinging)
            return rate, diagnostics.energy_error(swinging)

        # One long run: repeating it would only add minutes to the same median.
        timed = diagnostics.time_run(
            rate_and_energy, scene.initial_state(), repeats=1, warmup=0
        )
        rate, energy = (float(x) for x in timed.output)
        without_airy = float(scene.precession_rate()) * t1
        measure = (f"turned {rate * t1:.6f} rad (expected {expected * t1:.6f}; "
                   f"without Airy's term {without_airy:.6f})")  # fmt: skip
        return Measured(abs(rate / expected - 1), timed.run_seconds,
                        timed.compile_seconds, energy, measure)  # fmt: skip


def foucault_study(quick: bool) -> FoucaultStudy:
    """A quarter of the precession period (8.4 h, 4800 swings); quick: one hour."""
    hours = 1.0 if quick else float(FoucaultPendulum().precession_period()) / 4 / 3600
    steps = lambda dt: round(hours * 3600 / dt)
    attempts = [
        Attempt("GaussLegendre(2), h = 0.05 s", lj.GaussLegendre(stages=2), steps=steps(0.05), in_quick=False),
        Attempt("GaussLegendre(2), h = 0.2 s", lj.GaussLegendre(stages=2), steps=steps(0.2), in_quick=False),
        Attempt("VariationalMidpoint, h = 0.05 s", lj.VariationalMidpoint(), steps=steps(0.05), in_quick=False),
        Attempt("Tsit5, rtol 1e-8", diffrax.Tsit5(), rtol=1e-8),
        Attempt("Tsit5, rtol 1e-10", diffrax.Tsit5(), rtol=1e-10, in_quick=False),
        Attempt("Dopri8, rtol 1e-10", diffrax.Dopri8(), rtol=1e-10, in_quick=False),
    ]  # fmt: skip
    return FoucaultStudy(hours, [a for a in attempts if a.in_quick or not quick])
