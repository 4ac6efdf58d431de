"""Catalogue of bad input, round three, part two (issue 33): the cases the first
round could not fix in its files — refusals that name the problem and a remedy the
caller can apply, and a stale compilation that now gives the right physics.

The default run holds the refusals made before anything compiles (and one short
explicit run with dense output); the cases that compile more than that are marked
`integration`.
"""

import math
import warnings

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.mechanics.captured_globals import CapturedNumberWarning
from lagjax.scenes.driven import DampedDrivenOscillator
from lagjax.solvers.implicit import stage_failure_message

W = 1.5  # the oscillator's angular frequency (UPPER_CASE: a constant, not warned)
LAG = lj.Lagrangian(lambda q, qd: 0.5 * jnp.sum(qd**2) - 0.5 * W**2 * jnp.sum(q**2))
SEP = lj.SeparableHamiltonian(lambda p: 0.5 * p**2, lambda q: 0.5 * W**2 * q**2)
EMPTY = (jnp.zeros(0), jnp.zeros(0))
NO_COORDINATES = r"has no coordinates \(shape \(0,\)\).*at least one.*jnp\.array"


# -- 1. zero-length q outside simulate ----------------------------------------------


@pytest.mark.parametrize(
    "call",
    [
        lambda: LAG.acceleration(*EMPTY),
        lambda: jax.jit(LAG.acceleration)(*EMPTY),
        lambda: lj.linearize(LAG, EMPTY),
    ],
    ids=["acceleration", "acceleration under jit", "linearize"],
)
def test_zero_length_q_is_refused_by_name(call):
    with pytest.raises(ValueError, match=NO_COORDINATES):
        call()


# -- 2. the action of something that is not a trajectory -----------------------------


def test_action_of_a_tuple_names_the_trajectory_it_takes():
    states = (jnp.linspace(0.0, 1.0, 5), jnp.ones(5))
    with pytest.raises(TypeError, match=r"takes the Trajectory that lj\.simulate "
                       r"returns.*ts=.*got tuple.*action_of_path"):  # fmt: skip
        lj.action(LAG, states)


# -- 3. evaluating the dense output at a time that is not a number --------------------


@pytest.fixture(scope="module")
def dense_run():
    # Yoshida4 on H = p²/2 + W²q²/2 from (1, 0): q = cos(W t) to O(dt⁴).
    return lj.simulate(SEP, (1.0, 0.0), t1=1.0, dt=0.01, dense=True)


@pytest.mark.parametrize("t", [jnp.nan, np.inf, jnp.array([0.5, jnp.nan])])
def test_evaluate_refuses_a_time_that_is_not_finite(dense_run, t):
    with pytest.raises(ValueError, match=r"t(\[1\])? = (nan|inf) is not a finite "
                       r"time; evaluate at finite times inside .*\[t0, t1\]"):  # fmt: skip
        dense_run.evaluate(t)


@pytest.mark.integration
def test_evaluate_at_finite_times_still_gives_the_motion(dense_run):
    ts = jnp.array([0.25, 0.5, 1.0])
    q, _ = dense_run.evaluate(ts)
    np.testing.assert_allclose(q, np.cos(W * np.asarray(ts)), atol=1e-8)


@pytest.mark.integration
def test_evaluate_refuses_a_traced_nan_at_run_time(dense_run):
    at = eqx.filter_jit(lambda run, t: run.evaluate(t))
    with pytest.raises(RuntimeError, match="t is NaN or inf"):
        jax.block_until_ready(at(dense_run, jnp.array(jnp.nan)))
    with pytest.raises(RuntimeError, match="outside the integrated span"):
        jax.block_until_ready(at(dense_run, jnp.array(2.0)))


# -- 4. both ts and saveat ------------------------------------------------------------


