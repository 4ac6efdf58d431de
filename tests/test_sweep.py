"""lj.sweep: sharded over forced host devices, identical to the unsharded run."""

import os
import subprocess
import sys
import textwrap

import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from tests.helpers import relative_close

SCRIPT = textwrap.dedent(
    """
    import jax
    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import numpy as np
    import lagjax as lj

    assert len(jax.devices()) == 4, jax.devices()
    system = lj.SeparableHamiltonian(lambda p: 0.5 * p**2, lambda q, t, w: 0.5 * w**2 * q**2)
    size = 10  # not a multiple of the 4 devices: padded, then trimmed
    q0s = jnp.linspace(-1.0, 1.0, size)
    omegas = jnp.linspace(0.5, 2.0, size)
    y0s = (q0s, jnp.zeros(size))
    kwargs = dict(t1=1.0, dt=0.01, ts=jnp.linspace(0.0, 1.0, 5))
    sharded = lj.sweep(system, y0s, omegas, chunk_size=4, **kwargs)
    plain = jax.vmap(lambda y0, w: lj.simulate(system, y0, args=w, **kwargs))(y0s, omegas)
    assert sharded.q.shape == (size, 5), sharded.q.shape
    # The sharded program is compiled for a per-device batch of 1, the plain one for
    # 10: XLA may vectorize (and so round) differently. With lagjax's CPU loop
    # default (lagjax._core.cpu_loops) whole loop bodies are compiled as one kernel and
    # the two differ by up to 1.7e-15 on values of order 1 (a few ulp).
    np.testing.assert_allclose(np.asarray(sharded.q), np.asarray(plain.q), rtol=0, atol=4e-15)
    np.testing.assert_allclose(np.asarray(sharded.p), np.asarray(plain.p), rtol=0, atol=4e-15)
    print("max difference", float(jnp.max(jnp.abs(sharded.q - plain.q))))
    exact = q0s[:, None] * jnp.cos(omegas[:, None] * kwargs["ts"][None, :])
    np.testing.assert_allclose(np.asarray(sharded.q), np.asarray(exact), atol=1e-8)
    print("sharded sweep ok")
    """
)


# A fresh process with four host devices: CI's second step (`bash tasks.sh integration`).
@pytest.mark.integration
def test_sharded_sweep_on_four_host_devices():
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=4")
    env["JAX_PLATFORMS"] = "cpu"
    done = subprocess.run(
        [sys.executable, "-c", SCRIPT],
        env=env,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert "sharded sweep ok" in done.stdout


def test_sweep_shares_args_and_validates_batch():
    system = lj.SeparableHamiltonian(
        lambda p: 0.5 * p**2, lambda q, t, w: 0.5 * w**2 * q**2
    )
    q0s = jnp.array([0.5, 1.0, 1.5])
    traj = lj.sweep(system, (q0s, jnp.zeros(3)), args=2.0, t1=1.0, dt=0.01)
    assert np.allclose(traj.q[:, -1], q0s * np.cos(2.0), atol=1e-8)

    with pytest.raises(ValueError, match="same leading size"):
        lj.sweep(system, (q0s, jnp.zeros(2)), t1=1.0, dt=0.01, args=2.0)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_batched_trajectory_derives_p_qdot_and_energy():
    # Extra leading (batch) axes on a Trajectory are mapped over, not mistaken for q.
    lag = lj.Lagrangian(lambda q, v: 0.5 * v**2 - 0.5 * q**2)
    q0s = jnp.array([1.0, 2.0])
    batched = lj.sweep(
        lag, (q0s, jnp.zeros(2)), t1=1.0, dt=0.01, ts=jnp.linspace(0, 1, 3)
    )
    assert relative_close(batched.energy(), 0.5 * q0s[:, None] ** 2 * np.ones(3), 1e-8)
    assert np.allclose(batched.p, batched.qdot)
    assert np.allclose(batched.p[:, -1], -q0s * np.sin(1.0), atol=1e-8)
