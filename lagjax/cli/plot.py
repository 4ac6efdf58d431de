"""The figure of `lagjax run --plot`: the motion, the scene's physics, the energy.

Panels that read like a lab notebook, top to bottom:

1. the coordinates against time, named and in their units as the scene declares
   them (`AbstractScene.coordinates()`: θ [rad], x [m], …), one panel per unit —
   the whole run when it holds few swings, else its first swings (a long run drawn
   whole is a solid band);
2. the scene's own diagnostic where it has one (`scene.diagnostic(trajectory)`):
   e.g. the Foucault pendulum's swing-plane angle against −ω_E sin φ · t, Kepler's
   angular momentum against its constant, the eastward drift against
   ⅓ ω_E g t³ cos φ;
3. the relative energy change |E − E₀|/(|E₀| + |p₀·q̇₀|) on a log scale over the
   whole run —
   the integration error where the energy is conserved (left out for a scene
   with forces, friction or constraints whose diagnostic shows its physics);
4. where the scene has scalar closed-form checks (`scene.checks(trajectory)`), each
   one measured on each sixth of the run against its closed form: the Foucault
   precession rate, the pendulum's period, … — a drift along the run shows at a
   glance.

matplotlib is imported here only, so the command runs without it unless a plot is
asked for.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import numpy as np
from jax.flatten_util import ravel_pytree

from lagjax.cli.run import energy_report

# The run is cut into this many equal parts, and each scalar check measured on each.
_SEGMENTS = 6
_MAX_SWINGS_SHOWN = 12
_PANEL_HEIGHT = 2.4  # inches


def plot_run(path: str, name: str, scene: Any, trajectory: Any) -> None:
    """Write the figure of one trajectory of `scene` to `path` (format by suffix)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure = run_figure(name, scene, trajectory)
    figure.savefig(path, dpi=120)
    plt.close(figure)


def run_figure(name: str, scene: Any, trajectory: Any) -> Any:
    """The figure of one trajectory (a matplotlib `Figure`; the caller closes it)."""
    import matplotlib.pyplot as plt

    ts = np.asarray(trajectory.ts)
    flat_q = np.asarray(jax.vmap(lambda q: ravel_pytree(q)[0])(trajectory.q))
    groups = unit_groups(*scene.coordinates())
    diagnostic = scene.diagnostic(trajectory)
    checks = _check_series(scene, trajectory)
    # The energy error where the energy is conserved, or where the scene has no
    # curve of its own to show; not the decay of a damped run beside its closed form.
    energy = diagnostic is None or scene.conserves_energy_if_autonomous()
    rows = len(groups) + (diagnostic is not None) + energy + bool(checks)
    figure, axes = plt.subplots(
        rows, 1, figsize=(8, _PANEL_HEIGHT * rows + 0.6), squeeze=False
    )
    panels = iter(axes[:, 0])
    time_label = _with_unit("t", scene.time_unit)
    shown = _first_swings(ts, flat_q)
    for unit, members in groups.items():
        axis = next(panels)
        _plot_coordinates(axis, ts[:shown], flat_q[:shown], members, unit)
        span = "whole run" if shown == ts.size else f"first {shown} of {ts.size} saves"
        axis.set_xlabel(f"{time_label}  ({span})")
    summary = (type(scene).__doc__ or "").strip().splitlines()[0]
    axes[0, 0].set_title(f"lagjax run {name}\n{summary}", fontsize="medium")
    if diagnostic is not None:
        _plot_diagnostic(next(panels), diagnostic, time_label)
    if energy:
        scale = energy_report(trajectory).scale
        _plot_energy(
            next(panels), ts, np.asarray(trajectory.energy()), scale, time_label
        )
    if checks:
        _plot_checks(next(panels), checks, time_label)
    figure.tight_layout()
    return figure


