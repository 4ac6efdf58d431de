"""simulate(): every system/solver pairing, saving, batching, differentiation, failures."""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj

OMEGA = 1.7


def oscillator_lagrangian():
    return lj.Lagrangian(lambda x, v, t, w: 0.5 * v**2 - 0.5 * w**2 * x**2)


def oscillator_hamiltonian():
    return lj.SeparableHamiltonian(
        lambda p: 0.5 * p**2, lambda x, t, w: 0.5 * w**2 * x**2
    )


# One instance for the tests whose runs compile alike (a new instance has new
# functions, so its runs compile again).
OSCILLATOR = oscillator_hamiltonian()


def exact_oscillator(x0, v0, w, t):
    return x0 * np.cos(w * t) + v0 / w * np.sin(w * t)


def double_pendulum(q, qd):
    kinetic = qd[0] ** 2 + 0.5 * qd[1] ** 2 + qd[0] * qd[1] * jnp.cos(q[0] - q[1])
    return kinetic + 9.81 * (2 * jnp.cos(q[0]) + jnp.cos(q[1]))


@pytest.mark.parametrize(
    "system, solver, expected_name",
    [
        (oscillator_hamiltonian(), None, "Yoshida4"),
        (oscillator_hamiltonian(), lj.BlanesMoan4(), "BlanesMoan4"),
        (oscillator_hamiltonian(), lj.GaussLegendre(stages=3), "GaussLegendre"),
        (oscillator_lagrangian(), None, "GaussLegendre"),
        (oscillator_lagrangian(), diffrax.Dopri8(), "Dopri8"),
        (oscillator_lagrangian(), lj.ImplicitMidpoint(), "ImplicitMidpoint"),
    ],
)
def test_fixed_step_pairings_solve_the_oscillator(system, solver, expected_name):
    x0, v0 = 0.3, -0.8
    ts = jnp.linspace(0.0, 3.0, 7)
    traj = lj.simulate(
        system, (x0, v0), t1=3.0, dt=0.01, solver=solver, ts=ts, args=OMEGA
    )
    assert traj.stats["solver"] == expected_name
    tolerance = 1e-4 if expected_name == "ImplicitMidpoint" else 1e-8
    assert np.allclose(traj.q, exact_oscillator(x0, v0, OMEGA, ts), atol=tolerance)
    # q̇ and p are derived on demand from whichever was integrated (m = 1: equal).
    assert np.allclose(traj.qdot, traj.p, atol=1e-12)


def test_adaptive_default_and_final_state_only():
    traj = lj.simulate(
        oscillator_lagrangian(), (1.0, 0.0), t1=2.0, args=OMEGA, rtol=1e-10, atol=1e-10
    )
    # below rtol = 1e-9 the default is eighth order (solver_choice.HIGH_ORDER_RTOL)
    assert traj.stats["solver"] == "Dopri8"
    assert traj.ts.shape == (1,)
    assert np.isclose(traj.q[-1], exact_oscillator(1.0, 0.0, OMEGA, 2.0), atol=1e-8)
    assert int(traj.stats["num_rejected_steps"]) >= 0


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_lagrangian_through_gauss_legendre_conserves_energy():
    lag = lj.Lagrangian(double_pendulum, quadratic_in_velocity=True)
    y0 = (jnp.array([2.0, 2.5]), jnp.zeros(2))
    ts = jnp.linspace(0.0, 10.0, 101)
    # The energy error is truncation, falling as dt⁶ (8e-8, 1.2e-9, 1.8e-11 at
    # dt = 0.01, 0.005, 0.0025 on this chaotic orbit).
    symplectic = lj.simulate(
        lag, y0, t1=10.0, dt=0.0025, solver=lj.GaussLegendre(stages=3), ts=ts
    )
    energy = np.asarray(symplectic.energy())  # numpy: no small compilations
    assert np.max(np.abs(energy - energy[0]) / np.abs(energy[0])) < 1e-10
    reference = lj.simulate(
        lag, y0, t1=1.0, solver=diffrax.Dopri8(), rtol=1e-12, atol=1e-12
    )
    short = lj.simulate(lag, y0, t1=1.0, dt=0.005, solver=lj.GaussLegendre(stages=3))
    assert np.allclose(short.q[-1], reference.q[-1], atol=1e-9)
    assert np.allclose(short.qdot[-1], reference.qdot[-1], atol=1e-8)


