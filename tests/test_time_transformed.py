"""Time-transformed splitting (`lj.TimeTransformed`): the logarithmic Hamiltonian
on Kepler's problem, whose orbit it keeps exactly (energy, Runge–Lenz vector) and
whose timing is checked against Kepler's equation; symplecticity and reversibility
of the extended map; the order; jit, vmap and grad; refusals by name."""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.flatten_util import ravel_pytree

import lagjax as lj
from lagjax._integrate.time_transformed_run import _check_step_count
from lagjax.solvers.time_transformed import extended_state, start_weights

PERIOD = 2 * np.pi  # a = 1, GM = 1


def kepler() -> lj.SeparableHamiltonian:
    return lj.SeparableHamiltonian(lambda p: p @ p / 2, lambda q: -1 / jnp.sqrt(q @ q))


# One system for the runs that share a compiled program (the same solver and saves).
KEPLER = kepler()


def pericentre_state(e: float) -> tuple[jax.Array, jax.Array]:
    """At pericentre on the x axis: q = (1 − e, 0), |p| = √((1 + e)/(1 − e))."""
    return jnp.array([1 - e, 0.0]), jnp.array([0.0, np.sqrt((1 + e) / (1 - e))])


def runge_lenz_angle(q, p) -> np.ndarray:
    """Direction of A = p × L − q/r (the pericentre), per saved state."""
    q, p = np.asarray(q), np.asarray(p)
    angular = q[:, 0] * p[:, 1] - q[:, 1] * p[:, 0]
    r = np.linalg.norm(q, axis=1)
    ax = p[:, 1] * angular - q[:, 0] / r
    ay = -p[:, 0] * angular - q[:, 1] / r
    return np.arctan2(ay, ax)


def kepler_position(t, e: float) -> np.ndarray:
    """Closed form from pericentre: M = t = E − e sin E, q = (cos E − e, √(1−e²) sin E)."""
    mean = np.asarray(t, dtype=float)
    eccentric = mean + e * np.sin(mean)
    for _ in range(60):  # Newton on Kepler's equation
        eccentric -= (eccentric - e * np.sin(eccentric) - mean) / (
            1 - e * np.cos(eccentric)
        )
    return np.stack(
        [np.cos(eccentric) - e, np.sqrt(1 - e**2) * np.sin(eccentric)], axis=-1
    )


# Yoshida4 at e = 0.99 reaches 1.3e-12 at saves that fall on the pericentre: the
# round-off of the steps there walks the log-Hamiltonian Γ, and H − E = Γ/r reads
# it 2/(1 − e) = 200 times enlarged (test below). Störmer–Verlet stays at 5e-14
# only because its timing is off by a radian or so: its saves miss the pericentre.
@pytest.mark.parametrize(
    "e, splitting", [(0.9, lj.Yoshida4()), (0.99, lj.StormerVerlet())]
)
def test_kepler_energy_and_orbit_shape_kept_over_100_periods(e, splitting):
    ts = np.linspace(0, 100 * PERIOD, 401)
    traj = lj.simulate(KEPLER, pericentre_state(e), t1=ts[-1], dt=0.05, ts=ts,
                       solver=lj.TimeTransformed(splitting))  # fmt: skip
    # dt/ds = r: 2π/ds ≈ 126 steps per period whatever the eccentricity.
    assert int(traj.stats["num_steps"]) < 130 * 100
    error = np.abs(np.asarray(traj.energy()) / -0.5 - 1)
    assert error.max() <= 1e-12
    # No secular trend: the last quarter no worse than round-off above the first.
    assert error[-100:].max() <= error[:100].max() + 5e-14
    drift = np.abs(runge_lenz_angle(traj.q, traj.p))
    assert drift.max() <= 1e-10
    assert float(traj.stats["time_residual"]) <= 1e-12 * ts[-1]