def unit_groups(
    names: tuple[str, ...], units: tuple[str, ...]
) -> dict[str, list[tuple[int, str]]]:
    """{unit: [(index in q flattened, name), …]}: coordinates that share an axis.

    Lengths and angles on one axis would squash one of them flat; each unit gets a
    panel of its own, in the order the units first appear.
    """
    groups: dict[str, list[tuple[int, str]]] = {}
    for index, (name, unit) in enumerate(zip(names, units, strict=True)):
        groups.setdefault(unit, []).append((index, name))
    return groups


def _with_unit(label: str, unit: str) -> str:
    return f"{label} [{unit}]" if unit else label


def _plot_coordinates(axis, ts, flat_q, members, unit: str) -> None:
    for index, name in members:
        axis.plot(ts, flat_q[:, index], label=name)
    if len(members) <= 8:
        axis.legend(loc="upper right", fontsize="small")
    names = ", ".join(name for _, name in members)
    shown = names if len(members) <= 4 else "coordinates"
    axis.set_ylabel(_with_unit(shown, unit))


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


def _plot_diagnostic(axis, diagnostic, time_label: str) -> None:
    ts, measured = np.asarray(diagnostic.ts), np.asarray(diagnostic.measured)
    # The two curves usually lie on top of each other: the legend gives the gap.
    label = "measured"
    if diagnostic.expected is not None:
        expected = np.asarray(diagnostic.expected)
        label += f" (max |measured − closed form| = {np.max(np.abs(measured - expected)):.2g})"
    axis.plot(ts, measured, label=label)
    if diagnostic.expected is not None:
        axis.plot(ts, expected, "--", color="k", lw=1, label=diagnostic.expected_label)
    axis.legend(loc="best", fontsize="small")
    # The label names the quantity and ends with its unit, "… [rad]": the whole of
    # it as the panel's title, the unit on the axis.
    _, bracket, unit = diagnostic.label.rpartition(" [")
    axis.set_ylabel(f"[{unit}" if bracket else "")
    axis.set_title(diagnostic.label, fontsize="small")
    axis.set_xlabel(time_label)


def _plot_energy(
    axis, ts: np.ndarray, energy: np.ndarray, scale: float, time_label: str
) -> None:
    """The change at each save relative to the energy scale |E₀| + |p₀·q̇₀| (which
    stays meaningful where E₀ = 0), and its running maximum: a plateau is a
    bounded error (a symplectic solver's), a rising line a drift."""
    scale = max(scale, 1e-300)
    # Round-off: a change below half an ulp of E₀ is drawn on that floor, not at 0.
    floor = np.finfo(energy.dtype).eps / 2
    error = np.maximum(np.abs(energy[1:] - energy[0]) / scale, floor)
    axis.semilogy(ts[1:], error, lw=0.6, alpha=0.5, label="at each save")
    axis.semilogy(ts[1:], np.maximum.accumulate(error), lw=1.5, label="largest so far")
    axis.legend(loc="lower right", fontsize="small")
    axis.set_xlabel(time_label)
    axis.set_ylabel("|E − E₀| / (|E₀| + |p₀·q̇₀|)")
    axis.set_title(
        "energy: relative change (the integration error where E is conserved)",
        fontsize="small",
    )


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


def _plot_checks(axis, checks: dict[str, tuple], time_label: str) -> None:
    """Each check's relative deviation from its closed form, part by part: one
    scale for checks of different units, and no offset notation for values that
    agree to many digits."""
    for check, (times, measured, expected) in checks.items():
        scale = np.maximum(np.abs(expected), 1e-300)
        axis.plot(times, (measured - expected) / scale, "o-", ms=3, label=check)
    axis.axhline(0.0, color="k", lw=0.8, ls="--")
    axis.set_xlabel(f"end of each 1/{_SEGMENTS} of the run, {time_label}")
    axis.set_ylabel("(measured − closed form)\n/ |closed form|", fontsize="small")
    axis.set_title("the scene's checks, each measured on each part", fontsize="small")
    axis.legend(loc="best", fontsize="small")
