"""The stage equations of Gauss–Legendre are solved relative to the state's size:
a tiny oscillation is integrated as accurately as a large one."""

import jax.numpy as jnp
import numpy as np

import lagjax as lj


def test_a_pendulum_of_amplitude_1e_9_converges_at_fourth_order():
    lag = lj.Lagrangian(lambda q, qdot: 0.5 * qdot**2 + jnp.cos(q))
    amplitude = 1e-9  # linear regime: q = a cos t up to O(a³)
    errors = []
    for dt in (0.01, 0.005):
        run = lj.simulate(lag, (amplitude, 0.0), t1=10.0, dt=dt)
        errors.append(abs(float(run.q[-1]) - amplitude * np.cos(10.0)) / amplitude)
    # an absolute stopping floor of 45 ε left 1.6e-7 here, whatever the step
    assert errors[0] < 1e-9
    assert 10 < errors[0] / errors[1] < 24  # 2⁴ = 16: GaussLegendre(stages=2)


def test_a_state_at_rest_at_the_origin_stays_there():
    # the stage iteration maps 0 to 0: its stopping test must not divide 0 by 0
    lag = lj.Lagrangian(lambda q, qdot: 0.5 * qdot**2 + jnp.cos(q))
    run = lj.simulate(lag, (0.0, 0.0), t1=1.0, dt=0.01)
    assert float(run.q[-1]) == 0.0 and float(run.qdot[-1]) == 0.0