def test_vmap_equals_loop_and_sweep():
    system = OSCILLATOR
    x0s = jnp.linspace(-1.0, 1.0, 8)
    omegas = jnp.linspace(0.5, 2.0, 8)

    def final(x0, w):
        return lj.simulate(system, (x0, 0.0), t1=1.0, dt=0.01, args=w).q[-1]

    batched = jax.jit(jax.vmap(final))(x0s, omegas)
    looped = jnp.stack([final(x, w) for x, w in zip(x0s, omegas)])
    assert np.allclose(batched, looped, rtol=1e-14, atol=1e-15)
    swept = lj.sweep(system, (x0s, jnp.zeros(8)), omegas, t1=1.0, dt=0.01)
    assert np.allclose(swept.q[:, -1], batched, rtol=1e-14, atol=1e-15)


def test_grad_wrt_initial_state_and_parameter():
    system = oscillator_hamiltonian()
    t1 = 1.3

    def final_q(x0, w):
        return lj.simulate(system, (x0, 0.0), t1=t1, dt=0.005, args=w).q[-1]

    # Jitted: eagerly, the forward and the backward pass compile separately.
    dx0, dw = jax.jit(jax.grad(final_q, argnums=(0, 1)))(0.4, OMEGA)
    # x(t) = x0 cos ωt: ∂x/∂x0 = cos ωt, ∂x/∂ω = −x0 t sin ωt.
    assert np.isclose(dx0, np.cos(OMEGA * t1), atol=1e-8)
    assert np.isclose(dw, -0.4 * t1 * np.sin(OMEGA * t1), atol=1e-8)


def test_forward_mode_jacobian():
    system = oscillator_hamiltonian()
    t1 = 0.9

    def final_state(y0):
        traj = lj.simulate(
            system,
            (y0[0], y0[1]),
            t1=t1,
            dt=0.005,
            args=OMEGA,
            adjoint=diffrax.ForwardMode(),
        )
        return jnp.stack([traj.q[-1], traj.p[-1]])

    # Jitted: eagerly, jacfwd's bookkeeping around the run compiles piece by piece.
    jac = jax.jit(jax.jacfwd(final_state))(jnp.array([0.2, 0.1]))
    c, s = np.cos(OMEGA * t1), np.sin(OMEGA * t1)
    expected = np.array([[c, s / OMEGA], [-OMEGA * s, c]])
    assert np.allclose(jac, expected, atol=1e-8)


def test_failure_keeps_what_was_computed():
    ts = jnp.linspace(0.0, 10.0, 11)
    traj = lj.simulate(
        oscillator_lagrangian(),
        (1.0, 0.0),
        t1=10.0,
        solver=diffrax.Tsit5(),
        ts=ts,
        args=OMEGA,
        max_steps=20,
        throw=False,
    )
    assert traj.result != diffrax.RESULTS.successful
    assert np.isfinite(traj.q[0])
    with pytest.raises(Exception, match="max_steps"):
        lj.simulate(
            oscillator_lagrangian(), (1.0, 0.0), t1=10.0, args=OMEGA, max_steps=20
        )


def test_singular_mass_matrix_during_run_raises():
    lag = lj.Lagrangian(lambda q, qd: q * qd - 0.5 * q**2)
    with pytest.raises(Exception, match="non-finite"):
        lj.simulate(lag, (1.0, 0.0), t1=1.0, dt=0.1, solver=diffrax.Heun())


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(dt=0.0), "dt must be a finite non-zero"),
        (dict(dt=-0.1), "points away from t1"),
        (dict(t1=0.0, dt=0.1), "t1 must differ"),
        (dict(solver=lj.StormerVerlet()), "cannot choose its own step"),
    ],
)
def test_bad_arguments(kwargs, message):
    with pytest.raises(ValueError, match=message):
        lj.simulate(oscillator_hamiltonian(), (1.0, 0.0), args=OMEGA, **kwargs)


