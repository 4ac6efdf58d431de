"""Wisdom–Holman splitting (`lj.WisdomHolman`): the Kepler drift against Kepler's
equation (elliptic to e = 0.99, hyperbolic), a one-planet system integrated exactly,
second order on two planets, symplecticity and reversibility of the step,
conservation of total momentum and angular momentum, the corrector's gain, and
refusals by name."""

import inspect
import itertools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.flatten_util import ravel_pytree

import lagjax as lj
import lagjax._integrate.simulate as simulate_module
from lagjax._integrate.wisdom_holman_run import run_wisdom_holman
from lagjax.scenes.planetary import PlanetarySystem
from lagjax.solvers.kepler_drift import kepler_drift
from lagjax.solvers.wisdom_holman import (
    RESULTS,
    KeplerInteractionTerm,
    WisdomHolman,
    to_inertial,
    to_jacobi,
)

jitted_drift = jax.jit(kepler_drift)  # one compilation per shape, shared

# simulate hands a WisdomHolman solver to run_wisdom_holman once its hook is in.
ROUTED = "run_wisdom_holman" in inspect.getsource(simulate_module)


def simulate(scene, y0=None, *, t1, dt, corrector=None, ts=None, throw=True):
    """`lj.simulate(scene, y0, t1=t1, dt=dt, ts=ts, solver=WisdomHolman(...))`."""
    y0 = scene.initial_state() if y0 is None else y0
    solver = WisdomHolman(corrector=corrector)
    if ROUTED:
        return lj.simulate(scene, y0, t1=t1, dt=dt, ts=ts, solver=solver, throw=throw)
    return run_wisdom_holman(scene, y0, 0.0, t1, dt, solver, ts, None, None, throw)


def newton(function, derivative, start, iterations=60):
    """Plain Newton in NumPy float64: the independent solver of Kepler's equation."""
    x = np.array(start, dtype=float)
    for _ in range(iterations):
        x = x - function(x) / derivative(x)
    return x


def pericentre_states(e, mu=1.0, rp=None):
    """Bodies at pericentre on the x axis, orbits tilted out of the xy plane."""
    e = np.asarray(e, dtype=float)
    rp = 1 - e if rp is None else rp
    speed = np.sqrt(mu * (1 + e) / rp)
    zero = np.zeros_like(e)
    tilt = 0.3
    position = np.stack([rp, zero, zero], -1)
    velocity = np.stack([zero, speed * np.cos(tilt), speed * np.sin(tilt)], -1)
    return position, velocity, tilt


def in_orbit_plane(x, y, tilt):
    return np.stack([x, y * np.cos(tilt), y * np.sin(tilt)], -1)


def test_kepler_drift_follows_keplers_equation_for_ellipses_up_to_e_099():
    eccentricities = np.array([0.0, 0.3, 0.6, 0.9, 0.99])
    position, velocity, tilt = pericentre_states(eccentricities)
    # Elements from the state itself (as the drift sees it): a = μ/β.
    beta = 2 / np.linalg.norm(position, axis=-1) - np.sum(velocity**2, -1)
    a = 1 / beta
    e = 1 - position[:, 0] / a
    times = np.array([0.01, 0.7, 3.0, 6.2, 11.5, -4.4])  # forward, back, > a period
    h = times[:, None] * np.ones_like(e)
    moved, moved_velocity, converged = jitted_drift(
        jnp.asarray(np.broadcast_to(position, (*h.shape, 3))),
        jnp.asarray(np.broadcast_to(velocity, (*h.shape, 3))),
        jnp.ones(h.shape),
        jnp.asarray(h),
    )
    assert bool(jnp.all(converged))
    mean_anomaly = h / a**1.5
    anomaly = newton(
        lambda E: E - e * np.sin(E) - mean_anomaly,
        lambda E: 1 - e * np.cos(E),
        mean_anomaly + np.sign(np.sin(mean_anomaly)) * e,
    )
    expected = in_orbit_plane(
        a * (np.cos(anomaly) - e), a * np.sqrt(1 - e**2) * np.sin(anomaly), tilt
    )
    assert np.max(np.abs(np.asarray(moved) - expected)) < 2e-12
    # Energy and angular momentum of each orbit kept by the exact flow.
    energy = np.sum(np.asarray(moved_velocity) ** 2, -1) / 2 - 1 / np.linalg.norm(
        np.asarray(moved), axis=-1
    )
    np.testing.assert_allclose(energy, -beta / 2 * np.ones_like(h), rtol=1e-12)
    angular = np.cross(np.asarray(moved), np.asarray(moved_velocity))
    np.testing.assert_allclose(angular, np.cross(position, velocity) + 0 * angular,
                               rtol=0, atol=1e-13)  # fmt: skip