@pytest.mark.parametrize(
    "compensated",
    [True, pytest.param(False, marks=pytest.mark.integration)],  # a second compile
)
def test_kahans_sum_keeps_the_round_off_at_the_pericentre_small(compensated):
    """In exact arithmetic the logarithmic leapfrog keeps Kepler's energy exactly, so
    the energy error is round-off alone; each step's round-off changes the
    log-Hamiltonian Γ = ln((T + p_t) r), and at the pericentre H − E = Γ/r shows it
    2/(1 − e) = 200 times enlarged. Without Kahan's sum every one of the 50,000
    steps rounds the state (5.5e-12 rms over 8 orbits at the pericentre saves of 100
    periods); with it only the few steps a period near the pericentre, whose
    increments are as large as the state, add to the walk (3.3e-13 rms)."""
    solver = lj.TimeTransformed(lj.Yoshida4(compensated=compensated))
    ts = np.linspace(0, 100 * PERIOD, 401)  # the saves of the test above: one compile
    errors = []
    for e in np.linspace(0.99, 0.991, 8):
        traj = lj.simulate(KEPLER, pericentre_state(e), t1=ts[-1], dt=0.0125, ts=ts,
                           solver=solver)  # fmt: skip
        energy = np.asarray(traj.energy())[4::4]  # every fourth save: the pericentre
        errors.append(energy / -0.5 - 1)
    rms = np.sqrt(np.mean(np.square(errors)))
    if compensated:
        assert rms <= 1e-12
    else:
        assert rms >= 3e-12  # what the compensated bound guards against


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_timing_follows_keplers_equation():
    """Kahan–Li's eighth order: the time along the exact orbit to 1e-9 after 100
    periods at 126 steps per period (Yoshida4 at the same step: 1e-3)."""
    e = 0.9
    ts = np.linspace(0, 100 * PERIOD, 37)
    traj = lj.simulate(kepler(), pericentre_state(e), t1=ts[-1], dt=0.05, ts=ts,
                       solver=lj.TimeTransformed(lj.KahanLi8()))  # fmt: skip
    assert np.abs(np.asarray(traj.q) - kepler_position(ts, e)).max() <= 1e-9


def _one_step(splitting, ds):
    """The extended map Y ↦ Φ_ds(Y) on the flat ((p, p_t), (q, t)) of Kepler's
    problem, and the start state."""
    solver = lj.TimeTransformed(splitting)
    terms = solver.terms(kepler())
    start = extended_state(kepler(), pericentre_state(0.6), 0.0, None)
    flat, unravel = ravel_pytree(start)

    def step(y):
        y = unravel(y)
        state = splitting.init(terms, 0.0, ds, y, None)
        y1, *_ = splitting.step(terms, 0.0, ds, y, None, state, False)
        return ravel_pytree(y1)[0]

    return step, flat


@pytest.mark.parametrize("splitting", [lj.Yoshida4(), lj.BlanesMoan6()])
def test_extended_map_is_symplectic(splitting):
    step, flat = _one_step(splitting, 0.3)
    jacobian = jax.jacfwd(step)(flat)
    n = flat.size // 2  # flat order: p, p_t, q, t: momenta first
    identity = np.eye(n)
    form = np.block([[np.zeros((n, n)), -identity], [identity, np.zeros((n, n))]])
    defect = jacobian.T @ form @ jacobian - form
    assert np.abs(defect).max() <= 1e-12
    assert np.abs(jacobian - np.eye(2 * n)).max() > 1e-2  # a real step


def test_extended_map_is_time_reversible():
    forward, flat = _one_step(lj.Yoshida4(), 0.3)
    backward, _ = _one_step(lj.Yoshida4(), -0.3)
    there = forward(flat)
    assert np.abs(there - flat).max() > 1e-2
    assert np.abs(backward(there) - flat).max() <= 1e-13


def perturbed_kepler() -> lj.SeparableHamiltonian:
    """Kepler with a 1/r³ term: precessing orbits, no closed form."""
    return lj.SeparableHamiltonian(
        lambda p: p @ p / 2,
        lambda q: -1 / jnp.sqrt(q @ q) - 0.01 / jnp.sqrt(q @ q) ** 3,
    )


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_fourth_order_on_a_precessing_orbit():
    y0, t1 = pericentre_state(0.5), 7.0
    run = lambda splitting, ds: np.asarray(
        lj.simulate(perturbed_kepler(), y0, t1=t1, dt=ds,
                    solver=lj.TimeTransformed(splitting)).q[-1]
    )  # fmt: skip
    reference = run(lj.KahanLi8(), 0.01)
    steps = np.array([0.2, 0.1, 0.05])
    errors = [np.abs(run(lj.Yoshida4(), ds) - reference).max() for ds in steps]
    slope = np.polyfit(np.log(steps), np.log(errors), 1)[0]
    assert 3.7 <= slope <= 4.3, (errors, slope)


