"""Catalogue of bad or extreme input, round three (issue 33): refusals that name the
problem and a remedy the caller can apply, and extreme inputs that give the closed
form.

The default run holds the cases that refuse before anything compiles (and one
cheap closed form); the cases that compile a run are marked `integration`. Each
case asserts a message that names the problem (and the remedy), or the right
answer against a closed form.
"""

import math
import re
import warnings

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.cli import command as cli
from lagjax.cli import main
from lagjax.cli import run as cli_run
from lagjax.mechanics.captured_globals import CapturedNumberWarning, captured_numbers
from lagjax.scenes.pendulums import DoublePendulum, SimplePendulum
from tests.helpers import one_error_line

W = 1.5  # the oscillators' angular frequency (UPPER_CASE: a constant, not warned)


def oscillator(q, qd):
    return 0.5 * jnp.sum(qd**2) - 0.5 * W**2 * jnp.sum(q**2)


def oscillator_of_args(q, qd, t, args):
    return 0.5 * qd**2 - 0.5 * args * q**2


LAG = lj.Lagrangian(oscillator)
LAG_ARGS = lj.Lagrangian(oscillator_of_args)
HAM = lj.Hamiltonian(lambda q, p: 0.5 * jnp.sum(p**2) + 0.5 * W**2 * jnp.sum(q**2))
SEP = lj.SeparableHamiltonian(
    lambda p: 0.5 * jnp.sum(p**2), lambda q: 0.5 * W**2 * jnp.sum(q**2)
)
BODY = lj.RigidBody(jnp.array([1.0, 2.0, 3.0]))
F32 = (jnp.float32(1.0), jnp.float32(0.0))
EMPTY = (jnp.zeros(0), jnp.zeros(0))


def refused(name, call, error, pattern):
    return pytest.param(call, error, pattern, id=name)


# -- refused before compiling ------------------------------------------------------

STATE_REFUSALS = [
    refused("zero-length q, fixed step",
            lambda: lj.simulate(LAG, EMPTY, t1=1.0, dt=0.1),
            ValueError, r"q0 has no coordinates \(shape \(0,\)\).*at least one"),
    refused("zero-length q, adaptive",
            lambda: lj.simulate(LAG, EMPTY, t1=1.0),
            ValueError, r"q0 has no coordinates"),
    refused("q of shape (0, 3)",
            lambda: lj.simulate(LAG, (jnp.zeros((0, 3)),) * 2, t1=1.0, dt=0.1),
            ValueError, r"no coordinates \(shape \(0, 3\)\)"),
    refused("zero-length q of a Hamiltonian",
            lambda: lj.simulate(HAM, EMPTY, t1=1.0, dt=0.1),
            ValueError, r"q0 has no coordinates"),
    refused("a string in y0",
            lambda: lj.simulate(LAG, ("1", 0.0), t1=1.0, dt=0.1),
            TypeError, r"y0 must hold numbers, got str '1'.*float\(text\)"),
    refused("a dtype name in y0",
            lambda: lj.simulate(LAG, ("float32", 0.0), t1=1.0, dt=0.1),
            TypeError, r"y0 must hold numbers, got str 'float32'"),
    refused("an object in y0",
            lambda: lj.simulate(LAG, (object(), 0.0), t1=1.0, dt=0.1),
            TypeError, r"y0 must hold numbers, got object"),
    refused("q and qdot stacked in one array",
            lambda: lj.simulate(LAG, jnp.zeros((2, 3)), t1=1.0, dt=0.1),
            TypeError, r"y0 must be a pair.*shape \(2, 3\).*split it"),
]  # fmt: skip

ARGS_REFUSALS = [
    refused("NaN parameter",
            lambda: lj.simulate(LAG_ARGS, (1.0, 0.0), t1=1.0, dt=0.1, args=math.nan),
            ValueError, r"args contains NaN.*Pass finite parameters"),
    refused("NaN parameter, adaptive (was: 'raise max_steps')",
            lambda: lj.simulate(LAG_ARGS, (1.0, 0.0), t1=1.0, args=jnp.nan),
            ValueError, r"args contains NaN"),
    refused("NaN inside an args dict",
            lambda: lj.simulate(LAG_ARGS, (1.0, 0.0), t1=1.0, dt=0.1,
                                args={"k": jnp.array([1.0, jnp.nan])}),
            ValueError, r"args\['k'\] contains NaN"),
    refused("NaN inside an args list",
            lambda: lj.simulate(LAG_ARGS, (1.0, 0.0), t1=1.0, dt=0.1,
                                args=[math.nan]),
            ValueError, r"args\[0\] contains NaN"),
]  # fmt: skip

