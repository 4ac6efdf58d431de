"""Scenes name their coordinates and units and, where they have one, a diagnostic
curve; `lagjax run --plot` draws both and saves each swing densely enough to see it.

Fast: one short harmonic-oscillator run; the Foucault diagnostic is measured on the
exact solution of the linearised Foucault equation instead of a run.
"""

from typing import ClassVar

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import matplotlib
import numpy as np
import pytest
from jax.flatten_util import ravel_pytree

import lagjax as lj
import lagjax.scenes as scenes
from lagjax.cli import main
from lagjax.cli.plot import run_figure, unit_groups
from lagjax.cli.run import MAX_SAVED_POINTS, _save_times
from lagjax.scenes.base import AbstractScene, StateKind

matplotlib.use("Agg")
import matplotlib.pyplot as plt

SCENE_CLASSES = list(scenes.catalog().values())


@pytest.mark.parametrize("scene_class", SCENE_CLASSES, ids=lambda c: c.__name__)
def test_every_scene_names_its_coordinates_and_units(scene_class):
    scene = scene_class()
    names, units = scene.coordinates()
    size = ravel_pytree(scene.initial_state()[0])[0].size
    assert len(names) == len(units) == size
    assert len(set(names)) == size and not any(n.startswith("q[") for n in names)
    assert set(units) <= {"m", "rad", ""}  # SI; "" for the dimensionless FPU chain
    assert not any("\\" in text or "$" in text for text in (*names, *units))
    assert scene_class.time_unit in {"s", ""}


def test_scenes_of_any_size_name_every_coordinate():
    chain = scenes.SpringChain(size=12).coordinates()
    assert chain[0][-1] == "q₁₂" and chain[1] == ("m",) * 12
    assert len(scenes.FermiPastaUlamChain(pairs=5).coordinates()[0]) == 10
    pair = scenes.CoupledOscillators(masses=(1.0, 2.0), stiffness=(1.0, 3.0))
    assert pair.coordinates() == (("q₁", "q₂"), ("m", "m"))


def _kinetic(p, t, scene):
    return 0.5 * jnp.sum(p**2)


class MisdeclaredScene(AbstractScene):
    """Two coordinates, one declared name."""

    default_t1: ClassVar[float] = 1.0
    default_dt: ClassVar[float] = 0.1
    state_kind: ClassVar[StateKind] = "momentum"
    coordinate_names: ClassVar[tuple[str, ...]] = ("x",)

    def system(self):
        return lj.SeparableHamiltonian(_kinetic, _kinetic)

    def initial_state(self):
        return jnp.zeros(2), jnp.zeros(2)


def test_a_declaration_of_the_wrong_length_is_refused():
    with pytest.raises(ValueError, match="has 2 coordinates but declares 1 names"):
        MisdeclaredScene().coordinates()


def test_coordinates_share_a_panel_only_with_their_own_unit():
    groups = unit_groups(*scenes.RollingDisk().coordinates())
    assert groups == {"m": [(0, "x"), (1, "y")], "rad": [(2, "θ"), (3, "φ"), (4, "ψ")]}


class LinearFoucault(eqx.Module):
    r"""The exact path of the linearised Foucault pendulum, released at rest at a.

    $\ddot w + 2i\Omega_z\dot w + \omega_0^2 w = 0$, $w = x + iy$ (south, east),
    $\Omega_z = \omega_E\sin\varphi$: $w = a e^{-i\Omega_z t}(\cos\omega' t +
    i(\Omega_z/\omega')\sin\omega' t)$, $\omega'^2 = \omega_0^2 + \Omega_z^2$ — the
    swing plane turns at exactly $-\Omega_z$ (Landau & Lifshitz §39 prob. 3).
    """

    ts: jax.Array
    ys: tuple

    @property
    def q(self):
        return self.ys[0]

    @property
    def qdot(self):
        return self.ys[1]

    def energy(self):
        return 0.5 * jnp.sum(self.qdot**2 + self.q**2, axis=-1)


def linear_foucault(scene, ts) -> LinearFoucault:
    omega0 = jnp.sqrt(scene.gravity / scene.length)
    turn = scene.earth_rate * jnp.sin(scene.latitude)
    swing = jnp.sqrt(omega0**2 + turn**2)

    def position(t):
        w = scene.amplitude * jnp.exp(-1j * turn * t)
        w = w * (jnp.cos(swing * t) + 1j * turn / swing * jnp.sin(swing * t))
        return jnp.stack([w.real, w.imag])

    q = jax.vmap(position)(ts)
    qdot = jax.vmap(jax.jacfwd(position))(ts)
    return LinearFoucault(ts, (q, qdot))


