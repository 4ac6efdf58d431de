"""Dense output of `lj.Taylor(backend="jax")`: `traj.evaluate(t)` from the kept
step polynomials, against the harmonic oscillator's closed form, the saves at
`ts`, and the pendulum's energy, up to an event that ended the run."""

import diffrax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj

TAYLOR = lj.Taylor(rtol=1e-15, atol=1e-15)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_dense_values_follow_the_oscillator_and_agree_with_the_saves():
    oscillator = lj.Lagrangian(lambda q, qdot: 0.5 * qdot**2 - 0.5 * q**2)
    ts = jnp.linspace(0.0, 30.0, 7)
    run = lj.simulate(oscillator, (1.0, 0.5), t1=30.0, ts=ts, solver=TAYLOR,
                      dense=True)  # fmt: skip
    times = jnp.linspace(0.0, 30.0, 301)
    q, qdot = run.evaluate(times)
    exact = jnp.cos(times) + 0.5 * jnp.sin(times)
    np.testing.assert_allclose(q, exact, atol=1e-13)
    np.testing.assert_allclose(qdot, -jnp.sin(times) + 0.5 * jnp.cos(times), atol=1e-13)
    np.testing.assert_allclose(run.evaluate(ts)[0], run.q, rtol=0, atol=1e-15)
    assert run.evaluate(0.0)[0] == 1.0  # the first step's polynomial at τ = 0


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_dense_output_ends_at_the_event_and_keeps_the_energy():
    pendulum = lj.Lagrangian(lambda q, qdot: 0.5 * qdot**2 + jnp.cos(q))
    bottom = diffrax.Event(lambda t, y, args: y[0])
    run = lj.simulate(pendulum, (3.0, 0.0), t1=20.0, solver=TAYLOR, event=bottom,
                      dense=True)  # fmt: skip
    t_event = run.ts[0]
    q, qdot = run.evaluate(jnp.linspace(0.0, t_event, 200))
    energy = 0.5 * qdot**2 - jnp.cos(q)
    np.testing.assert_allclose(energy, -np.cos(3.0), atol=1e-14)
    assert abs(run.evaluate(t_event)[0]) < 1e-14
    with pytest.raises(Exception, match="outside the integrated span"):
        run.evaluate(t_event + 0.5)


def test_dense_output_on_heyoka_is_refused_by_name():
    pendulum = lj.Lagrangian(lambda q, qdot: 0.5 * qdot**2 + jnp.cos(q))
    heyoka = lj.Taylor(backend="heyoka", rtol=1e-15, atol=1e-15)
    with pytest.raises(ValueError, match=r"dense output with lj\.Taylor"):
        lj.simulate(pendulum, (0.5, 0.0), t1=5.0, solver=heyoka, dense=True)