def test_kepler_drift_follows_the_hyperbolic_kepler_equation():
    eccentricities = np.array([1.2, 2.0, 5.0])
    position, velocity, tilt = pericentre_states(eccentricities, rp=np.ones(3))
    beta = 2 / np.linalg.norm(position, axis=-1) - np.sum(velocity**2, -1)
    a = -1 / beta  # |a| of the hyperbola
    e = 1 + position[:, 0] / a
    h = np.array([[0.5], [3.0], [-20.0]]) * np.ones(3)
    moved, _, converged = jitted_drift(
        jnp.asarray(np.broadcast_to(position, (*h.shape, 3))),
        jnp.asarray(np.broadcast_to(velocity, (*h.shape, 3))),
        jnp.ones(h.shape),
        jnp.asarray(h),
    )
    assert bool(jnp.all(converged))
    mean_anomaly = h / a**1.5
    anomaly = newton(
        lambda H: e * np.sinh(H) - H - mean_anomaly,
        lambda H: e * np.cosh(H) - 1,
        np.arcsinh(mean_anomaly / e),
    )
    expected = in_orbit_plane(
        a * (e - np.cosh(anomaly)), a * np.sqrt(e**2 - 1) * np.sinh(anomaly), tilt
    )
    scale = np.linalg.norm(expected, axis=-1, keepdims=True)
    assert np.max(np.abs(np.asarray(moved) - expected) / scale) < 1e-13


@pytest.mark.integration  # compiles derivatives of the drift's loop
def test_kepler_drift_derivative_is_the_flows():
    position, velocity, _ = pericentre_states(np.array(0.6))

    def final_x(start):
        return kepler_drift(start, jnp.asarray(velocity), jnp.asarray(1.0), 2.0)[0][0]

    start = jnp.asarray(position)
    gradient = jax.grad(final_x)(start)
    step = 1e-6
    central = [
        (final_x(start.at[i].add(step)) - final_x(start.at[i].add(-step))) / (2 * step)
        for i in range(3)
    ]
    np.testing.assert_allclose(gradient, central, rtol=1e-7, atol=1e-8)