TIME_AND_TOLERANCE_REFUSALS = [
    refused("adaptive span far from t = 0 (was: 'raise max_steps')",
            lambda: lj.simulate(LAG, (1.0, 0.0), t0=1e15, t1=1e15 + 1.0),
            ValueError, r"only 8 ulps of t wide.*starts at 0"),
    refused("float32 at rtol 1e-12 (was: 'raise max_steps')",
            lambda: lj.simulate(LAG, F32, t1=1.0, rtol=1e-12, atol=1e-12),
            ValueError, r"below the resolution of float32.*rtol ≥ 1e-06.*float64"),
    refused("float64 at rtol 1e-20",
            lambda: lj.simulate(LAG, (1.0, 0.0), t1=1.0, rtol=1e-20, atol=1e-20),
            ValueError, r"below the resolution of float64"),
    refused("NaN rtol",
            lambda: lj.simulate(LAG, (1.0, 0.0), t1=1.0, rtol=math.nan),
            ValueError, r"rtol must be a finite non-negative number"),
    refused("negative atol",
            lambda: lj.simulate(LAG, (1.0, 0.0), t1=1.0, atol=-1e-8),
            ValueError, r"atol must be a finite non-negative number"),
    refused("rtol and atol both 0",
            lambda: lj.simulate(LAG, (1.0, 0.0), t1=1.0, rtol=0.0, atol=0.0),
            ValueError, r"both 0: no step could ever be accepted"),
    refused("subnormal span",
            lambda: lj.simulate(LAG, (1.0, 0.0), t1=1e-320, dt=1e-321),
            ValueError, r"below the smallest normal float"),
    refused("t1 < t0 with a positive dt",
            lambda: lj.simulate(LAG, (1.0, 0.0), t0=0.0, t1=-1.0, dt=0.01),
            ValueError, r"dt = 0.01 points away from t1 = -1.0.*same sign"),
]  # fmt: skip

MODE_REFUSALS = [
    refused("normal_modes of a Hamiltonian",
            lambda: lj.normal_modes(HAM, 0.0),
            TypeError, r"takes a lagjax Lagrangian.*got a Hamiltonian.*"
            r"ham\.to_lagrangian\(\)"),
    refused("normal_modes of a SeparableHamiltonian",
            lambda: lj.normal_modes(SEP, 0.0),
            TypeError, r"got a SeparableHamiltonian.*to_lagrangian\(\)"),
    refused("normal_modes of a rigid body",
            lambda: lj.normal_modes(BODY, jnp.array([1.0, 0.0, 0.0, 0.0])),
            TypeError, r"got a RigidBody.*lj\.linearize"),
    refused("normal_modes of a plain function",
            lambda: lj.normal_modes(oscillator, jnp.zeros(1)),
            TypeError, r"got a function: wrap the function: lj\.Lagrangian\(L\)"),
    refused("normal_modes of a scene of a Hamiltonian",
            lambda: lj.normal_modes(SimplePendulum(), 0.0),
            TypeError, r"SimplePendulum, whose system is a SeparableHamiltonian.*"
            r"scene\.system\(\)\.to_lagrangian\(\) with args=scene"),
    refused("normal_modes about zero coordinates",
            lambda: lj.normal_modes(LAG, jnp.zeros(0)),
            ValueError, r"q_eq has no coordinates"),
    refused("equilibrium of a Hamiltonian",
            lambda: lj.equilibrium(HAM, 0.1),
            TypeError, r"equilibrium takes a lagjax Lagrangian"),
]  # fmt: skip


@pytest.mark.parametrize(
    "call, error, pattern",
    STATE_REFUSALS + ARGS_REFUSALS + TIME_AND_TOLERANCE_REFUSALS + MODE_REFUSALS,
)
def test_refused_by_name_before_compiling(call, error, pattern):
    with pytest.raises(error, match=pattern):
        call()