@pytest.mark.integration  # a long run; CI runs it in its integration step (default-suite time)
def test_a_users_weight_gives_the_same_orbit():
    """w(x) = x^(-3/2): dt/ds = r^(3/2), steps still finer at pericentre."""
    e, ts = 0.7, np.linspace(0, 3 * PERIOD, 7)
    solver = lj.TimeTransformed(lj.KahanLi8(), weight=lambda x: x**-1.5)
    traj = lj.simulate(kepler(), pericentre_state(e), t1=ts[-1], dt=0.02, ts=ts,
                       solver=solver)  # fmt: skip
    assert np.abs(np.asarray(traj.q) - kepler_position(ts, e)).max() <= 1e-8


@pytest.mark.integration  # long compile: CI's second step
def test_vmap_over_eccentricities_and_jit():
    eccentricities = jnp.array([0.5, 0.9, 0.99])
    solver = lj.TimeTransformed(lj.Yoshida4())
    # Several saves, two in the first step: each member's loop to each save time.
    ts = jnp.array([0.0, 1e-4, 2e-4, 0.3, 2.0, 4.5, PERIOD])

    @jax.jit
    def positions(e):
        q0 = jnp.array([1 - e, 0.0])
        p0 = jnp.array([0.0, jnp.sqrt((1 + e) / (1 - e))])
        return lj.simulate(KEPLER, (q0, p0), t1=PERIOD, ts=ts, dt=0.01,
                           solver=solver).q  # fmt: skip

    batched = jax.vmap(positions)(eccentricities)
    for e, q in zip(eccentricities, batched):
        alone = lj.simulate(KEPLER, pericentre_state(float(e)), t1=PERIOD, ts=ts,
                            dt=0.01, solver=solver).q  # fmt: skip
        assert np.abs(q - alone).max() <= 1e-13
        assert np.abs(q - kepler_position(ts, float(e))).max() <= 1e-6
    # After one period, back at pericentre.
    expected = np.stack([1 - eccentricities, 0 * eccentricities], axis=1)
    assert np.abs(batched[:, -1] - expected).max() <= 1e-6


@pytest.mark.integration  # long compile: CI's second step
def test_grad_through_a_bounded_run_matches_finite_differences():
    solver = lj.TimeTransformed(lj.Yoshida4())

    def x_final(speed):
        y0 = (jnp.array([0.5, 0.0]), jnp.array([0.0, speed]))
        traj = lj.simulate(kepler(), y0, t1=4.0, dt=0.02, solver=solver,
                           max_steps=600)  # fmt: skip
        return traj.q[-1, 0]

    speed, h = 1.6, 1e-5
    gradient = jax.grad(x_final)(speed)
    finite = (x_final(speed + h) - x_final(speed - h)) / (2 * h)
    assert abs(gradient - finite) <= 1e-6 * max(1.0, abs(finite))
    assert abs(gradient) > 1e-2


def test_too_few_steps_is_reported():
    solver = lj.TimeTransformed(lj.Yoshida4())
    y0 = pericentre_state(0.5)
    with pytest.raises(Exception, match="did not reach the last save time"):
        lj.simulate(kepler(), y0, t1=10.0, dt=0.05, solver=solver, max_steps=10)
    traj = lj.simulate(kepler(), y0, t1=10.0, dt=0.05, solver=solver,
                       max_steps=10, throw=False)  # fmt: skip
    assert traj.result == diffrax.RESULTS.max_steps_reached
    assert np.isnan(np.asarray(traj.q)).all()


