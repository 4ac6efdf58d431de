"""Chain regularization: gravitating bodies in a chain of their closest pairs.

Oracles: the chain transformation is a canonical point transformation and its
inverse returns the state to round-off; re-forming the chain picks the closest
pair and leaves the physical state where it was; a two-body chain follows
Kepler's equation; energy, total momentum and angular momentum are kept through
the Pythagorean problem's close encounters, wherever the configuration sits; the
symmetric step retraces itself.
"""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.mechanics.particles import total_angular_momentum, total_momentum
from lagjax.scenes.planetary import PlanetarySystem
from lagjax.scenes.pythagorean import PythagoreanThreeBody
from lagjax.solvers.chain import CHAIN_HAMILTONIAN, ChainBodies
from lagjax.solvers.chain_coordinates import ChainState, chain_links
from lagjax.solvers.chain_coordinates import closest_pair_chain as _closest_pair_chain
from lagjax.solvers.chain_coordinates import from_chain as _from_chain
from lagjax.solvers.chain_coordinates import rechained as _rechained
from lagjax.solvers.chain_coordinates import to_chain as _to_chain
from lagjax.solvers.time_transformed import extended_state

MASSES = np.array([1.0, 2.0, 0.5, 3.0])
# Compiled: op by op, the unrolled pairs took seconds per test.
to_chain, from_chain, rechained, closest_pair_chain = (
    jax.jit(f) for f in (_to_chain, _from_chain, _rechained, _closest_pair_chain)
)


def _four_bodies():
    generator = np.random.default_rng(7)
    return generator.normal(size=(4, 3)) + 10.0, generator.normal(size=(4, 3))


def _chain_in_order(masses, q, p, order):
    """The chain state for a given order, from the definitions (module docstring of
    `lagjax.solvers.chain_coordinates`)."""
    order = np.asarray(order)
    placed_q, placed_p = q[order], p[order]
    relative = placed_p - (masses[order] / np.sum(masses))[:, None] * np.sum(p, 0)
    W = -np.cumsum(relative, axis=0)[:-1]
    return ChainState(placed_q[1:] - placed_q[:-1], W, order)


def test_chain_coordinates_and_back_is_the_identity():
    q, p = _four_bodies()
    chain, centre, momentum = to_chain(MASSES, q, p)
    q_back, p_back = from_chain(MASSES, chain, centre, momentum)
    np.testing.assert_allclose(q_back, q, rtol=0, atol=1e-14 * 11)
    np.testing.assert_allclose(p_back, p, rtol=0, atol=1e-14)
    np.testing.assert_allclose(centre, MASSES @ q / np.sum(MASSES), rtol=1e-15)
    np.testing.assert_allclose(momentum, np.sum(p, 0), rtol=1e-15)


def test_the_chain_transformation_is_canonical():
    """M^T J M = J for (q, p) -> ((X, R), (W, P)), M its Jacobian (the chain's
    order is piecewise constant in q)."""
    q, p = _four_bodies()

    def transform(z):
        q, p = (half.reshape(4, 3) for half in jnp.split(z, 2))
        chain, centre, momentum = _to_chain(MASSES, q, p)
        X, W = chain.X.ravel(), chain.W.ravel()
        return jnp.concatenate([X, centre, W, momentum])

    z = np.concatenate([q.ravel(), p.ravel()])
    jacobian = np.asarray(jax.jit(jax.jacfwd(transform))(z))
    size = q.size
    form = np.block([[np.zeros((size, size)), np.eye(size)],
                     [-np.eye(size), np.zeros((size, size))]])  # fmt: skip
    np.testing.assert_allclose(jacobian.T @ form @ jacobian, form, atol=1e-13)
    chain = to_chain(MASSES, q, p)[0]
    np.testing.assert_allclose(
        chain.W, _chain_in_order(MASSES, q, p, chain.order).W, rtol=0, atol=1e-14
    )


def test_the_chain_hamiltonian_is_the_bodies_energy():
    q, p = _four_bodies()
    chain, _, momentum = to_chain(MASSES, q, p)

    @jax.jit
    def chained(chain):
        bodies = ChainBodies(jnp.asarray(MASSES)[chain.order], jnp.asarray(1.5))
        kinetic = CHAIN_HAMILTONIAN.kinetic_energy(chain.W, 0.0, bodies)
        return kinetic + CHAIN_HAMILTONIAN.potential_energy(chain.X, 0.0, bodies)

    kinetic = 0.5 * np.sum(p**2 / MASSES[:, None])
    kinetic = kinetic - np.sum(np.asarray(momentum) ** 2) / (2 * np.sum(MASSES))
    distance = np.linalg.norm(q[:, None] - q[None], axis=-1)
    upper = np.triu_indices(4, 1)
    potential = -1.5 * np.sum((MASSES[:, None] * MASSES[None])[upper] / distance[upper])
    np.testing.assert_allclose(chained(chain), kinetic + potential, rtol=1e-13)


