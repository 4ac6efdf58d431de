"""Tables, verdicts and the figure of `rigid_long_horizon.py`.

Reads the measured points (one dict per method and setting) and writes the
Markdown summary — who reaches each error level first, whether the Lie–Poisson
splitting beats Dopri8, the hand-written-twin overhead — the CSV, the JSON and the
two-panel work-precision PNG.

References: Hairer, Nørsett & Wanner, *Solving ODEs I*, 2nd ed., §II.10
(work-precision diagrams).
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from matplotlib.ticker import NullFormatter

from benchmarks import palette
from lagjax import diagnostics

LIE_POISSON = "Lie–Poisson"
ERROR_LEVELS = (1e-3, 1e-6, 1e-9, 1e-12)
QUANTITIES = dict(  # column: its name in the summary, | escaped for Markdown tables
    momentum_error="\\|L\\| error",
    energy_error="energy error",
    final_error="final-state error",
)
TIE = 1.3  # run-time ratios closer to 1 than this are within the timing noise


def fastest(records: list[dict], quantity: str, level: float, family=None):
    """The fastest point (of `family`, or any) whose `quantity` is within `level`."""
    points = [
        diagnostics.WorkPrecisionPoint(r["method"], r["value"], r["run_s"], r[quantity])
        for r in records
        if family is None or r["family"] == family
    ]
    return diagnostics.fastest_within(points, level)


def fastest_table(records: list[dict], floor: float) -> tuple[list[str], list[dict]]:
    """Markdown lines and JSON rows: per quantity and level, who got there first.

    Final-state levels under the reference's floor cannot be judged, so are left out.
    """
    lines = [
        "| quantity | level | fastest | fastest Lie–Poisson | fastest Dopri8 "
        "| Lie–Poisson / Dopri8 time |",
        "|---|---|---|---|---|---|",
    ]
    rows = []
    for quantity, name in QUANTITIES.items():
        for level in ERROR_LEVELS:
            if quantity == "final_error" and level < floor:
                continue
            best, ours, dopri = (
                fastest(records, quantity, level, family)
                for family in (None, LIE_POISSON, "Dopri8")
            )
            ratio = ours.run_seconds / dopri.run_seconds if ours and dopri else math.nan
            cells = [
                "—" if p is None else f"{p.method} ({p.setting:.3g}): "
                f"{p.run_seconds * 1e3:.3g} ms" for p in (best, ours, dopri)
            ]  # fmt: skip
            row = f"| {name} | {level:.0e} | {' | '.join(cells)} | {ratio:.2g} |"
            lines.append(row)
            rows.append(dict(quantity=quantity, level=level, ratio=ratio, **{
                key: p and p._asdict() for key, p in
                (("fastest", best), ("lie_poisson", ours), ("dopri8", dopri))}))  # fmt: skip
    return lines, rows


def _comparison(row: dict) -> str | None:
    """The fastest Lie–Poisson run against the fastest Dopri8 run at one level.

    Within TIE of each other they count as tied: the machine is shared, and
    repeated runs moved the timings by about that much.
    """
    ours, dopri, ratio = row["lie_poisson"], row["dopri8"], row["ratio"]
    if ours and dopri and ratio < 1 / TIE:
        return "faster than Dopri8 at"
    if ours and dopri:
        return "slower at" if ratio > TIE else f"tied (within {TIE}×) at"
    if ours or dopri:
        return "the only one to reach" if ours else "not reaching (Dopri8 does)"
    return None


def verdict(rows: list[dict]) -> list[str]:
    """Where the issue's claim (Lie–Poisson faster than Dopri8) holds, by quantity."""
    lines = []
    for quantity, name in QUANTITIES.items():
        groups: dict[str, list[str]] = {}
        for row in (r for r in rows if r["quantity"] == quantity):
            if key := _comparison(row):
                groups.setdefault(key, []).append(f"{row['level']:.0e}")
        found = "; ".join(
            f"{key} {', '.join(levels)}" for key, levels in groups.items()
        )
        lines.append(f"- **{name}**: Lie–Poisson {found or 'no data'}.")
    return lines


def point_table(records: list[dict]) -> list[str]:
    head = "| method | setting | steps | run [ms] | compile [s] | max \\|L\\| err "
    lines = [head + "| max L (space) err | max energy err | ‖RᵀR − I‖ | final err |",
             "|---|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    errors = ("momentum_error", "space_momentum_error", "energy_error",
              "orthonormality", "final_error")  # fmt: skip
    for r in records:
        cells = [r["method"], f"{r['parameter']} = {r['value']:.3g}", str(r["steps"]),
                 f"{r['run_s'] * 1e3:.3g}", f"{r['compile_s']:.2f}",
                 *(f"{r[key]:.1e}" for key in errors)]  # fmt: skip
        lines.append(f"| {' | '.join(cells)} |")
    return lines