@pytest.mark.parametrize(
    "transform", ["jvp", pytest.param("jacfwd", marks=pytest.mark.integration)]
)
def test_forward_mode_through_an_adaptive_run_names_the_adjoint(transform):
    def final_q(q0):
        return lj.simulate(LAG_ARGS, (q0, 0.0), t1=1.0, args=2.0).q[-1]

    differentiate = {
        "jacfwd": lambda: jax.jacfwd(final_q)(1.0),
        "jvp": lambda: jax.jvp(final_q, (1.0,), (1.0,)),
    }[transform]
    with pytest.raises(TypeError, match=r"adjoint=diffrax\.ForwardMode\(\)"):
        differentiate()


# -- module-level numbers frozen by compiling ----------------------------------------

g = 9.81  # lowercase on purpose: a number a user may rebind later
MOON = 1.62


def falls_with_g(q, qd):
    return 0.5 * qd**2 - g * q


def potential_with_g(q):
    return g * (1 - jnp.cos(q))


def through_a_helper(q, qd):
    return 0.5 * qd**2 - potential_with_g(q)


def constants_and_modules(q, qd):
    return 0.5 * qd**2 - MOON * jnp.cos(q) * math.pi + np.pi - jnp.sum(q)


@pytest.mark.parametrize("function", [falls_with_g, through_a_helper])
def test_a_module_level_number_read_by_l_warns(function):
    with pytest.warns(CapturedNumberWarning, match=r"reads the module-level number\(s\) "
                      r"g = 9.81.*rebinding g.*args"):  # fmt: skip
        lj.Lagrangian(function)


def test_modules_functions_and_constants_do_not_warn():
    with warnings.catch_warnings():
        warnings.simplefilter("error", CapturedNumberWarning)
        lj.Lagrangian(constants_and_modules)
        lj.Lagrangian(oscillator_of_args)
        lj.SeparableHamiltonian(lambda p: 0.5 * p**2, lambda q: W**2 * q**2 / 2)
    assert captured_numbers(constants_and_modules) == {}


def test_a_module_level_number_in_h_or_v_warns():
    with pytest.warns(CapturedNumberWarning, match=r"potential energy V reads.*g ="):
        lj.SeparableHamiltonian(lambda p: 0.5 * p**2, potential_with_g)
    with pytest.warns(CapturedNumberWarning, match=r"Hamiltonian H reads.*g ="):
        lj.Hamiltonian(lambda q, p: 0.5 * p**2 + g * q)


# -- extreme inputs that must give the closed form -----------------------------------


def test_free_fall_from_rest_at_zero_energy_is_not_a_divergence():
    # E0 = 0 and p0·q̇0 = 0: any round-off used to count as divergence (10²⁹³).
    free_fall = lj.Lagrangian(lambda q, qd: 0.5 * qd**2 + 9.81 * q)
    trajectory = lj.simulate(free_fall, (0.0, 0.0), t1=1.0, dt=0.01)
    np.testing.assert_allclose(trajectory.q[-1], 9.81 / 2, rtol=1e-12)
    assert float(trajectory.stats["energy_drift"]) < 1e-10


@pytest.mark.integration
def test_pendulum_let_go_where_its_energy_is_zero():
    # V = −cos q, released at q = π/2: E0 = 6e-17, and the run keeps the energy
    # (it was flagged as a divergence, drift 2e5).
    pendulum = lj.Lagrangian(lambda q, qd: 0.5 * qd**2 + jnp.cos(q))
    trajectory = lj.simulate(pendulum, (math.pi / 2, 0.0), t1=10.0, dt=0.01)
    assert trajectory.result == diffrax.RESULTS.successful
    energy = np.asarray(trajectory.energy())
    assert abs(energy[-1] - energy[0]) < 1e-9


@pytest.mark.integration
def test_normal_modes_of_a_scene_of_a_lagrangian():
    # Double pendulum, equal masses and lengths: ω² = (g/l)(2 ∓ √2).
    scene = DoublePendulum()
    omegas = lj.normal_modes(scene, jnp.zeros(2)).omegas
    expected = np.sqrt(9.81 * np.array([2 - math.sqrt(2), 2 + math.sqrt(2)]))
    np.testing.assert_allclose(omegas, expected, rtol=1e-12)


# The rest compile a run each.


@pytest.mark.integration
def test_normal_modes_of_a_hamiltonian_scene_through_its_lagrangian():
    scene = SimplePendulum()
    lagrangian = scene.system().to_lagrangian()
    omegas = lj.normal_modes(lagrangian, jnp.zeros(()), args=scene).omegas
    np.testing.assert_allclose(omegas, [math.sqrt(9.81 / 1.0)], rtol=1e-12)