def test_rechaining_picks_the_closest_pair_and_keeps_the_state():
    """Four bodies on a line, chained 0-1-2-3; then bodies 0 and 3 (the chain's
    ends) come within 1e-3 of each other: the new chain links them, and the
    positions and momenta stay where they were."""
    masses = MASSES
    q = np.array([[0.0, 0.0, 0], [1.0, 0.1, 0], [2.2, 0.0, 0], [0.001, 0.0005, 0]])
    p = np.array([[0.3, -0.1, 0], [0.0, 0.2, 0], [-0.5, 0.0, 0], [0.2, -0.1, 0]])
    old = _chain_in_order(masses, q, p, [0, 1, 2, 3])
    new, changed = rechained(old)
    assert bool(changed)
    assert (0, 3) in chain_links(new.order)
    assert chain_links(new.order) == chain_links(
        closest_pair_chain(np.linalg.norm(q[:, None] - q[None], axis=-1))
    )
    momentum = np.sum(p, 0)
    for state in (old, new):
        q_back, p_back = from_chain(masses, state, masses @ q / 6.5, momentum)
        np.testing.assert_allclose(q_back, q, rtol=0, atol=1e-15 * 4)
        np.testing.assert_allclose(p_back, p, rtol=0, atol=1e-15 * 4)

    # The change of chain is canonical too: (X, W) -> (X', W') at the new order.
    def change(z):
        X, W = (half.reshape(3, 3) for half in jnp.split(z, 2))
        state = _rechained(ChainState(X, W, jnp.asarray(old.order)))[0]
        return jnp.concatenate([state.X.ravel(), state.W.ravel()])

    z = np.concatenate([old.X.ravel(), old.W.ravel()])
    jacobian = np.asarray(jax.jit(jax.jacfwd(change))(z))
    form = np.block([[np.zeros((9, 9)), np.eye(9)], [-np.eye(9), np.zeros((9, 9))]])
    np.testing.assert_allclose(jacobian.T @ form @ jacobian, form, atol=1e-14)
    # Built again from its own separations the chain stays, bit for bit.
    again, changed_again = rechained(new)
    assert not bool(changed_again)
    assert all(np.array_equal(a, b) for a, b in zip(again, new))


