"""The flat-vector route of `simulate`: same physics, one vector for diffrax.

For a plain ODETerm `simulate` integrates the raveled (q, q̇) and unravels what it
saves (`lagjax._integrate.flat_state`). The run must be the same run: same steps, same states,
pytree coordinates and saved times intact.
"""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

import lagjax as lj
from lagjax._integrate.flat_state import FlatState, flattened
from lagjax.scenes.pendulums import DoublePendulum
from tests.helpers import tree_allclose


def _spherical_pendulum(q, qdot):
    """q as a dict: the pytree must come back as a dict."""
    theta = q["theta"]  # φ is cyclic: L_z is conserved
    kinetic = 0.5 * (qdot["theta"] ** 2 + (jnp.sin(theta) * qdot["phi"]) ** 2)
    return kinetic + 9.81 * jnp.cos(theta)


def test_flat_run_is_the_pair_run():
    """Against the same run kept as a pair (a SaveAt fn turns flattening off)."""
    lag = lj.Lagrangian(_spherical_pendulum)
    y0 = ({"theta": jnp.asarray(1.0), "phi": jnp.asarray(0.0)},
          {"theta": jnp.asarray(0.0), "phi": jnp.asarray(2.0)})  # fmt: skip
    ts = jnp.linspace(0.0, 5.0, 11)
    options = dict(t1=5.0, solver=diffrax.Dopri8(), rtol=1e-10, atol=1e-10)
    flat = lj.simulate(lag, y0, ts=ts, **options)
    pair = lj.simulate(
        lag, y0, saveat=diffrax.SaveAt(ts=ts, fn=lambda t, y, args: y), **options
    )
    assert set(flat.q) == {"theta", "phi"} and flat.q["theta"].shape == (11,)
    steps = int(flat.stats["num_steps"]), int(pair.stats["num_steps"])
    if jax.default_backend() == "cpu":
        assert steps[0] == steps[1]
    else:  # a GPU fuses the two programs differently: 176 against 172 on an H200
        assert abs(steps[0] - steps[1]) <= 0.05 * steps[1]
    # The same arithmetic, compiled as two programs: with lagjax's CPU loop default
    # (lagjax._core.cpu_loops) XLA rounds them differently, by up to 2.6e-11 here, and
    # both are 4.9e-9 from a reference at rtol 1e-14 (bit-identical without it).
    assert tree_allclose(flat.ys, pair.ys, rtol=1e-10, atol=1e-10)
    # L_z = sin²θ φ̇ is conserved: physics, not only agreement. Saved times fall
    # between steps, on Dopri8's dense output (measured 1e-9 at rtol 1e-10).
    lz = jnp.sin(flat.q["theta"]) ** 2 * flat.qdot["phi"]
    assert np.max(np.abs(lz - lz[0])) < 1e-8 * abs(float(lz[0]))


def test_unravel_keeps_leading_axes_and_shapes():
    state = (jnp.arange(6.0).reshape(2, 3), jnp.asarray(7.0))
    flat = FlatState.of(state)
    vector = flat.ravel(state)
    assert vector.shape == (7,)
    saved = jnp.stack([vector, 2 * vector])  # two saved times
    back = flat.unravel(saved)
    assert back[0].shape == (2, 2, 3) and back[1].shape == (2,)
    assert tree_allclose(
        jax.tree.map(lambda x: x[1], back), jax.tree.map(lambda x: 2 * x, state)
    )


def test_equal_structures_compare_equal():
    """Static, hashable structure: equal systems reuse one compilation."""
    first = FlatState.of((jnp.zeros(2), jnp.zeros(2)))
    second = FlatState.of((jnp.ones(2), jnp.ones(2)))
    assert first == second and hash(first) == hash(second)


def test_pairs_that_must_stay_pairs():
    scene = DoublePendulum()
    y0 = scene.initial_state()
    term = diffrax.ODETerm(lambda t, y, args: y)
    splitting = (term, term)
    assert flattened(splitting, y0, None)[2] is None
    mixed = (jnp.zeros(2, jnp.float32), jnp.zeros(2))
    assert flattened(term, mixed, None)[2] is None
    custom = diffrax.SaveAt(t1=True, fn=lambda t, y, args: y[0])
    assert flattened(term, y0, custom)[2] is None
    assert flattened(term, y0, diffrax.SaveAt(steps=True))[2] is not None
