"""A Taylor series that overflows float64 (a motion far faster than the time
unit) is told by name on both routes, concrete and under `jit`; the remedy it
names — a time unit near the motion's scale — runs to the closed form; and a
non-finite run for another reason keeps the generic message."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj

pytest.importorskip("heyoka")

X0 = 1e-12  # a picometre, as a molecule's stretch
OMEGA_SI = 5e14  # rad/s, a molecular vibration


def oscillator(omega):
    return lj.Lagrangian(lambda x, v: 0.5 * v**2 - 0.5 * omega**2 * x**2)


def tight(backend="jax"):
    return lj.Taylor(rtol=1e-13, atol=1e-30, backend=backend)


@pytest.mark.parametrize("backend", ["jax", "heyoka"])
def test_an_overflowing_series_names_the_time_scale(backend):
    with pytest.raises(lj.SimulationError, match="overflows float64") as raised:
        lj.simulate(oscillator(OMEGA_SI), (X0, 0.0), t1=1e-14, solver=tight(backend))
    message = str(raised.value)
    assert "time scale ρ ≈" in message and "Dopri8" in message
    # the radius from the finite orders is within a decade of 1/ω
    rho = float(message.split("ρ ≈ ")[1].split(" ")[0])
    assert 0.1 / OMEGA_SI < rho < 100 / OMEGA_SI


def test_under_jit_the_message_names_the_cause():
    final = jax.jit(lambda x0: lj.simulate(oscillator(OMEGA_SI), (x0, 0.0), t1=1e-14,
                                           solver=tight()).q[-1])  # fmt: skip
    with pytest.raises(Exception, match="Taylor series overflows float64"):
        jax.block_until_ready(final(X0))


def test_the_remedy_a_time_unit_near_the_motion_runs_to_the_closed_form():
    omega_fs = OMEGA_SI * 1e-15  # rad/fs
    ts = jnp.linspace(0.0, 10.0, 11)  # femtoseconds
    run = lj.simulate(oscillator(omega_fs), (X0, 0.0), t1=10.0, ts=ts, solver=tight())
    np.testing.assert_allclose(run.q, X0 * np.cos(omega_fs * ts), rtol=0, atol=1e-24)


def test_another_non_finite_cause_keeps_the_generic_message():
    # V = −2√x: the force 1/√x pulls x to 0, where √x turns NaN; the series is
    # finite at every finite state, so the overflow is not named
    falling = lj.Lagrangian(lambda x, v: 0.5 * v**2 + 2 * jnp.sqrt(x))
    with pytest.raises(lj.SimulationError) as raised:
        lj.simulate(falling, (1.0, -3.0), t1=5.0, ts=jnp.linspace(0, 5.0, 51),
                    solver=lj.Taylor(rtol=1e-12, atol=1e-12))  # fmt: skip
    assert "overflows" not in str(raised.value)