def test_splitting_needs_separable_system():
    with pytest.raises(ValueError, match="separable"):
        lj.simulate(
            oscillator_lagrangian(),
            (1.0, 0.0),
            dt=0.1,
            solver=lj.Yoshida4(),
            args=OMEGA,
        )
    general = lj.Hamiltonian(lambda q, p: 0.5 * p**2 + 0.5 * q**2)
    with pytest.raises(ValueError, match="SeparableHamiltonian"):
        lj.simulate(general, (1.0, 0.0), dt=0.1, solver=lj.StormerVerlet())


@pytest.mark.parametrize(
    "solver", [lj.Yoshida4(), lj.GaussLegendre(stages=2), diffrax.Tsit5()]
)
def test_fixed_step_scan_path_matches_diffeqsolve(solver):
    # Final-state-only runs take the lax.scan path; asking for ts takes diffeqsolve.
    # t1 is not a multiple of dt, so both must shorten the last step alike.
    system = oscillator_hamiltonian()
    kwargs = dict(t1=1.234, dt=0.01, solver=solver, args=OMEGA)
    fast = lj.simulate(system, (0.3, -0.2), **kwargs)
    general = lj.simulate(system, (0.3, -0.2), ts=jnp.array([1.234]), **kwargs)
    assert np.allclose(fast.q, general.q, atol=1e-13)
    assert np.allclose(fast.p, general.p, atol=1e-13)
    assert int(fast.stats["num_steps"]) == int(general.stats["num_steps"]) == 124


def test_failed_implicit_solve_is_reported_on_the_scan_path():
    stiff = lj.SeparableHamiltonian(lambda p: 0.5 * p**2, lambda q: 0.5e6 * q**2)
    solver = lj.GaussLegendre(stages=2)  # fixed-point iteration diverges at ωh = 100
    traj = lj.simulate(stiff, (1.0, 0.0), t1=1.0, dt=0.1, solver=solver, throw=False)
    assert traj.result != diffrax.RESULTS.successful
    with pytest.raises(Exception, match=r"stage equations of .* did not converge"):
        lj.simulate(stiff, (1.0, 0.0), t1=1.0, dt=0.1, solver=solver)


def test_progress_meter_runs_and_reports(capfd):
    traj = lj.simulate(
        oscillator_hamiltonian(), (1.0, 0.0), t1=1.0, dt=0.01, args=OMEGA, progress=True
    )
    jax.block_until_ready(traj.q)
    assert "100.00%" in capfd.readouterr().out
    assert np.isclose(traj.q[-1], np.cos(OMEGA), atol=1e-8)


def test_save_at_every_step_is_not_mistaken_for_a_failure():
    # diffrax pads SaveAt(steps=True) with inf; those slots are not results.
    traj = lj.simulate(
        oscillator_lagrangian(),
        (1.0, 0.0),
        t1=1.0,
        args=OMEGA,
        solver=diffrax.Tsit5(),
        saveat=diffrax.SaveAt(steps=True),
    )
    used = np.isfinite(np.asarray(traj.ts))
    assert used.sum() == int(traj.stats["num_accepted_steps"])
    assert np.allclose(
        np.asarray(traj.q)[used], np.cos(OMEGA * np.asarray(traj.ts)[used]), atol=1e-6
    )


def test_numpy_and_jax_scalar_times_and_variational_refusal():
    system = OSCILLATOR
    # Array y0 and args of the vmap test's types: its compiled run serves both.
    start, omega = (jnp.float64(1.0), 0.0), jnp.float64(OMEGA)
    for t1, dt in [(np.float64(1.0), np.float64(0.01)), (jnp.asarray(1.0), 0.01)]:
        traj = lj.simulate(system, start, t1=t1, dt=dt, args=omega)
        assert np.isclose(traj.q[-1], np.cos(OMEGA), atol=1e-8)
    # Traced times still work (inside jit, dt and t1 as arguments).
    traced = jax.jit(
        lambda t1: lj.simulate(
            system, (1.0, 0.0), t1=t1, dt=0.01, args=OMEGA, max_steps=200
        ).q[-1]
    )
    assert np.isclose(traced(1.0), np.cos(OMEGA), atol=1e-6)
    damped = lj.Lagrangian(
        lambda x, v: 0.5 * v**2 - 0.5 * x**2, dissipation=lambda v: v**2
    )
    with pytest.raises(ValueError, match="conservative action"):
        lj.simulate(
            damped, (1.0, 0.0), t1=1.0, dt=0.01, solver=lj.VariationalMidpoint()
        )


