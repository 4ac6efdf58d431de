"""`simulate(..., solver=lj.Taylor())`: the derived equations by Taylor series, by
JAX and by heyoka, against closed forms; what it cannot do, refused by name."""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj

pytest.importorskip("heyoka")

OMEGA = 1.7


def oscillator():
    return lj.Lagrangian(lambda q, qdot: 0.5 * qdot**2 - 0.5 * OMEGA**2 * q**2)


@pytest.mark.parametrize("backend", ["jax", "heyoka"])
def test_the_oscillator_follows_its_closed_form(backend):
    ts = jnp.linspace(0.0, 10.0, 11)
    run = lj.simulate(oscillator(), (1.0, 0.0), t1=10.0, ts=ts, rtol=1e-14,
                      atol=1e-14, solver=lj.Taylor(backend=backend))  # fmt: skip
    assert run.result == diffrax.RESULTS.successful
    assert run.stats["solver"] == f"Taylor[{backend}]"
    np.testing.assert_allclose(run.q, np.cos(OMEGA * ts), atol=1e-12)
    np.testing.assert_allclose(run.qdot, -OMEGA * np.sin(OMEGA * ts), atol=1e-12)


def test_a_separable_hamiltonian_through_heyoka_keeps_its_energy():
    kepler = lj.SeparableHamiltonian(
        lambda p: 0.5 * jnp.sum(p**2), lambda q: -1.0 / jnp.sqrt(jnp.sum(q**2))
    )
    y0 = (jnp.array([1.0, 0.0]), jnp.array([0.0, 1.2]))
    run = lj.simulate(kepler, y0, t1=50.0, ts=jnp.linspace(0, 50, 51),
                      solver=lj.Taylor(backend="heyoka"), rtol=1e-15, atol=1e-15)  # fmt: skip
    energy = np.asarray(run.energy())
    assert np.max(np.abs(energy - energy[0])) < 1e-13


def test_heyoka_runs_under_jit_and_refuses_gradients_by_name():
    def final(q0):
        run = lj.simulate(oscillator(), (q0, 0.0), t1=1.0, rtol=1e-14, atol=1e-14,
                          solver=lj.Taylor(backend="heyoka"))  # fmt: skip
        return run.q[-1]

    assert jax.jit(final)(1.0) == pytest.approx(np.cos(OMEGA), abs=1e-13)
    with pytest.raises(TypeError, match=r"backend='jax'"):
        jax.grad(final)(1.0)


def test_running_out_of_steps_is_one_clear_error():
    with pytest.raises(lj.SimulationError, match="max_steps = 5"):
        lj.simulate(oscillator(), (1.0, 0.0), t1=100.0, max_steps=5,
                    solver=lj.Taylor(backend="heyoka"), rtol=1e-14, atol=1e-14)  # fmt: skip


@pytest.mark.parametrize("backend", ["jax", "heyoka"])
def test_out_of_steps_names_the_tolerance_the_solver_used(backend):
    """The solver's own rtol, not simulate's default it overrode."""
    with pytest.raises(lj.SimulationError, match=r"rtol = 1e-13\)"):
        lj.simulate(oscillator(), (1.0, 0.0), t1=100.0, max_steps=5,
                    solver=lj.Taylor(rtol=1e-13, atol=1e-13, backend=backend))  # fmt: skip


@pytest.mark.parametrize(
    "options, named",
    [
        ({"dt": 0.1}, "dt"),
        ({"stepsize_controller": diffrax.PIDController(1e-6, 1e-6)}, "stepsize"),
        ({"adjoint": diffrax.ForwardMode()}, "adjoint"),
    ],
)
def test_options_a_taylor_run_does_not_have_are_refused(options, named):
    with pytest.raises(ValueError, match=named):
        lj.simulate(oscillator(), (1.0, 0.0), t1=1.0, solver=lj.Taylor(), **options)


def test_a_constrained_lagrangian_is_refused():
    pendulum = lj.Lagrangian(
        lambda q, v: 0.5 * jnp.sum(v**2) - 9.81 * q[1],
        constraints=lambda q: jnp.sum(q**2) - 1.0,
    )
    y0 = (jnp.array([1.0, 0.0]), jnp.zeros(2))
    with pytest.raises(ValueError, match="constraints"):
        lj.simulate(pendulum, y0, t1=1.0, solver=lj.Taylor())


def test_bad_backend_and_tolerances_are_refused():
    with pytest.raises(ValueError, match="backend"):
        lj.Taylor(backend="llvm")
    with pytest.raises(ValueError, match="rtol"):
        lj.Taylor(rtol=-1.0)


def _pendulum_with(args):
    """L of a pendulum whose args also hold a number its equations never read
    (as a scene's args hold its initial amplitude)."""
    return lj.Lagrangian(lambda q, v, t, a: a["m"] * (
        0.5 * a["l"] ** 2 * v**2 + a["g"] * a["l"] * jnp.cos(q)))  # fmt: skip


@pytest.mark.parametrize("unused", ["a_release", "z_release"])  # first or last
def test_a_parameter_the_equations_never_read_reaches_heyoka(unused):
    """heyoka counts the parameters its equations use (the highest index, plus
    one) and refuses more values: one unused and last in args was heyoka's
    ValueError for one trajectory, saved states and a batch. On the closed
    form's small-oscillation period 2π √(l/g) they all return to the start."""
    args = {"m": 3.0, "l": 0.5, "g": 9.81, unused: 0.7}
    system, theta0 = _pendulum_with(args), 1e-4  # period shift θ₀²/16: 6e-10
    period = 2 * np.pi * np.sqrt(0.5 / 9.81)
    heyoka = lj.Taylor(backend="heyoka", rtol=1e-15, atol=1e-15)
    one = lj.simulate(system, (theta0, 0.0), t1=period, args=args, solver=heyoka)
    saved = lj.simulate(system, (theta0, 0.0), t1=period, args=args, solver=heyoka,
                        ts=jnp.linspace(0.0, period, 5))  # fmt: skip
    batch = jax.vmap(lambda a0: lj.simulate(system, (a0, 0.0), t1=period, args=args,
                                             solver=heyoka).q[-1])  # fmt: skip
    np.testing.assert_allclose(one.q[-1], theta0, rtol=1e-8)
    np.testing.assert_allclose(saved.q[::2], [theta0, -theta0, theta0], rtol=1e-8)
    np.testing.assert_allclose(batch(jnp.array([theta0, 2 * theta0])),
                               [theta0, 2 * theta0], rtol=1e-8)  # fmt: skip
