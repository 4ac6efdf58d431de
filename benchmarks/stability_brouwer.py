r"""Round-off over 10⁶ periods of a harmonic oscillator: Brouwer's law for the splittings.

Each rounding error of a long run is a small random kick to the invariants; if the
kicks are unbiased they add up like a random walk, so the energy error grows like
√n (Brouwer's law), not like n. This study measures the growth exponent for
`StormerVerlet` and `Yoshida4`, with and without Kahan-compensated increments
(their `compensated` field), over 10⁶ periods (`--quick`: 10⁴).

**What is measured, and why that way.** The energy error of a symplectic method has
a truncation part — bounded and periodic, ~(hω)²/8, 10⁻³ for Störmer–Verlet here —
that would hide round-off (10⁻¹⁶ per step) completely. On a linear problem it can be
removed exactly: one step is a linear symplectic map M (the same at every step), and
for any M ∈ SL(2) the quadratic form
$y^T J(M - M^{-1})\,y = y^T J(2M - \operatorname{tr}M)\,y$ is conserved by M
exactly (it commutes with M, and $M^T J M = J$). That *modified energy* H̃ is built
here from the solver's own coefficient tables in extended precision
(`numpy.longdouble`), so in exact arithmetic H̃ would not move at all: every change
of H̃ along the run is round-off. The run is read in windows ending at
n = 10¹, 10², …, 10⁶ periods, each its last tenth (10 samples in (0.9n, n]); the
error at window n is max |H̃ − H̃₀|/H̃₀ over the window, as an RMS over 32
oscillators started at different phases (Brouwer's law is a statement about a
distribution; one run alone scatters by a factor ~2). The exponent is the
least-squares slope of log error against log n, with a bootstrap standard error
over the 32 runs. Outcome: **accurate** if the exponent is within 0.15 of ½; the
`error` column is the RMS at the last window, `energy` the error of H itself there.

**Measured** (10⁶ periods): exponents 0.49–0.50 ± 0.01 for all four variants —
the round-off is unbiased with or without compensation. Compensation lowers its
level 10× for Störmer–Verlet (7·10⁻¹⁴ against 7·10⁻¹³ at 10⁶ periods: it rounds
the increment, ~hω times the state) and 4× for Yoshida4 (1.4·10⁻¹³ against
6·10⁻¹³), whose increment sums three substeps with weights up to 1.7.

**Set-up choices that matter at this level.**

- The period is 1 s and the step 2⁻⁶ s (64 steps per period, hω = 0.098): a power
  of two, so every time k·h is exact and every step has exactly the same h. With
  h = 1/60 the times t₀ + k·h round, the steps t_{k+1} − t_k differ by ~ulp(t), and
  the modified energy — which depends on h — random-walks by ~(hω)² ulp(t)/h per
  step: a growth faster than √n that is the *time grid's* round-off, not the
  state's. The "raw" row shows it; `lj.simulate` now rounds such a dt onto an
  exact grid (`lagjax._integrate.time_grid.grid_step`, a relative change below 1e-8), and the
  "exact grid" row shows the √n law restored.
- The run is one `lax.scan` over the solver's own `step`, carrying its state (the
  Kahan compensation) from the first step to the last, with times t₀ + k·h as
  `lj.simulate`'s fixed-step path forms them. Chaining `lj.simulate` calls to read
  the windows would restart the compensation at every call; restarting once per
  period was measured to double the compensated error at 10⁴ periods.

References: Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed.,
Springer 2006, §VIII.5 (round-off, compensated summation, Brouwer's law);
D. Brouwer, Astron. J. 51, 37 (1944); Hairer, McLachlan & Razakarivony, BIT 48, 231
(2008) (Brouwer's law for implicit Runge–Kutta methods).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

import lagjax as lj
from benchmarks.stability_engine import Measured, judged_row
from lagjax import diagnostics
from lagjax._integrate.time_grid import grid_step
from lagjax.scenes.oscillators import HarmonicOscillator

SAMPLES = 10  # per window, at n·(0.91, 0.92, …, 1.00) periods
ENSEMBLE = 32  # oscillators, started at different phases
# 64-bit mantissa on x86 Linux: M and H̃ 2¹¹ × finer than float64. Where longdouble
# is double (Windows, Apple silicon) the n = 10 window gains a ~10⁻¹⁶ floor.
EXTENDED = np.longdouble


def oscillator() -> HarmonicOscillator:
    """m = 1, k = (2π)²: ω ≈ 2π rad/s, a period of 1 s."""
    return HarmonicOscillator(stiffness=(2 * math.pi) ** 2)


def step_matrix(solver, stiffness: float, step: float) -> np.ndarray:
    """One step of a splitting method on q̈ = −k q (m = 1), in extended precision."""

    def kick(b):
        return np.array(
            [[1, 0], [-EXTENDED(b) * EXTENDED(step) * EXTENDED(stiffness), 1]]
        )

    def drift(a):
        return np.array([[1, EXTENDED(a) * EXTENDED(step)], [0, 1]])

    matrix = kick(solver.kick_coefficients[0])
    for a, b in zip(solver.drift_coefficients, solver.kick_coefficients[1:]):
        matrix = kick(b) @ drift(a) @ matrix
    return matrix.astype(EXTENDED)


def conserved_form(matrix: np.ndarray) -> np.ndarray:
    """S with Mᵀ S M = S: J(2M − tr M), for M = [[a, b], [c, d]], det M = 1."""
    (a, b), (c, d) = matrix
    return np.array([[c, (d - a) / 2], [(d - a) / 2, -b]], dtype=EXTENDED)


def _window_samples(decades: int) -> tuple[np.ndarray, np.ndarray]:
    """The periods read (ascending) and the window each belongs to.

    Window j covers the last tenth of the run up to n = 10^(j+1) periods, read at
    SAMPLES evenly spread periods: the same fraction at every n, so the window
    maximum of a random walk scales exactly like its typical size, √n. (A window of
    fixed length would span the whole run at n = 10 and a sliver of it at 10⁶,
    inflating the first point by ~1.4 and flattening the fit by ~0.04.)
    """
    periods, windows = [], []
    for j in range(decades):
        fractions = 0.9 + 0.1 * np.arange(1, SAMPLES + 1) / SAMPLES
        picked = np.unique(np.round(10 ** (j + 1) * fractions).astype(int))
        periods.extend(picked)
        windows.extend([j] * len(picked))
    return np.asarray(periods), np.asarray(windows)


def _slots(periods: np.ndarray) -> np.ndarray:
    """For each period of the run, where its end state is saved, or a slot past
    the end (which `.at[].set(mode="drop")` ignores)."""
    slots = np.full(periods[-1], len(periods))
    slots[periods - 1] = np.arange(len(periods))
    return slots


def _record(solver, step: float, per_period: int, slots: np.ndarray):
    """A function y0 ↦ the states at the window samples (one run, one scan)."""
    scene = oscillator()
    hamiltonian = scene.system()
    # The same (drift, kick) pair lj.simulate builds for a SeparableHamiltonian.
    terms = (
        diffrax.ODETerm(lambda t, p, args: hamiltonian.velocity(None, p, t, args)),
        diffrax.ODETerm(lambda t, q, args: hamiltonian.potential_force(q, t, args)),
    )
    samples = int(slots.max())  # the past-the-end slot is the count

    def run(y0):
        def one_period(carry, period_and_slot):
            period, slot = period_and_slot

            def one_step(state, k):
                y, solver_state = state
                start, end = k * step, (k + 1) * step  # as lj.simulate's scan path
                y, _, _, solver_state, _ = solver.step(
                    terms, start, end, y, scene, solver_state, False
                )
                return (y, solver_state), None

            y, solver_state, saved = carry
            first = period * per_period
            steps = first + jnp.arange(per_period)
            (y, solver_state), _ = jax.lax.scan(one_step, (y, solver_state), steps)
            saved = saved.at[slot].set(jnp.stack(y), mode="drop")
            return (y, solver_state, saved), None

        state = solver.init(terms, 0.0, step, y0, scene)
        saved = jnp.zeros((samples, 2))
        xs = (jnp.arange(len(slots)), jnp.asarray(slots))
        return jax.lax.scan(one_period, (y0, state, saved), xs)[0][2]

    return jax.vmap(run)


def _starts() -> tuple[jax.Array, jax.Array]:
    """Unit amplitude at ENSEMBLE phases: the same energy, different round-off."""
    phases = 2 * np.pi * (np.arange(ENSEMBLE) + 0.0123) / ENSEMBLE
    omega = float(oscillator().frequency())
    return jnp.asarray(np.cos(phases)), jnp.asarray(-omega * np.sin(phases))


def _relative_change(form: np.ndarray, states: np.ndarray, starts: np.ndarray):
    """|yᵀSy / y₀ᵀSy₀ − 1| in extended precision; states (runs, samples, 2)."""
    states, starts = states.astype(EXTENDED), starts.astype(EXTENDED)
    value = np.einsum("rsi,ij,rsj->rs", states, form, states)
    initial = np.einsum("ri,ij,rj->r", starts, form, starts)
    return np.abs(value / initial[:, None] - 1).astype(float)


def growth_exponent(periods: np.ndarray, maxima: np.ndarray, seed: int = 0):
    """Slope of log RMS(window max) against log n, and its bootstrap standard error.

    `maxima` has one row per run and one column per window.
    """

    def slope(rows):
        rms = np.sqrt(np.mean(rows**2, axis=0))
        return float(np.polyfit(np.log(periods), np.log(rms), 1)[0])

    picks = np.random.default_rng(seed).integers(0, len(maxima), (200, len(maxima)))
    spread = np.std([slope(maxima[pick]) for pick in picks])
    return slope(maxima), float(spread)


@dataclass
class BrouwerStudy:
    """Windows at 10¹ … 10^`decades` periods; attempts are (label, solver, step)."""

    decades: int
    attempts: list[tuple[str, Any, float]]
    tolerance: float = 0.15  # on |exponent − ½|
    name: str = field(init=False)

    def __post_init__(self):
        self.name = f"harmonic oscillator, 1e{self.decades} periods (round-off)"

    def rows(self, timing: dict) -> Iterator[dict]:
        for label, solver, step in self.attempts:
            yield judged_row(
                self.name, label, self.tolerance,
                lambda solver=solver, step=step: self._measure(solver, step),
            )  # fmt: skip

    def _measure(self, solver, step: float) -> Measured:
        scene, (periods, windows) = oscillator(), _window_samples(self.decades)
        per_period = round(1 / step)
        record = _record(solver, step, per_period, _slots(periods))
        starts = _starts()
        # One long run: a repeat would cost as much and say nothing new.
        timed = diagnostics.time_run(record, starts, repeats=1, warmup=0)
        states = np.asarray(timed.output)
        initial = np.stack([np.asarray(x) for x in starts], axis=-1)
        stiffness = float(scene.stiffness)
        modified = conserved_form(step_matrix(solver, stiffness, step))
        change = _relative_change(modified, states, initial)
        maxima = np.stack(
            [change[:, windows == j].max(axis=1) for j in range(self.decades)], axis=1
        )
        ends = 10.0 ** np.arange(1, self.decades + 1)
        exponent, spread = growth_exponent(ends, maxima)
        rms = np.sqrt(np.mean(maxima**2, axis=0))
        # The true energy, for scale: its error is the bounded truncation part.
        energy = np.diag(np.array([stiffness, 1], dtype=EXTENDED))  # 2H, m = 1
        last = states[:, windows == self.decades - 1]
        energy_error = float(_relative_change(energy, last, initial).max())
        measure = (f"H̃ error ∝ n^{exponent:.2f} ± {spread:.2f}: "
                   f"{rms[0]:.1e} at n = 10, {rms[-1]:.1e} at n = 1e{self.decades}")  # fmt: skip
        return Measured(float(rms[-1]), timed.run_seconds, timed.compile_seconds,
                        energy_error, measure, score=abs(exponent - 0.5))  # fmt: skip


def brouwer_study(quick: bool) -> BrouwerStudy:
    """Both splittings at 64 steps per period, compensated and plain; then h = 1/60."""
    dyadic, decades = 2.0**-6, 4 if quick else 6
    # lj.simulate rounds an awkward dt onto an exact grid (lagjax._integrate.time_grid).
    exact_sixtieth = grid_step(0.0, 10.0**decades, 1 / 60)
    attempts = [
        ("StormerVerlet, Kahan-compensated", lj.StormerVerlet(), dyadic),
        ("StormerVerlet, plain sums", lj.StormerVerlet(compensated=False), dyadic),
        ("Yoshida4, Kahan-compensated", lj.Yoshida4(), dyadic),
        ("Yoshida4, plain sums", lj.Yoshida4(compensated=False), dyadic),
        ("StormerVerlet, compensated, h = 1/60 (raw)", lj.StormerVerlet(), 1 / 60),
        ("StormerVerlet, compensated, h = 1/60 (exact grid)", lj.StormerVerlet(),
         exact_sixtieth),
    ]  # fmt: skip
    return BrouwerStudy(decades, attempts)