def _kepler_relative(t, a, e, mu):
    """Relative position at time t from pericentre (x along the pericentre)."""
    mean = np.sqrt(mu / a**3) * t
    anomaly = mean.copy()
    for _ in range(50):  # Newton on Kepler's equation E − e sin E = M
        anomaly -= (anomaly - e * np.sin(anomaly) - mean) / (1 - e * np.cos(anomaly))
    return a * np.stack([np.cos(anomaly) - e, np.sqrt(1 - e**2) * np.sin(anomaly)], -1)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_a_two_body_chain_follows_keplers_equation():
    masses, gravity, a, e = np.array([1.0, 0.5]), 1.0, 1.0, 0.8
    mu = gravity * masses.sum()
    speed = np.sqrt(mu * (1 + e) / (a * (1 - e)))
    relative_q = np.array([a * (1 - e), 0.0, 0.0])
    relative_v = np.array([0.0, speed, 0.0])
    shares = np.array([-masses[1], masses[0]])[:, None] / masses.sum()
    q0 = shares * relative_q
    scene = PlanetarySystem(masses=masses, positions=q0, velocities=shares
                            * relative_v, gravitational_constant=gravity)  # fmt: skip
    p0 = masses[:, None] * shares * relative_v
    ts = np.linspace(0.0, 3 * 2 * np.pi, 13)[1:]
    solver = lj.ChainRegularization(lj.GraggBulirschStoer(rtol=1e-13, atol=1e-13))
    traj = lj.simulate(scene, (q0, p0), t1=float(ts[-1]), ts=ts, dt=0.1,
                       solver=solver)  # fmt: skip
    relative = np.asarray(traj.q[:, 1] - traj.q[:, 0])
    expected = _kepler_relative(ts, a, e, mu)
    np.testing.assert_allclose(relative[:, :2], expected, rtol=0, atol=5e-12)
    np.testing.assert_allclose(relative[:, 2], 0.0, atol=1e-15)
    np.testing.assert_allclose(traj.p[:, 0], -traj.p[:, 1], atol=1e-13)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_invariants_through_the_pythagorean_encounters_anywhere():
    """To t = 30, through the closest encounter (r ≈ 1e-3 near t = 29.8): energy to
    1e-12, momentum and angular momentum to round-off, as given and shifted by 100
    (in barycentric coordinates the shift raises the energy error tenfold per
    decade; the chain sees only separations)."""
    scene = PythagoreanThreeBody()
    q0, p0 = scene.initial_state()
    ts = np.linspace(0.0, 30.0, 31)
    solver = lj.ChainRegularization(lj.GraggBulirschStoer(rtol=3e-14, atol=3e-14))

    @jax.jit
    def run(q0):
        traj = lj.simulate(scene, (q0, p0), t1=30.0, ts=ts, dt=0.1, solver=solver)
        return traj.q, traj.p, traj.energy(), traj.stats["num_rechains"]

    results = jax.vmap(run)(jnp.stack([q0, q0 + 100.0]))
    for shift, q, p, energy, rechains in zip((0.0, 100.0), *results):
        assert np.max(np.abs(energy / scene.energy() - 1)) < 1e-12, shift
        assert np.max(np.abs(total_momentum(p))) < 1e-13
        moments = total_angular_momentum(q - shift, p)
        assert np.max(np.abs(moments)) < 1e-12
        assert int(rechains) > 0
    np.testing.assert_allclose(results[0][1] - 100.0, results[0][0], atol=1e-6)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_two_binaries_meet_and_the_chain_follows_every_close_pair():
    """Two binaries (masses 1, 1 and 0.8, 1.2) fly into each other: the chain is
    re-formed hundreds of times over four bodies (places three links apart are
    separated along the chain), and energy and momentum stay kept; the
    barycentric run at the same tolerance loses more than ten times as much."""
    masses = np.array([1.0, 1.0, 0.8, 1.2])
    q0 = np.array([[-3.1, 0.25], [-2.9, 0.25], [3.0, -0.25], [3.15, -0.25]])
    inner, outer = np.sqrt(2.0 / 0.2) / 2, np.sqrt(2.0 / 0.15)
    v0 = np.array([[0.5, -inner], [0.5, inner], [-0.5, 0.6 * outer],
                   [-0.5, -0.4 * outer]])  # fmt: skip
    v0 = v0 - masses @ v0 / masses.sum()
    scene = PlanetarySystem(masses=masses, positions=q0, velocities=v0,
                            gravitational_constant=1.0)  # fmt: skip
    ts = np.linspace(0.0, 10.0, 41)
    errors = []
    for solver in (lj.ChainRegularization, lj.TimeTransformed):
        method = solver(lj.GraggBulirschStoer(rtol=1e-13, atol=1e-13))
        traj = lj.simulate(scene, (q0, masses[:, None] * v0), t1=10.0, ts=ts,
                           dt=0.01, solver=method)  # fmt: skip
        energy = np.asarray(traj.energy())
        errors.append(np.max(np.abs(energy / energy[0] - 1)))
        assert np.max(np.abs(np.asarray(total_momentum(traj.p)))) < 1e-13
        if solver is lj.ChainRegularization:
            assert int(traj.stats["num_rechains"]) > 100
    assert errors[0] < 1e-11 and errors[0] < errors[1] / 10, errors


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_one_symmetric_step_retraces_itself():
    """The time-transformed leapfrog on the chain: a step of ds then one of −ds
    return the extended state to round-off."""
    scene = PythagoreanThreeBody()
    q, p = scene.initial_state()
    p = p + jnp.array([[0.3, -0.2], [0.1, 0.4], [-0.3, 0.0]])
    masses = scene.masses
    chain, _, _ = to_chain(masses, q, p)
    bodies = ChainBodies(masses[chain.order], scene.gravitational_constant)
    solver = lj.ChainRegularization(lj.StormerVerlet())
    terms = solver.terms()
    y0 = extended_state(CHAIN_HAMILTONIAN, (chain.X, chain.W), 0.0, bodies)

    @jax.jit
    def there_and_back(y0):
        zero = jnp.zeros(())
        step = solver.splitting.step
        state = solver.splitting.init(terms, zero, 0.05, y0, bodies)
        y1, *_ = step(terms, zero, 0.05, y0, bodies, state, False)
        state = solver.splitting.init(terms, zero, -0.05, y1, bodies)
        y2, *_ = step(terms, zero, -0.05, y1, bodies, state, False)
        return y1, y2

    y1, y2 = there_and_back(y0)
    assert float(y1[1][1]) > 0.0  # time advanced
    for a, b in zip(jax.tree_util.tree_leaves(y2), jax.tree_util.tree_leaves(y0)):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-14)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_a_run_cut_short_by_max_steps_says_so_and_saves_nan_beyond():
    scene = PythagoreanThreeBody()
    solver = lj.ChainRegularization(lj.GraggBulirschStoer(rtol=1e-12, atol=1e-12))
    traj = lj.simulate(scene, scene.initial_state(), t1=10.0, ts=[1.0, 5.0, 10.0],
                       dt=0.1, solver=solver, max_steps=50, throw=False)  # fmt: skip
    assert traj.result == diffrax.RESULTS.max_steps_reached
    assert int(traj.stats["num_steps"]) == 50
    q = np.asarray(traj.q)
    assert np.all(np.isfinite(q[0])) and np.all(np.isnan(q[1:]))
    with pytest.raises(Exception, match="did not reach the last save time"):
        lj.simulate(scene, scene.initial_state(), t1=10.0, dt=0.1, solver=solver,
                    max_steps=50)  # fmt: skip