def two_body(eccentricity=0.6, planet_mass=1e-3):
    """A star and one planet at pericentre, G = 1, a = 1 about the star."""
    mu = 1 + planet_mass
    rp = 1 - eccentricity
    speed = np.sqrt(mu * (1 + eccentricity) / rp)
    masses = np.array([1.0, planet_mass])
    relative_x = np.array([rp, 0.0, 0.0])
    relative_v = np.array([0.0, speed * np.cos(0.4), speed * np.sin(0.4)])
    # Centre of mass at rest at the origin.
    positions = np.stack([-planet_mass / mu * relative_x, 1 / mu * relative_x])
    velocities = np.stack([-planet_mass / mu * relative_v, 1 / mu * relative_v])
    scene = PlanetarySystem(masses=masses, positions=positions, velocities=velocities,
                            gravitational_constant=1.0)  # fmt: skip
    return scene, mu


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_one_planet_is_integrated_exactly():
    """No interaction: the map is the exact two-body flow at any step (dt = T/7)."""
    scene, mu = two_body()
    period = 2 * np.pi / np.sqrt(mu)
    dt = period / 7
    ts = dt * np.arange(0, 71, 10)
    traj = simulate(scene, t1=ts[-1], dt=dt, ts=ts)
    relative = np.asarray(traj.q[:, 1] - traj.q[:, 0])
    anomaly = newton(
        lambda E: E - 0.6 * np.sin(E) - np.sqrt(mu) * ts,
        lambda E: 1 - 0.6 * np.cos(E),
        np.sqrt(mu) * ts,
    )
    expected = np.stack(
        [np.cos(anomaly) - 0.6, 0.8 * np.sin(anomaly) * np.cos(0.4),
         0.8 * np.sin(anomaly) * np.sin(0.4)], -1,
    )  # fmt: skip
    assert np.max(np.abs(relative - expected)) < 1e-12
    centre = np.asarray(jnp.einsum("i,tij->tj", scene.masses, traj.q))
    assert np.max(np.abs(centre)) < 1e-15
    assert traj.stats["coordinates"] == "Jacobi"


def two_planets():
    """Star, and two Jupiter-mass planets at a = 1 and 1.6 with e ≈ 0.1, G = 1."""
    masses = np.array([1.0, 1e-3, 1e-3])
    positions = np.array([[0.0, 0, 0], [0.9, 0, 0], [0, 1.76, 0.05]])
    velocities = np.array([[0.0, 0, 0], [0, 1.1, 0.02], [-0.83, 0, 0]])
    return PlanetarySystem(masses=masses, positions=positions, velocities=velocities,
                           gravitational_constant=1.0)  # fmt: skip


def jacobi_setup(scene):
    term = KeplerInteractionTerm(scene.masses, scene.gravitational_constant)
    return term, to_jacobi(scene.masses, *scene.initial_state())


@eqx.filter_jit
def synchronised_steps(term, y, h, steps):
    """`WisdomHolman().step` applied `steps` times (a traced count: one compilation)."""
    solver = WisdomHolman()

    def one(_, y):
        return solver.step(term, 0.0, h, y, None, None, False)[0]

    return jax.lax.fori_loop(0, steps, one, y)


@pytest.mark.integration  # four runs of the synchronised step
def test_second_order_on_two_planets():
    term, y0 = jacobi_setup(two_planets())
    span = 16.0
    finals = [
        ravel_pytree(synchronised_steps(term, y0, span / n, n))[0]
        for n in (40, 80, 160, 320)
    ]
    differences = [
        float(jnp.max(jnp.abs(a - b))) for a, b in itertools.pairwise(finals)
    ]
    slopes = np.log2(np.array(differences[:-1]) / np.array(differences[1:]))
    assert np.all(np.abs(slopes - 2) < 0.15), slopes


@pytest.mark.integration  # compiles derivatives of the drift's loop
def test_one_step_is_symplectic_and_time_reversible():
    term, y0 = jacobi_setup(two_planets())
    flat, unravel = ravel_pytree(y0)
    solver = WisdomHolman()

    def step(flat_y, h):
        y1, *_ = solver.step(term, 0.0, h, unravel(flat_y), None, None, False)
        return ravel_pytree(y1)[0]

    jacobian = jax.jacfwd(step)(flat, 0.3)
    half = flat.size // 2
    identity = np.eye(half)
    j = np.block(
        [[np.zeros((half, half)), identity], [-identity, np.zeros_like(identity)]]
    )
    np.testing.assert_allclose(jacobian.T @ j @ jacobian, j, atol=1e-12)
    back = step(step(flat, 0.3), -0.3)
    assert float(jnp.max(jnp.abs(back - flat))) < 1e-14


