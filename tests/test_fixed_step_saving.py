"""Fixed-step runs that save states on the step grid: nested scans, no interpolation.

The oracle is the exact solution of the harmonic oscillator (q = cos t) and of the
pendulum's energy, and diffrax's own loop on the same solver (round-off apart).
"""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax._integrate.fixed_step_loop import uniform_grid_saves

OSCILLATOR = lj.SeparableHamiltonian(lambda p: 0.5 * p**2, lambda q: 0.5 * q**2)
START = (jnp.asarray(1.0), jnp.asarray(0.0))


def test_grid_detection():
    assert uniform_grid_saves(0.0, 0.1, np.linspace(0.0, 1.0, 11)) == (0, 1, 11)
    assert uniform_grid_saves(0.0, 0.1, np.array([0.3, 0.7, 1.1])) == (3, 4, 3)
    assert uniform_grid_saves(1.0, -0.5, np.array([0.0, -1.0])) == (2, 2, 2)
    assert uniform_grid_saves(0.0, 0.1, np.array([0.0, 0.15])) is None  # off grid
    assert uniform_grid_saves(0.0, 0.1, np.array([0.0, 0.1, 0.3])) is None  # uneven
    assert uniform_grid_saves(0.0, 0.1, np.array([0.2, 0.1])) is None  # backwards
    assert uniform_grid_saves(0.0, 0.1, np.array([-0.1, 0.0])) is None  # before t0


def test_saved_states_follow_the_exact_solution_at_fourth_order():
    ts = jnp.linspace(0.0, 20.0, 41)
    errors = []
    for dt in (0.1, 0.05):
        run = lj.simulate(
            OSCILLATOR, START, t1=20.0, dt=dt, solver=lj.Yoshida4(), ts=ts
        )
        assert int(run.stats["num_steps"]) == round(20.0 / dt)
        np.testing.assert_array_equal(run.ts, ts)
        errors.append(float(jnp.max(jnp.abs(run.q - jnp.cos(ts)))))
    assert errors[1] < 1e-5
    assert 3.7 < np.log2(errors[0] / errors[1]) < 4.3


def test_saved_states_match_diffrax_loop_to_round_off():
    # The same solver and steps through diffeqsolve (forced by an explicit SaveAt).
    # The scan runs on the exact grid (`step_grid`: dt = 0.01 moved by up to half an
    # ulp of t1 = 5, 4.4e-16), diffrax on its own: 500 steps shift the phase by
    # up to 500 · 4.4e-16 = 2.2e-13.
    ts = jnp.linspace(0.0, 5.0, 11)
    options = dict(t1=5.0, dt=0.01, solver=lj.StormerVerlet())
    scan = lj.simulate(OSCILLATOR, START, ts=ts, **options)
    loop = lj.simulate(OSCILLATOR, START, saveat=diffrax.SaveAt(ts=ts), **options)
    for a, b in zip(scan.ys, loop.ys):
        np.testing.assert_allclose(a, b, rtol=0, atol=3e-13)


def test_first_save_after_t0_and_backward_runs():
    forward = lj.simulate(
        OSCILLATOR, START, t1=3.0, dt=0.01, ts=jnp.array([1.0, 2.0, 3.0])
    )
    np.testing.assert_allclose(
        forward.q, jnp.cos(jnp.array([1.0, 2.0, 3.0])), atol=1e-9
    )
    backward = lj.simulate(
        OSCILLATOR, START, t0=0.0, t1=-2.0, dt=-0.01, ts=jnp.array([-1.0, -2.0])
    )
    np.testing.assert_allclose(backward.q, jnp.cos(jnp.array([1.0, 2.0])), atol=1e-9)


def test_off_grid_save_times_still_give_the_solution():
    # Off the grid the run goes through diffeqsolve's interpolation: still close.
    ts = jnp.array([0.0, 0.555, 1.0])
    run = lj.simulate(OSCILLATOR, START, t1=1.0, dt=0.01, ts=ts)
    np.testing.assert_allclose(run.q, jnp.cos(ts), atol=1e-4)


def test_lagrangian_saved_run_conserves_energy_and_batches():
    pendulum = lj.Lagrangian(lambda q, qdot: 0.5 * qdot**2 + jnp.cos(q))
    ts = jnp.linspace(0.0, 10.0, 101)

    def energies(q0):
        run = lj.simulate(pendulum, (q0, 0.0), t1=10.0, dt=0.01, ts=ts)
        return run.energy()

    batch = jax.vmap(energies)(jnp.array([1.0, 2.0, 3.0]))
    assert batch.shape == (3, 101)
    exact = -jnp.cos(jnp.array([1.0, 2.0, 3.0]))
    assert float(jnp.max(jnp.abs(batch - exact[:, None]))) < 1e-9


@pytest.mark.parametrize("throw", [True, False])
def test_failed_implicit_step_is_reported_on_the_saving_path(throw):
    # Newton's stage solve cannot converge with one iteration on a stiff step.
    stiff = lj.SeparableHamiltonian(lambda p: 0.5 * p**2, lambda q: 0.5e6 * q**4)
    solver = lj.GaussLegendre(stages=2, root_find_max_steps=1)
    ts = jnp.linspace(0.0, 1.0, 11)
    call = lambda: lj.simulate(
        stiff, START, t1=1.0, dt=0.1, solver=solver, ts=ts, throw=throw
    )
    if throw:
        with pytest.raises(Exception, match=r"(?i)nonlinear|solve|converge"):
            call()
    else:
        assert call().result != diffrax.RESULTS.successful