class _Bodies(eqx.Module):
    masses: jax.Array
    gravitational_constant: jax.Array


def _newtonian(masses_of):
    def kinetic(p, t, bodies):
        return 0.5 * jnp.sum(p**2 / masses_of(bodies)[:, None])

    def potential(q, t, bodies):
        m = masses_of(bodies)
        distance = jnp.linalg.norm(q[:, None] - q[None], axis=-1)
        upper = np.triu_indices(m.shape[0], 1)
        return -jnp.sum((m[:, None] * m[None] / distance)[upper])

    return lj.SeparableHamiltonian(kinetic, potential)


@pytest.mark.parametrize(
    "masses, q0, match",
    [
        ([1.0], [[0.0, 0.0]], "N ≥ 2 bodies"),
        ([1.0, -2.0], [[0.0, 0.0], [1.0, 0.0]], "every mass must be positive"),
        ([1.0, 0.0], [[0.0, 0.0], [1.0, 0.0]], "every mass must be positive"),
        ([1.0, 2.0], [[0.0, 0.0]], "one row per mass"),
    ],
)
def test_bad_bodies_are_refused_by_name(masses, q0, match):
    bodies = _Bodies(jnp.asarray(masses), jnp.asarray(1.0))
    q0 = jnp.asarray(q0)
    solver = lj.ChainRegularization(lj.GraggBulirschStoer())
    with pytest.raises(ValueError, match=match):
        lj.simulate(_newtonian(lambda b: b.masses), (q0, jnp.zeros_like(q0)),
                    t1=1.0, dt=0.1, solver=solver, args=bodies)  # fmt: skip


def test_a_system_that_is_not_newtonian_gravity_is_refused():
    bodies = _Bodies(jnp.asarray([1.0, 2.0]), jnp.asarray(1.0))
    system = _newtonian(lambda b: 2 * b.masses)  # not the masses it declares
    q0 = jnp.asarray([[0.0, 0.0], [1.0, 0.0]])
    solver = lj.ChainRegularization(lj.GraggBulirschStoer())
    with pytest.raises(ValueError, match="pairwise Newtonian gravity"):
        lj.simulate(system, (q0, jnp.zeros_like(q0) + 0.1), t1=1.0, dt=0.1,
                    solver=solver, args=bodies)  # fmt: skip
    with pytest.raises(ValueError, match="takes no rtol"):
        lj.simulate(PythagoreanThreeBody(), PythagoreanThreeBody().initial_state(),
                    t1=1.0, dt=0.1, solver=solver, rtol=1e-12)  # fmt: skip
    with pytest.raises(TypeError, match="gravitating bodies"):
        lj.simulate(system, (q0, q0), t1=1.0, dt=0.1, solver=solver, args=None)
    with pytest.raises(ValueError, match="Runge–Kutta–Nyström"):
        lj.ChainRegularization(lj.BlanesMoanNystrom6())