def test_refusals_name_the_problem():
    solver = lj.TimeTransformed(lj.Yoshida4())
    y0 = pericentre_state(0.5)
    general = lj.Hamiltonian(lambda q, p: p @ p / 2 - 1 / jnp.sqrt(q @ q))
    with pytest.raises(ValueError, match=r"T\(p\) \+ V\(q\)"):
        lj.simulate(general, y0, t1=1.0, dt=0.05, solver=solver)
    repulsive = lj.SeparableHamiltonian(
        lambda p: p @ p / 2, lambda q: 1 / jnp.sqrt(q @ q)
    )
    with pytest.raises(ValueError, match="weight"):
        lj.simulate(repulsive, y0, t1=1.0, dt=0.05, solver=solver)
    for ds in (0.0, -0.1):
        with pytest.raises(ValueError, match="fictitious step"):
            lj.simulate(kepler(), y0, t1=1.0, dt=ds, solver=solver)
    with pytest.raises(ValueError, match="fictitious step"):
        lj.simulate(kepler(), y0, t1=1.0, solver=solver)
    with pytest.raises(ValueError, match="Nyström"):
        lj.TimeTransformed(lj.BlanesMoanNystrom6())
    with pytest.raises(ValueError, match="dense"):
        lj.simulate(kepler(), y0, t1=1.0, dt=0.05, solver=solver, dense=True)


def test_simulates_tolerances_are_refused_not_ignored():
    y0 = pericentre_state(0.5)
    for solver in (lj.TimeTransformed(lj.Yoshida4()),
                   lj.TimeTransformed(lj.GraggBulirschStoer())):  # fmt: skip
        with pytest.raises(ValueError, match=r"takes no rtol from simulate.*"
                           r"GraggBulirschStoer\(rtol="):  # fmt: skip
            lj.simulate(kepler(), y0, t1=1.0, dt=0.05, solver=solver, rtol=1e-10)


def slow_far_kepler(mu: float = 2.96e-4, r: float = 5.0):
    """A circular orbit in AU and days (the Sun's GM): w(−V) = r/μ ≈ 1.7e4, so a
    fictitious step ds = 1e-3 is a physical step of about 17 days."""
    system = lj.SeparableHamiltonian(
        lambda p: p @ p / 2, lambda q: -mu / jnp.sqrt(q @ q)
    )
    return system, (jnp.array([r, 0.0]), jnp.array([0.0, np.sqrt(mu / r)]))


def test_step_count_is_judged_from_the_physical_step():
    system, y0 = slow_far_kepler()
    solver = lj.TimeTransformed(lj.Yoshida4())
    with pytest.raises(ValueError, match=r"physical step of 1\.689\d*e-05"):
        lj.simulate(system, y0, t1=1e6, dt=1e-9, solver=solver)  # 6e10 steps


def test_step_count_is_judged_from_the_orbits_mean_pace():
    """From the pericentre of e = 0.9999, dt/ds = r = 1e-4: at that pace
    ds = 0.05 over 1000 periods would be 1.3e9 steps, but the orbit's mean pace
    (⟨r⟩ ~ a = 1) makes it 1.3e5, which runs; an unbound start (E ≥ 0) has no mean
    pace and is judged at the start's."""
    solver = lj.TimeTransformed(lj.Yoshida4())
    span = 1000 * 2 * np.pi
    weight0, mean = start_weights(solver, kepler(), pericentre_state(0.9999), 0.0, None)
    # E = v²/2 − 1/r cancels terms of 1e4: its round-off is 1e-12 of 1e4.
    assert abs(float(mean) - 1.0) < 1e-9 and abs(float(weight0) - 1e-4) < 1e-12
    _check_step_count(solver, 0.0, span, 0.05, weight0, mean)  # not refused
    with pytest.raises(ValueError, match=r"about 1\.26e\+09 steps"):
        _check_step_count(solver, 0.0, span, 0.05, weight0, jnp.nan)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_a_small_fictitious_step_in_days_runs():
    """1e6 days at ds = 1e-3: 10⁹ fictitious units of t, 6·10⁴ steps (refused
    when the span was divided by ds as if it were dt)."""
    system, y0 = slow_far_kepler()
    period = 2 * np.pi * np.sqrt(5.0**3 / 2.96e-4)  # about 4083 days
    run = lj.simulate(system, y0, t1=1e6, dt=1e-3,
                      solver=lj.TimeTransformed(lj.Yoshida4()))  # fmt: skip
    radius = float(jnp.linalg.norm(run.q[-1]))
    angle = float(jnp.arctan2(run.q[-1][1], run.q[-1][0]))
    expected = float(np.angle(np.exp(2j * np.pi * 1e6 / period)))
    # The orbit's shape is exact (the logarithmic Hamiltonian); its timing is
    # Yoshida4's at about 240 steps per orbit, over 245 orbits.
    assert abs(radius - 5.0) < 1e-9 and abs(angle - expected) < 1e-4
