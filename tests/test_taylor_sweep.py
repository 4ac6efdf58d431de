"""`lj.sweep` with `lj.Taylor()` runs its members on the batch-native Taylor loop
and gives what `jax.vmap(simulate)` gives."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj


def pendulum(q, qdot, t, args):
    return 0.5 * qdot**2 + args["g"] * jnp.cos(q)


@pytest.mark.integration  # two Taylor compilations, ~10 s each
def test_a_taylor_sweep_runs_the_batch_loop_and_matches_vmap_of_simulate():
    lag = lj.Lagrangian(pendulum)
    q0s = jnp.linspace(0.1, 1.0, 8)
    qd0s = jnp.zeros(8)
    gravities = {"g": jnp.linspace(1.0, 9.81, 8)}
    solver = lj.Taylor(rtol=1e-13, atol=1e-13)
    ts = jnp.linspace(0.0, 3.0, 7)
    swept = lj.sweep(lag, (q0s, qd0s), gravities, ts=ts, solver=solver)
    assert swept.solver_name == "Taylor[jax, batch]"
    assert swept.q.shape == (8, 7)
    one = jax.jit(
        jax.vmap(
            lambda q0, qd0, g: lj.simulate(
                lag, (q0, qd0), ts=ts, args={"g": g}, solver=solver
            )
        )
    )(q0s, qd0s, gravities["g"])
    np.testing.assert_allclose(swept.q, one.q, atol=1e-12)
    np.testing.assert_array_equal(swept.stats["num_steps"], one.stats["num_steps"])
    # Physics: each member keeps its own energy (its own g) to the tolerance.
    energy = swept.energy()
    assert float(jnp.max(jnp.abs(energy - energy[:, :1]))) < 1e-11