def test_saved_fixed_step_runs_get_their_exact_step_budget():
    """10⁵ + 2·10⁴ fixed steps with saving: not cut off by the adaptive default 10⁵."""
    oscillator = lj.SeparableHamiltonian(lambda p: 0.5 * p**2, lambda q: 0.5 * q**2)
    t1, steps = 120.0, 120_000
    trajectory = lj.simulate(
        oscillator, (1.0, 0.0), t1=t1, dt=t1 / steps, solver=lj.StormerVerlet(),
        ts=jnp.linspace(0.0, t1, 3),
    )  # fmt: skip
    assert int(trajectory.stats["num_steps"]) == steps
    assert abs(float(trajectory.q[-1]) - np.cos(t1)) < 1e-5  # (h²/24)·t phase error


@pytest.mark.parametrize("saved", [False, True])
def test_diffrax_implicit_solver_with_a_fixed_step(saved):
    """Kvaerno5 at a fixed dt: its Newton tolerances come from simulate's rtol/atol."""
    lag = oscillator_lagrangian()
    ts = jnp.linspace(0.0, 1.0, 3) if saved else None
    trajectory = lj.simulate(
        lag, (1.0, 0.0), t1=1.0, dt=0.01, solver=diffrax.Kvaerno5(), args=1.0, ts=ts
    )
    assert abs(float(trajectory.q[-1]) - np.cos(1.0)) < 1e-8


def test_diffrax_implicit_solver_with_a_fixed_step_on_a_nonlinear_pendulum():
    """Kvaerno5 at the 150° pendulum scene's dt = 0.01: diffrax's chord iteration
    stopped it as diverged at rtol ≤ 1e-8; at a fixed step it runs on Newton and
    meets the period's elliptic closed form to its truncation error."""
    scene = lj.scenes.SimplePendulum()
    period = float(scene.period())
    run = lj.simulate(scene, scene.initial_state(), t1=period, dt=period / 400,
                      solver=diffrax.Kvaerno5(), rtol=1e-10, atol=1e-10)  # fmt: skip
    assert abs(float(run.q[-1]) - float(scene.amplitude)) < 1e-7


def test_fixed_steps_are_all_equal_on_an_awkward_dt():
    """dt = 1/60: every grid time of the scan path is exact, so every h is equal.

    Checked on the grid and through its consequence: Störmer–Verlet (kick–drift–
    kick) on H = (p² + q²)/2 keeps H̃ = (p² + (1 − h²/4) q²)/2 exactly but for
    round-off. Over 6·10⁴ steps that stays at ~1e-16 (Brouwer, compensated);
    with the raw 1/60 the ulp-wobble of h made it 4.4e-14 (6·10⁵ steps: 7e-12).
    """
    from lagjax._integrate.time_grid import grid_step

    steps, dt = 60_000, 1 / 60
    rounded = grid_step(0.0, steps * dt, dt)
    assert abs(rounded - dt) <= 1e-8 * dt
    grid = np.arange(steps + 1) * rounded
    assert len(set(np.diff(grid))) == 1  # exact; np.arange(...) / 60 is not
    assert len(set(np.diff(np.arange(steps + 1) * dt))) > 1
    assert grid_step(0.1, steps * dt, dt) == dt  # t0 off the grid: left alone

    oscillator = lj.SeparableHamiltonian(lambda p: 0.5 * p**2, lambda q: 0.5 * q**2)
    start = (np.cos(0.3), np.sin(0.3))
    final = lj.simulate(
        oscillator, start, t1=steps * rounded, dt=dt, solver=lj.StormerVerlet()
    )
    assert int(final.stats["num_steps"]) == steps

    def modified(q, p):
        return 0.5 * (p**2 + (1 - rounded**2 / 4) * q**2)

    drift = modified(float(final.q[-1]), float(final.p[-1])) - modified(*start)
    assert abs(drift) < 1e-15, drift
