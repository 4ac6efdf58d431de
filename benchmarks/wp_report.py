"""Writing the work-precision report: the CSV, the JSON, the diagrams, the summary.

`summary.md` names, per scene and error level, the fastest run — overall, lagjax's
and the peers' — and, for the same method at the same tolerance, the median run-time
ratio of each peer to lagjax. Levels finer than ten times a reference's floor are
left out: the reference cannot judge them.

References: Hairer, Nørsett & Wanner, *Solving Ordinary Differential Equations I*,
2nd ed., §II.10 (work-precision diagrams).
"""

from __future__ import annotations

import csv
import json
import math
import platform
import time
from pathlib import Path

import jax
import matplotlib

matplotlib.use("Agg")  # files only, no display
import matplotlib.pyplot as plt
from matplotlib.ticker import NullFormatter

from benchmarks import palette
from lagjax import diagnostics

ERROR_LEVELS = (1e-3, 1e-6, 1e-9)

# (lagjax method, peer method) run at the same tolerances: same algorithm or tableau.
TWINS = (
    ("lagjax Tsit5", "diffrax Tsit5 (hand-written)"),
    ("lagjax Dopri8", "diffrax Dopri8 (hand-written)"),
    ("lagjax Dopri8", "scipy DOP853 (hand-written numpy)"),
    ("lagjax Dopri8", "SymPy LagrangesMethod → scipy DOP853"),
)


def _points(records: list[dict]) -> list[diagnostics.WorkPrecisionPoint]:
    return [
        diagnostics.WorkPrecisionPoint(r["method"], r["value"], r["run_s"], r["error"])
        for r in records
        if r["outcome"] == "ok"
    ]


def _described(point: diagnostics.WorkPrecisionPoint | None, records) -> str:
    if point is None:
        return "—"
    kind = next(r["parameter"] for r in records if r["method"] == point.method)
    return f"{point.method} ({kind} {point.setting:.3g}): {point.run_seconds:.2e} s"


def fastest_lines(records: list[dict], floors: dict, titles: dict) -> list[str]:
    """Markdown: per scene and error level, the fastest run, lagjax's and the peers'."""
    lines = [
        "| scene | error ≤ | fastest | fastest lagjax | fastest peer | peer / lagjax |",
        "|---|---|---|---|---|---|",
    ]
    for key, title in titles.items():
        rows = [r for r in records if r["scene"] == key]
        ours = _points([r for r in rows if r["family"] == "lagjax"])
        theirs = _points([r for r in rows if r["family"] != "lagjax"])
        for level in ERROR_LEVELS:
            if level < 10 * floors[key]:
                continue  # finer than the reference can judge
            mine = diagnostics.fastest_within(ours, level)
            peer = diagnostics.fastest_within(theirs, level)
            best = diagnostics.fastest_within([p for p in (mine, peer) if p], level)
            ratio = peer.run_seconds / mine.run_seconds if mine and peer else math.nan
            lines.append(
                f"| {title} | {level:.0e} | {best.method if best else '—'} | "
                f"{_described(mine, rows)} | {_described(peer, rows)} | {ratio:.2g} |"
            )
    return lines


def twin_lines(records: list[dict]) -> list[str]:
    """Same method, same tolerance: median run-time ratios peer / lagjax."""
    lines = [
        "| scene | lagjax | peer | peer / lagjax run time (median over rtol) |",
        "|---|---|---|---|",
    ]
    for key in dict.fromkeys(r["scene"] for r in records):
        ok = [r for r in records if r["scene"] == key and r["outcome"] == "ok"]
        for ours, theirs in TWINS:
            mine = {r["value"]: r["run_s"] for r in ok if r["method"] == ours}
            peer = {r["value"]: r["run_s"] for r in ok if r["method"] == theirs}
            shared = sorted(set(mine) & set(peer))
            if shared:
                ratio = diagnostics.median_ratio(
                    [peer[v] for v in shared], [mine[v] for v in shared]
                )
                lines.append(f"| {key} | {ours} | {theirs} | {ratio:.2f} |")
    return lines


def write_diagrams(out: Path, records: list[dict], titles: dict, caption: str) -> None:
    """One `wp_<scene>.png` per scene: error against run time, a line per method,
    in the colours of `benchmarks.palette`; `caption` (the date, the clock) below."""
    for key, title in titles.items():
        points = _points([r for r in records if r["scene"] == key])
        axes = diagnostics.plot_work_precision(points, title=title)
        palette.restyle(axes)
        axes.xaxis.set_minor_formatter(NullFormatter())  # labels 2×10⁻² … overlap
        axes.figure.text(0.01, 0.005, caption, fontsize=7, color="0.3")
        axes.figure.tight_layout(rect=(0, 0.03, 1, 1))
        axes.figure.savefig(out / f"wp_{key}.png", dpi=120)
        plt.close(axes.figure)


def caption(meta: dict) -> str:
    """The figure's note: when, where, in what mode and by which clock."""
    return (
        f"lagjax {meta['mode']} run of {meta['date']}, {meta['machine']}, jax "
        f"{meta['jax']}; run time = {meta.get('clock', 'wall-clock')} time"
    )


def _summary(meta: dict, records, floors, titles, studies) -> list[str]:
    return [
        f"# lagjax work-precision summary ({meta['mode']}, {meta['date']})",
        "",
        "The fastest run reaching each relative final-state error. Peers are the "
        "same equations written by hand (diffrax, scipy) or derived by SymPy; run "
        "times are medians of warm runs, compilation and derivation excluded, "
        f"measured as {meta.get('clock', 'wall-clock')} time.",
        "",
        *fastest_lines(records, floors, titles),
        "",
        "## Same method and tolerance: lagjax against its peers",
        "",
        *twin_lines(records),
        "",
        "Relative accuracy of the float64 references (0: exact solution): "
        + ", ".join(f"{k} {v:.0e}" for k, v in floors.items()),
        "",
        *studies.get("markdown", []),
    ]


def write_report(
    out: Path, records, floors, titles, studies, quick: bool, clock: str = "wall-clock"
) -> None:
    """work_precision.csv, the diagrams, report.json and summary.md, in `out`.

    `clock` names what the run times measure ("wall-clock" time, or "CPU process"
    time, which a loaded machine disturbs less); it goes in the captions.
    """
    with open(out / "work_precision.csv", "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(records[0]))
        writer.writeheader()
        writer.writerows(records)
    meta = dict(
        mode="quick" if quick else "full",
        date=time.strftime("%Y-%m-%d %H:%M"),
        machine=f"{platform.machine()}, {jax.devices()[0].device_kind}",
        jax=jax.__version__,
        clock=clock,
    )
    write_diagrams(out, records, titles, caption(meta))
    report = dict(meta=meta, reference_floor=floors, work_precision=records)
    report.update(studies.get("data", {}))
    (out / "report.json").write_text(json.dumps(report, indent=1, default=str))
    summary = _summary(meta, records, floors, titles, studies)
    (out / "summary.md").write_text("\n".join(summary) + "\n")