def test_jacobi_coordinates_round_trip_and_keep_the_total_momentum():
    scene = PlanetarySystem()
    q, p = scene.initial_state()
    jq, jp = to_jacobi(scene.masses, q, p)
    np.testing.assert_allclose(
        jp[0], jnp.sum(p, 0), rtol=0, atol=1e-15 * float(jnp.max(jnp.abs(p)))
    )
    back_q, back_p = to_inertial(scene.masses, jq, jp)
    np.testing.assert_allclose(back_q, q, atol=1e-14)
    np.testing.assert_allclose(
        back_p, p, rtol=0, atol=1e-15 * float(jnp.max(jnp.abs(p)))
    )


@pytest.mark.integration  # three compilations of the outer solar system run
def test_outer_solar_system_conserves_momenta_and_the_corrector_pays():
    scene = PlanetarySystem()
    q0, p0 = scene.initial_state()
    energy0 = scene.system()(q0, p0, 0.0, scene)
    ts = np.linspace(0, 2e4, 21)
    errors = {}
    for corrector in (None, 3, 5):
        traj = simulate(scene, t1=2e4, dt=50.0, ts=ts, corrector=corrector)
        checks = scene.checks(traj)
        for name in ("total momentum", "angular momentum"):
            measured, expected = checks[name]
            scale = float(jnp.max(jnp.abs(expected)))
            assert float(jnp.max(jnp.abs(measured - expected))) < 1e-13 * scale, name
        errors[corrector] = float(jnp.max(jnp.abs(traj.energy() / energy0 - 1)))
    # O(εh²) without, O(εh³ + ε²h²) with: at h = 50 days over 100 times smaller.
    assert errors[3] < errors[None] / 100, errors
    assert errors[5] < errors[None] / 100, errors


def test_bad_input_is_refused_by_name():
    scene = PlanetarySystem()
    with pytest.raises(ValueError, match="masses"):
        PlanetarySystem(masses=(0.0, 1e-3, 1e-3, 1e-4, 1e-4, 1e-8))
    no_star = eqx.tree_at(lambda s: s.masses, scene, scene.masses.at[0].set(-1.0))
    with pytest.raises(ValueError, match="central mass"):
        simulate(no_star, t1=100.0, dt=10.0)
    for dt in (0.0, -10.0):
        with pytest.raises(ValueError, match="dt"):
            simulate(scene, t1=100.0, dt=dt)
    with pytest.raises(ValueError, match="step grid"):
        simulate(scene, t1=100.0, dt=10.0, ts=[0.0, 15.0])
    with pytest.raises(ValueError, match="corrector"):
        WisdomHolman(corrector=4)
    kepler = lj.scenes.KeplerCartesian()
    with pytest.raises((TypeError, ValueError), match="gravitating bodies"):
        simulate(kepler, t1=1.0, dt=0.1)


def test_a_drift_that_cannot_converge_says_so():
    """A non-finite body fails its own Kepler equation and no other's."""
    position, velocity, _ = pericentre_states(np.array([0.0, 0.3, 0.6, 0.9, 0.99]))
    position = np.broadcast_to(position, (6, 5, 3)).copy()
    position[2, 3, 0] = np.nan
    _, _, converged = jitted_drift(
        jnp.asarray(position),
        jnp.asarray(np.broadcast_to(velocity, (6, 5, 3))),
        jnp.ones((6, 5)),
        jnp.full((6, 5), 0.7),
    )
    assert not bool(converged[2, 3]) and int(jnp.sum(~converged)) == 1


@pytest.mark.integration  # compiles the synchronised step
def test_a_failed_step_is_a_result_not_a_number():
    term, (q, p) = jacobi_setup(two_planets())
    y = (q.at[1].set(jnp.nan), p)
    step = eqx.filter_jit(WisdomHolman().step)
    *_, result = step(term, 0.0, 0.1, y, None, None, False)
    assert result == RESULTS.kepler_not_converged
