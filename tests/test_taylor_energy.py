r"""Energy of a pendulum over 10⁶ periods with `lj.Taylor` at tol 1e-15, on both
routes (JAX, and heyoka's integrator on the translated equations): round-off
only, no linear drift.

A Taylor method at a tolerance below the unit round-off ε leaves round-off as the
only error: each of the N steps changes the energy by about ε|E| with a sign
that does not persist, so the error is at most a random walk, |ΔE|/|E| ~ ε√N
(Brouwer's law, ∝ t^½), never the linear drift ∝ t of a truncation error that
accumulates step after step. The error is sampled at log-spaced times and its
running maximum fitted by |ΔE|(t) ∝ t^a: a ≈ 0.5 for a random walk, 1 for a
drift. The same measure on a run at tol 1e-9, where truncation dominates,
finds the drift (a ≈ 1), so it can tell them apart. On the JAX route the state is carried
with compensated summation (`lagjax.taylor.step.compensated_advance`): what each
step loses is the rounding of its increment.

References: D. Brouwer, "On the accumulation of errors in numerical integration",
Astronomical Journal 46 (1937) 149; F. Biscani & D. Izzo, "Revisiting high-order
Taylor methods for astrodynamics and celestial mechanics", MNRAS 504 (2021) 2614
(heyoka's tolerance and step rule).
"""

import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.special_functions import complete_elliptic_k

PENDULUM = lj.Lagrangian(lambda q, qdot: 0.5 * qdot**2 + jnp.cos(q))  # ω₀ = 1
THETA0 = 1.0
PERIOD = 4 * float(complete_elliptic_k(np.sin(THETA0 / 2) ** 2))
EPS = np.finfo(np.float64).eps


def energy_growth(tol: float, periods: float, backend: str) -> tuple[float, float, int]:
    """(the exponent a of |ΔE|(t) ∝ t^a, the largest relative energy error, the
    number of steps) of a run over `periods` periods at tolerance `tol`."""
    if backend == "heyoka":
        pytest.importorskip("heyoka")
    ts = PERIOD * np.geomspace(1.0, periods, 200)
    solver = lj.Taylor(backend=backend, rtol=tol, atol=tol)
    run = lj.simulate(PENDULUM, (THETA0, 0.0), t1=ts[-1], ts=ts, solver=solver,
                      max_steps=10**9)  # fmt: skip
    q, qdot = np.asarray(run.q), np.asarray(run.qdot)
    energy0 = -np.cos(THETA0)
    error = np.abs(0.5 * qdot**2 - np.cos(q) - energy0) / abs(energy0)
    # The running maximum: monotone, and free of the zeros that an energy equal
    # to its start to the last bit gives (floored at ε, the resolution of E).
    envelope = np.maximum.accumulate(np.maximum(error, EPS))
    exponent = np.polyfit(np.log(ts), np.log(envelope), 1)[0]
    return float(exponent), float(envelope[-1]), int(run.stats["num_steps"])


@pytest.mark.integration  # 2·10⁷ steps: 10–20 s a route
@pytest.mark.parametrize("backend", ["jax", "heyoka"])
def test_energy_over_a_million_periods_shows_no_drift(backend):
    exponent, error, steps = energy_growth(1e-15, 1e6, backend)
    assert steps > 10**7  # the whole span was integrated
    assert exponent <= 0.6  # a random walk gives 0.5, a linear drift 1
    # A random walk of N round-offs of ε each stays within ε√N.
    assert error <= EPS * np.sqrt(steps)


@pytest.mark.integration
@pytest.mark.parametrize("backend", ["jax", "heyoka"])
def test_the_measure_sees_the_drift_of_a_loose_tolerance(backend):
    exponent, error, _ = energy_growth(1e-9, 1e4, backend)
    assert exponent >= 0.9  # truncation errors accumulate linearly
    assert error > 1e3 * EPS