@pytest.mark.parametrize("solver", [None, lj.Taylor()], ids=["default", "taylor"])
def test_ts_and_saveat_together_are_refused(solver):
    ts = jnp.array([0.5, 1.0])
    with pytest.raises(ValueError, match=r"both ts and saveat.*pass one.*"
                       r"saveat=diffrax\.SaveAt\(ts=\.\.\."):  # fmt: skip
        lj.simulate(LAG, (1.0, 0.0), t1=1.0, dt=0.1, solver=solver, ts=ts,
                    saveat=diffrax.SaveAt(t1=True))  # fmt: skip


# -- 5. traced save times that cannot be read -----------------------------------------


@pytest.fixture(scope="module")
def traced_save_run():
    return jax.jit(lambda ts: lj.simulate(SEP, (1.0, 0.0), t1=1.0, dt=0.01, ts=ts).q)


@pytest.mark.integration
@pytest.mark.parametrize(
    "ts, reason",
    [
        ([0.5, np.nan, 1.0], "NaN or inf"),
        ([0.5, np.inf, 1.0], "NaN or inf"),
        ([0.5, 0.25, 1.0], "not sorted from t0 towards t1"),
        ([0.5, 0.75, 1.5], r"outside \[t0, t1\]"),
    ],
)
def test_traced_save_times_that_cannot_be_read_are_refused(traced_save_run, ts, reason):
    with pytest.raises(RuntimeError, match=f"simulate: ts .*{reason}.*jnp.linspace"):
        jax.block_until_ready(traced_save_run(jnp.array(ts)))


@pytest.mark.integration
def test_traced_save_times_that_can_be_read_give_the_motion(traced_save_run):
    ts = jnp.array([0.25, 0.5, 1.0])
    np.testing.assert_allclose(traced_save_run(ts), np.cos(W * ts), atol=1e-8)


# -- 6. a failed stage solve names both of its causes ---------------------------------


@pytest.mark.parametrize("solver", [lj.GaussLegendre(), lj.ImplicitMidpoint()])
def test_stage_failure_names_stiffness_and_a_singular_mass_matrix(solver):
    message = stage_failure_message(solver)
    assert "stiff" in message and "reduce dt" in message
    assert "root_finder=optimistix.Newton" in message
    assert "singular or degenerate" in message and "∂²L/∂q̇²" in message
    assert "smaller t1" in message  # the remedy there, which no step size replaces
    assert "converges at any step" not in message  # Newton does not, past q = 0


@pytest.mark.integration
def test_a_fixed_step_run_into_a_singular_mass_matrix_says_so():
    # L = ½ q² q̇² from (1, −1): q² = 1 − 2t reaches the singular point at t = ½.
    vanishing = lj.Lagrangian(lambda q, qd: 0.5 * q**2 * qd**2)
    with pytest.raises(RuntimeError, match=r"did not converge.*stiff.*singular or "
                       r"degenerate.*smaller t1"):  # fmt: skip
        lj.simulate(vanishing, (1.0, -1.0), t1=1.0, dt=0.01, solver=lj.GaussLegendre())


# -- 7. a scene's check that the run cannot show --------------------------------------


@eqx.filter_jit
def closed_form(scene, ts):
    return scene.exact_solution(ts)


def exact_run(scene, t1, samples):
    """A `Trajectory` of the scene's closed form: its checks must all hold."""
    ts = jnp.linspace(0.0, t1, samples)
    system, args = scene.resolve(None)
    return lj.Trajectory(ts=ts, ys=closed_form(scene, ts), system=system,
                         args=args, run_stats={}, result=diffrax.RESULTS.successful,
                         solver_name="closed form")  # fmt: skip


def test_driven_response_on_a_short_run_is_not_judged():
    scene = DampedDrivenOscillator()  # γ = 1: the transient has died out by t = 40
    with pytest.raises(ValueError, match=r"cannot judge the steady-state response.*"
                       r"saved 0.*ends at t = 5\b.*t1 ≥ 40/γ \+ 4π/Ω = 48\.38"):  # fmt: skip
        scene.checks(exact_run(scene, 5.0, 51))