def cosine(t):
    return math.cos(W * t)


@pytest.mark.integration
@pytest.mark.parametrize(
    "kwargs, times",
    [
        pytest.param(dict(t1=-1.0, dt=-0.01), [-1.0], id="backward, fixed step"),
        pytest.param(dict(t1=-1.0), [-1.0], id="backward, adaptive"),
        pytest.param(dict(t1=1.0, dt=0.01, ts=[0.5, 0.5, 1.0]), [0.5, 0.5, 1.0],
                     id="duplicate save times"),
        pytest.param(dict(t1=1.0, ts=[0.5, 0.5, 1.0]), [0.5, 0.5, 1.0],
                     id="duplicate save times, adaptive"),
        pytest.param(dict(t1=1.0, dt=0.01, ts=[0.0, 0.0]), [0.0, 0.0],
                     id="every save at t0"),
        pytest.param(dict(t1=2.0, dt=0.01, ts=[0, 1, 2]), [0.0, 1.0, 2.0],
                     id="integer save times"),
        pytest.param(dict(t1=1.0, dt=0.03), [1.0], id="dt not dividing the span"),
        pytest.param(dict(t0=5.0, t1=6.0, dt=0.01), [1.0], id="autonomous from t0=5"),
        pytest.param(dict(t1=1.0, dt=jnp.asarray(0.01)), [1.0], id="dt as an array"),
    ],
)  # fmt: skip
def test_extreme_times_give_the_closed_form(kwargs, times):
    # q = cos(W t) from (1, 0); a run from t0 = 5 is the same motion shifted.
    trajectory = lj.simulate(LAG, [1.0, 0.0], **kwargs)  # y0 as a list
    expected = [cosine(t) for t in times]
    np.testing.assert_allclose(trajectory.q, expected, rtol=2e-6, atol=1e-9)


@pytest.mark.integration
@pytest.mark.parametrize("amplitude", [1e200, 1e-200])
def test_huge_and_tiny_amplitudes_of_a_linear_system(amplitude):
    # The oscillator is linear: q = a cos(W t) at any amplitude float64 holds.
    trajectory = lj.simulate(LAG, (amplitude, 0.0), t1=1.0, dt=0.01)
    np.testing.assert_allclose(trajectory.q[-1] / amplitude, cosine(1.0), rtol=1e-8)


@pytest.mark.integration
def test_an_infinite_parameter_is_named_among_the_causes():
    with pytest.raises(
        Exception, match=r"non-finite state.*infinite parameter in args"
    ):
        lj.simulate(LAG_ARGS, (1.0, 0.0), t1=1.0, dt=0.1, args=math.inf)


@pytest.mark.integration
def test_forward_mode_with_the_named_adjoint_gives_the_closed_form():
    # ∂q(1)/∂q0 = cos(√k t) for the oscillator of stiffness k = 2.
    def final_q(q0):
        return lj.simulate(LAG_ARGS, (q0, 0.0), t1=1.0, args=2.0, rtol=1e-10,
                           atol=1e-10, adjoint=diffrax.ForwardMode()).q[-1]  # fmt: skip

    np.testing.assert_allclose(jax.jacfwd(final_q)(1.0), math.cos(math.sqrt(2.0)),
                               rtol=1e-7)  # fmt: skip


@pytest.mark.integration
def test_a_mass_matrix_vanishing_mid_run_is_not_told_to_raise_max_steps():
    # L = ½ q² q̇² from (1, −1): q² = 1 − 2t reaches the singular point at t = ½.
    vanishing = lj.Lagrangian(lambda q, qd: 0.5 * q**2 * qd**2)
    with pytest.raises(lj.SimulationError, match=r"stalled.*raising max_steps will "
                       r"not help.*singular") as failure:  # fmt: skip
        lj.simulate(vanishing, (1.0, -1.0), t1=1.0, max_steps=10_000)
    assert "raise max_steps" not in str(failure.value)
    reached = float(np.asarray(failure.value.trajectory.ts)[-1])
    np.testing.assert_allclose(reached, 0.5, atol=1e-6)


@pytest.mark.integration
def test_numbers_passed_as_args_follow_their_new_value():
    # The remedy the warning names: q = cos(√g t) on Earth, then on the Moon.
    finals = [
        float(lj.simulate(LAG_ARGS, (1.0, 0.0), t1=1.0, dt=0.01, args=gravity).q[-1])
        for gravity in (9.81, MOON)
    ]
    expected = [math.cos(math.sqrt(gravity)) for gravity in (9.81, MOON)]
    np.testing.assert_allclose(finals, expected, rtol=1e-7)