@pytest.mark.parametrize("latitude", [np.pi / 4, -np.pi / 3, 0.1])
def test_foucault_diagnostic_is_the_plane_turning_at_minus_omega_sin_latitude(
    latitude,
):
    # A fast Earth (ω_E = 0.01 rad/s, g/l = 1 s⁻²): the plane turns 1.5 rad·sin φ
    # in the run, well above the residual wobble ½ω_E sin φ/√(g/l) of the measure.
    scene = scenes.FoucaultPendulum(latitude=latitude, earth_rate=0.01)
    ts = jnp.linspace(0.0, 150.0, 3001)
    curve = scene.diagnostic(linear_foucault(scene, ts))
    assert curve is not None and curve.expected is not None
    rate = -0.01 * np.sin(latitude)
    assert np.allclose(curve.expected[1:] / ts[1:], rate, rtol=1e-14, atol=0)
    wobble = 0.5 * 0.01 * abs(np.sin(latitude))  # the measure's residual, rad
    assert np.max(np.abs(curve.measured - curve.expected)) < 1.1 * wobble
    slope = np.polyfit(np.asarray(ts), np.asarray(curve.measured), 1)[0]
    assert abs(slope / rate - 1) < 1e-3


def _texts(figure) -> list[str]:
    texts = []
    for axis in figure.axes:
        texts += [axis.get_xlabel(), axis.get_ylabel(), axis.get_title()]
        legend = axis.get_legend()
        texts += [t.get_text() for t in legend.get_texts()] if legend else []
    return texts


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_the_foucault_figure_has_named_axes_and_the_plane_against_its_rate():
    scene = scenes.FoucaultPendulum(earth_rate=0.01)
    path = linear_foucault(scene, jnp.linspace(0.0, 150.0, 3001))
    # The figure reads a trajectory's system and args (its energy panel's scale).
    system, args = scene.resolve(None)
    exact = lj.Trajectory(
        ts=path.ts, ys=path.ys, system=system, args=args, run_stats={},
        result=diffrax.RESULTS.successful, solver_name="exact (linearised)",
    )  # fmt: skip
    figure = run_figure("foucault-pendulum", scene, exact)
    texts = _texts(figure)
    plt.close(figure)
    assert "x (south), y (east) [m]" in texts
    assert "swing-plane angle θ(t) − θ(0) [rad]" in texts
    assert "−ω_E sin φ · t" in texts and "|E − E₀| / (|E₀| + |p₀·q̇₀|)" in texts
    assert any(text.startswith("t [s]") for text in texts)
    assert "precession rate" in texts  # the check, measured on each sixth


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_run_writes_the_plot_and_saves_every_step_of_a_default_run(tmp_path, capsys):
    plot, data = tmp_path / "run.png", tmp_path / "run.npz"
    argv = ["run", "harmonic-oscillator", "--t1", "2"]
    assert main([*argv, "--plot", str(plot), "--save", str(data)]) == 0
    assert f"plot      {plot}" in capsys.readouterr().out
    height, width, _ = matplotlib.image.imread(plot).shape
    assert width == 960 and height > 500  # 8 inches at 120 dpi, panels stacked
    assert np.allclose(np.diff(np.load(data)["ts"]), 0.01)  # the default step


@pytest.mark.parametrize(
    "scene, period",
    [
        (scenes.HarmonicOscillator(), scenes.HarmonicOscillator().period()),
        (scenes.SimplePendulum(), scenes.SimplePendulum().period()),
        (scenes.KeplerCartesian(), scenes.KeplerCartesian().period()),
        (scenes.FoucaultPendulum(), 2 * np.pi * np.sqrt(9.81 / 9.81)),
    ],
    ids=["oscillator", "pendulum", "kepler", "foucault"],
)
def test_default_runs_save_twenty_points_a_swing(scene, period):
    t1, dt = scene.default_t1, scene.default_dt
    times = _save_times(t1, dt, scene.default_dt, MAX_SAVED_POINTS)
    assert times[0] == 0 and np.isclose(times[-1], t1)
    assert np.max(np.diff(times)) <= float(period) / 20


def test_save_times_follow_the_scene_scale_on_the_grid_up_to_the_cap():
    finer = _save_times(5.0, 0.001, 0.01, MAX_SAVED_POINTS)  # --dt below the scale
    assert finer.size == 501 and np.allclose(np.diff(finer), 0.01)
    long = _save_times(1e3, 1e-3, 1e-3, MAX_SAVED_POINTS)  # 10⁶ steps
    assert long.size <= MAX_SAVED_POINTS
    steps = long / 1e-3
    assert np.allclose(steps, np.round(steps))  # on the step grid