@pytest.mark.integration
def test_driven_checks_of_the_closed_form_hold_once_the_transient_is_gone():
    # Compiled (one program; the run's length is then known only at run time).
    scene, checked = DampedDrivenOscillator(), eqx.filter_jit(lambda s, r: s.checks(r))
    for name, (measured, expected) in checked(
        scene, exact_run(scene, 60.0, 601)
    ).items():
        np.testing.assert_allclose(measured, expected, rtol=1e-9, atol=1e-12,
                                   err_msg=name)  # fmt: skip
    with pytest.raises(RuntimeError, match="cannot judge the steady-state response"):
        jax.block_until_ready(checked(scene, exact_run(scene, 5.0, 601)))


@pytest.mark.integration
def test_free_damped_run_is_judged_at_any_length():
    # F₀ = 0 settles to rest: the energy decays as e^{−γt} on average from t = 0.
    scene = DampedDrivenOscillator(drive_amplitude=0.0)
    checks = scene.checks(exact_run(scene, 5.0, 51))
    measured, expected = checks["energy decay rate"]
    np.testing.assert_allclose(measured, expected, rtol=1e-12)


# -- 8. a module-level number rebound between two systems -----------------------------

g = 9.81  # lowercase on purpose: a number a user rebinds between runs
EARTH, MOON = 9.81, 1.62


def pendulum(q, qd):
    return 0.5 * qd**2 + g * jnp.cos(q)


def build_pendulum(gravity):
    global g
    g = gravity
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CapturedNumberWarning)
        return lj.Lagrangian(pendulum)


def test_systems_built_before_and_after_a_rebinding_differ():
    earth, moon, again = (build_pendulum(x) for x in (EARTH, MOON, EARTH))
    assert earth != moon and earth == again
    assert hash(jax.tree_util.tree_structure(earth)) == hash(
        jax.tree_util.tree_structure(again)
    )
    assert jax.tree_util.tree_structure(earth) != jax.tree_util.tree_structure(moon)


def test_the_warning_says_a_new_system_reads_the_new_value():
    global g
    g = EARTH
    with pytest.warns(CapturedNumberWarning, match=r"rebinding g .*old value with "
                      r"this object.*built after the rebinding reads the new one"):  # fmt: skip
        lj.Lagrangian(pendulum)


def small_angle_final_angle(system, gravity, amplitude=1e-4, t1=1.0):
    """q(t1) of a run from (amplitude, 0), and the small-angle closed form."""
    final = lj.simulate(system, (amplitude, 0.0), t1=t1, dt=0.01).q[-1]
    return float(final), amplitude * math.cos(math.sqrt(gravity) * t1)


@pytest.mark.integration
def test_a_new_lagrangian_after_rebinding_g_gives_the_moon():
    # Amplitude 1e-4: the small-angle closed form holds to ~1e-9 relative (the
    # next term is amplitude²/16), far below the Earth–Moon difference.
    earth = build_pendulum(EARTH)
    on_earth, earth_closed = small_angle_final_angle(earth, EARTH)
    moon = build_pendulum(MOON)
    on_moon, moon_closed = small_angle_final_angle(moon, MOON)
    np.testing.assert_allclose(on_earth, earth_closed, rtol=1e-6)
    np.testing.assert_allclose(on_moon, moon_closed, rtol=1e-6)


GRAVITY = 9.81  # an UPPER_CASE "constant" a user rebinds all the same


def constant_pendulum(q, qd):
    return 0.5 * qd**2 + GRAVITY * jnp.cos(q)


def test_a_rebound_upper_case_constant_is_part_of_the_identity_but_not_warned():
    global GRAVITY
    with warnings.catch_warnings():
        warnings.simplefilter("error", CapturedNumberWarning)  # not warned about
        earth = lj.Lagrangian(constant_pendulum)
        GRAVITY = MOON
        try:
            moon = lj.Lagrangian(constant_pendulum)
        finally:
            GRAVITY = EARTH
        again = lj.Lagrangian(constant_pendulum)
    assert earth != moon and earth == again