# -- the command ---------------------------------------------------------------------


PENDULUM = ["run", "simple-pendulum"]
COMMAND_REFUSALS = [
    ([*PENDULUM, "--save", "run.png", "--plot", "run.png"], "name the same file"),
    ([*PENDULUM, "--save", "a/../run.png", "--plot", "run.png"], "name the same file"),
    ([*PENDULUM, "--param", "mass=1e-300"], r"mass=1e-300: outside 1e-100\.\.1e\+100"),
    ([*PENDULUM, "--param", "mass=1e300"], r"outside 1e-100\.\.1e\+100"),
    (["run", "double-pendulum", "--param", "masses=1,1e-300"], "masses=1,1e-300"),
    ([*PENDULUM, "--param", "mass=1e-90", "--param", "length=1e-90"],
     r"energy scale at the start.*nearer 1"),
    ([*PENDULUM, "--param", "mass=1", "--param", "mass=2"], "given more than once"),
    ([*PENDULUM, "--t1", "1", "--dt", "5"], r"--dt 5 is longer than the run"),
    ([*PENDULUM, "--t1", "0.001"], r"the scene's step 0.01 is longer than the run"),
    ([*PENDULUM, "--t1", "1e-320", "--dt", "1e-321"], "below the smallest normal"),
]  # fmt: skip


@pytest.mark.parametrize("argv, message", COMMAND_REFUSALS)
def test_command_refuses_before_running(argv, message, capsys, tmp_path, monkeypatch):
    (tmp_path / "a").mkdir()
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    line = one_error_line(capsys)
    assert line.startswith("lagjax: error: ")
    assert re.search(message, line), line
    assert not (tmp_path / "run.png").exists()


@pytest.mark.parametrize("t1, dt", [(1e-6, 1e-9), (-1e-6, -1e-9), (10.0, 0.01),
                                    (1.0, 0.3)])  # fmt: skip
def test_the_command_save_grid_ends_exactly_at_t1(t1, dt):
    # 1000 · 1e-9 = 1.0000000000000002e-6: one ulp past t1, refused by simulate.
    times = cli_run._save_times(t1, dt, 0.01, cli_run.MAX_SAVED_POINTS)
    assert times[0] == 0.0 and times[-1] == t1
    assert np.all(np.abs(times) <= abs(t1))
    assert np.all(np.diff(times) * np.sign(t1) > 0)


def test_library_only_remedies_are_left_out_of_the_command():
    text = (
        "The run diverged: the energy changed. Reduce dt. simulate(..., "
        "throw=False) returns the run instead of raising, with the ratio in "
        "stats['energy_drift']."
    )
    assert (
        cli._command_remedies(text)
        == "The run diverged: the energy changed. Reduce dt."
    )


@pytest.mark.integration
def test_command_save_grid_one_ulp_past_t1_runs(tmp_path, capsys):
    path = tmp_path / "short.npz"
    assert main([*PENDULUM, "--t1", "1e-6", "--dt", "1e-9", "--save", str(path)]) == 0
    assert np.load(path)["ts"][-1] == 1e-6


@pytest.mark.integration
def test_command_backward_run_says_so_and_saves_negative_times(tmp_path, capsys):
    path = tmp_path / "back.npz"
    assert main([*PENDULUM, "--t1", "2", "--backward", "--save", str(path)]) == 0
    assert "backward from t = 0 to -2" in capsys.readouterr().out
    ts = np.load(path)["ts"]
    assert ts[-1] == -2.0 and np.all(np.diff(ts) < 0)


@pytest.mark.integration
def test_command_does_not_call_a_driven_energy_an_error(capsys):
    assert main(["run", "damped-driven-oscillator", "--t1", "5"]) == 0
    out = capsys.readouterr().out
    assert "energy    not conserved by this scene" in out
    assert "max relative error" not in out


@pytest.mark.integration
def test_command_free_fall_from_rest_at_zero_energy_runs(capsys):
    # Was: "run failed: The run diverged" (E0 = 0, p0·q̇0 = 0).
    argv = ["run", "free-fall", "--param", "initial_velocity=0", "--t1", "1"]
    assert main(argv) == 0
    assert "energy    max relative error" in capsys.readouterr().out
