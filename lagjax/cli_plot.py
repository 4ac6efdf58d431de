"""The figure of `lagjax run --plot`: the motion, the energy, and the scene's check.

Three panels that read like a lab notebook:

1. the coordinates against time — the whole run when it holds few swings, else
   its first swings (a long run drawn whole is a solid band);
2. the relative energy error |E − E₀|/|E₀| on a log scale, over the whole run;
3. where the scene has closed-form checks (`scene.checks(trajectory)`), each
   scalar check measured on each sixth of the run against its closed form: e.g.
   the Foucault pendulum's precession rate fitted on each part against
   −ω_E sin φ, the pendulum's period, the eastward deflection at the end of each
   part against ⅓ω_E g t³ cos φ — a drift along the run shows at a glance.

matplotlib is imported here only, so the command runs without it unless a plot is
asked for.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import numpy as np
from jax.flatten_util import ravel_pytree

# The run is cut into this many equal parts, and each scalar check measured on each.
_SEGMENTS = 6
_MAX_SWINGS_SHOWN = 12


def plot_run(path: str, name: str, scene: Any, trajectory: Any) -> None:
    """Write the figure of one trajectory of `scene` to `path` (format by suffix)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ts = np.asarray(trajectory.ts)
    flat_q = np.asarray(jax.vmap(lambda q: ravel_pytree(q)[0])(trajectory.q))
    checks = _check_series(scene, trajectory)
    rows = 3 if checks else 2
    figure, axes = plt.subplots(rows, 1, figsize=(8, 2.6 * rows + 0.6))
    _plot_coordinates(axes[0], ts, flat_q)
    axes[0].set_title(f"lagjax run {name}")
    _plot_energy(axes[1], ts, np.asarray(trajectory.energy()))
    if checks:
        _plot_checks(axes[2], checks)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def _plot_coordinates(axis, ts: np.ndarray, flat_q: np.ndarray) -> None:
    shown = _first_swings(ts, flat_q)
    for index in range(flat_q.shape[1]):
        axis.plot(ts[:shown], flat_q[:shown, index], label=f"q[{index}]")
    if flat_q.shape[1] <= 8:
        axis.legend(loc="upper right", fontsize="small")
    axis.set_ylabel("coordinates q (scene units)")
    span = "whole run" if shown == ts.size else f"first {shown} of {ts.size} saves"
    axis.set_xlabel(f"t [s]  ({span})")


def _first_swings(ts: np.ndarray, flat_q: np.ndarray) -> int:
    """How many saved points to draw so that at most ~12 swings show.

    A swing is counted at each sign change of a coordinate about its mean; a run
    with fewer swings (or none, a fall) is drawn whole.
    """
    centred = flat_q - flat_q.mean(axis=0)
    crossings = np.nonzero(np.any(np.diff(np.sign(centred), axis=0) != 0, axis=1))[0]
    limit = 2 * _MAX_SWINGS_SHOWN
    if crossings.size <= limit:
        return ts.size
    return int(crossings[limit]) + 1


def _plot_energy(axis, ts: np.ndarray, energy: np.ndarray) -> None:
    scale = max(abs(float(energy[0])), 1e-300)
    error = np.abs(energy[1:] - energy[0]) / scale + 1e-17
    axis.semilogy(ts[1:], error)
    axis.set_xlabel("t [s]")
    axis.set_ylabel("|E − E₀| / |E₀|")


def _check_series(scene: Any, trajectory: Any) -> dict[str, tuple]:
    """{check: (segment ends, measured, expected)} on `_SEGMENTS` equal parts.

    Equal parts have one shape, so the check compiles once (growing windows
    compiled anew for each length: 20 s a window on the pendulum).
    """
    size = int(np.asarray(trajectory.ts).size)
    length = size // _SEGMENTS
    series: dict[str, tuple[list, list, list]] = {}
    if length < 3:
        return {}
    for start in range(0, length * _SEGMENTS, length):
        part = slice(start, start + length)
        window = eqx.tree_at(
            lambda t: (t.ts, t.ys),
            trajectory,
            (
                trajectory.ts[part],
                jax.tree_util.tree_map(lambda x, p=part: x[p], trajectory.ys),
            ),
        )
        try:
            checks = scene.checks(window)
        except ValueError:  # a window too short to judge: no point for it
            continue
        for check, (measured, expected) in checks.items():
            measured, expected = np.asarray(measured), np.asarray(expected)
            if measured.size != 1 or expected.size != 1:
                continue  # a vector check has no single curve to draw
            times, values, closed = series.setdefault(check, ([], [], []))
            times.append(float(trajectory.ts[start + length - 1]))
            values.append(float(measured))
            closed.append(float(expected))
    return {key: tuple(np.asarray(v) for v in value) for key, value in series.items()}


def _plot_checks(axis, checks: dict[str, tuple]) -> None:
    for index, (check, (times, measured, expected)) in enumerate(checks.items()):
        colour = f"C{index}"
        axis.plot(times, measured, "o-", color=colour, ms=3, label=f"{check}: measured")
        axis.plot(times, expected, "--", color=colour, label=f"{check}: closed form")
    axis.set_xlabel(f"end of each 1/{_SEGMENTS} of the run, t [s]")
    axis.set_ylabel("check on that part")
    axis.legend(loc="best", fontsize="small")