def plot(records: list[dict], title: str, path: Path, caption: str = "") -> None:
    """Two panels, log-log: max |L| error and max energy error against run time, in
    the colours of `benchmarks.palette`; `caption` (the date, the clock) below."""
    figure, axes = plt.subplots(1, 2, figsize=(13, 5.2), constrained_layout=True)
    panels = (("momentum_error", "max |L| error along the run (relative, no unit)"),
              ("energy_error", "max energy error along the run (relative, no unit)"))  # fmt: skip
    for ax, (quantity, ylabel) in zip(axes, panels):
        for method in dict.fromkeys(r["method"] for r in records):
            rows = sorted((r for r in records if r["method"] == method),
                          key=lambda r: r["run_s"])  # fmt: skip
            # An exact zero (no round-off at all) is drawn at 1e-17, below the rest.
            errors = [max(r[quantity], 1e-17) for r in rows]
            ax.loglog([r["run_s"] for r in rows], errors, label=method, ms=4,
                      **palette.style(method))  # fmt: skip
        ax.set(
            xlabel="run time [s] (median of warm runs, compile excluded)", ylabel=ylabel
        )
        ax.grid(True, which="major", alpha=0.3)
        ax.xaxis.set_minor_formatter(NullFormatter())  # labels 2×10⁻² … overlap
    axes[0].legend(fontsize=8, loc="best")
    figure.suptitle(title)
    if caption:
        figure.supxlabel(caption, fontsize=7, color="0.3")
    figure.savefig(path, dpi=120)
    plt.close(figure)


def records_from_markdown(text: str) -> list[dict]:
    """The points of a written report, from its "Every point" table.

    Enough to redraw the figure (method, family, run time, |L| and energy errors)
    without measuring again; values carry the table's three significant digits.
    """
    table = text.split("## Every point", 1)[1].strip().splitlines()[2:]
    records = []
    for row in table:
        cells = [cell.strip() for cell in row.strip().strip("|").split(" | ")]
        method, setting = cells[0], cells[1]
        parameter, _, value = setting.partition(" = ")
        family = (
            LIE_POISSON if method.startswith("RigidBody") else method.split("(")[1][:-1]
        )
        records.append(dict(
            method=method, family=family, parameter=parameter, value=float(value),
            steps=int(cells[2]), run_s=float(cells[3]) / 1e3,
            compile_s=float(cells[4]), momentum_error=float(cells[5]),
            space_momentum_error=float(cells[6]), energy_error=float(cells[7]),
            orthonormality=float(cells[8]), final_error=float(cells[9]),
        ))  # fmt: skip
    return records


def write(out: Path, records, meta, twin) -> None:
    lines, rows = fastest_table(records, meta["reference_floor"])
    twin_lines = [
        f"- RigidBodyVerlet({label}): lj.simulate {twin[key]['lagjax_s'] * 1e3:.3g} "
        f"ms, twin {twin['twin_s'] * 1e3:.3g} ms, ratio **{twin[key]['ratio']:.2f}×** "
        f"(final states differ by {twin[key]['final_difference']:.0e})"
        for key, label in (("plain", "compensated=False"), ("compensated", ""))
    ]
    sections = [
        [f"# {meta['title']}"],
        [f"Mode {meta['mode']}; {meta['device']}; jax {meta['jax']}. Run time: median "
         "of warm runs, compile excluded. Errors: relative, the maximum over every "
         "step of the run; the final (R, ω) against Dopri8 at rtol 1e-14 (floor "
         f"{meta['reference_floor']:.0e}). The machine was shared with other runs: "
         f"read the run times as ratios, and ratios within {TIE}× as ties."],
        ["## Who reaches each error level first"], lines,
        ["## Does the Lie–Poisson splitting beat Dopri8?"], verdict(rows),
        [f"## Overhead against a hand-written twin ({twin['steps']} RigidBodyVerlet "
         f"steps, h = {twin['h']}, as a plain lax.scan)"], twin_lines,
        ["## Every point"], point_table(records),
    ]  # fmt: skip
    text = "\n\n".join("\n".join(section) for section in sections) + "\n"
    (out / "rigid_long_horizon.md").write_text(text)
    with open(out / "rigid_long_horizon.csv", "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(records[0]))
        writer.writeheader()
        writer.writerows(records)
    report = dict(meta=meta, points=records, fastest=rows, twin=twin)
    (out / "rigid_long_horizon.json").write_text(json.dumps(report, indent=1))
    caption = (
        f"{meta['mode']} run, {meta['device']}, jax {meta['jax']}; run time = "
        "wall-clock time"
    )
    plot(records, meta["title"], out / "rigid_long_horizon.png", caption)
