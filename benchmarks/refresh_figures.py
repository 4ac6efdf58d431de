"""Redraw the committed figures of `benchmarks/figures/` from their committed data.

    python -m benchmarks.refresh_figures [--measure wp|scaling ...] [--out DIR]

Without `--measure`, nothing is run: the six figures are drawn from the data
files beside them, in the colours of `benchmarks.palette` —

- `wp_kepler.png`, `wp_double_pendulum.png`, `wp_henon_heiles.png` from
  `work_precision.json` (the full sweeps of `work_precision.py` on those scenes);
- `scaling.png` from `scaling.json` (the size and batch studies of `scaling.py`);
- `taylor_frontier.png` from `taylor_frontier.json` (`taylor_frontier.py`'s full
  run: lagjax's Taylor route and heyoka, every setting's error against time);
- `rigid_long_horizon.png` from the "Every point" table of `rigid_long_horizon.md`
  (written by `rigid_long_horizon.py`; run times to three digits).

`--measure wp` re-runs those three work-precision sweeps and `--measure scaling`
the scaling studies (its SymPy derivations capped by `--sympy-budget`), each
writing its JSON first. Run times are then **CPU process time**
(`time.process_time`, every thread of the process): on a shared machine, another
process's load slows the wall clock of a run but hardly its CPU time. The clock is
swapped in the modules that read it (`lagjax.diagnostics.time_run`, the SymPy and
build timers of `scaling_size`, `scaling_throughput` and `peers`). Each figure's
caption says when it was measured and by which clock.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
import types
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

FIGURES = Path(__file__).parent / "figures"
WP_SCENES = ("kepler", "double_pendulum", "henon_heiles")
TIMING = dict(repeats=5, max_seconds=2.0)  # as a full run of work_precision.py


def _meta(clock: str) -> dict:
    return dict(
        mode="full",
        date=time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        machine=f"{platform.machine()}, {jax.devices()[0].device_kind}",
        jax=jax.__version__,
        clock=clock,
    )


def use_cpu_clock() -> None:
    """Make the benchmark timers read CPU process time instead of the wall clock."""
    import lagjax.diagnostics
    from benchmarks import peers, scaling_size, scaling_throughput

    cpu = types.SimpleNamespace(perf_counter=time.process_time)
    for module in (lagjax.diagnostics, peers, scaling_size, scaling_throughput):
        module.time = cpu  # type: ignore[attr-defined]


def measure_work_precision(out: Path) -> None:
    """The full sweeps of the three scenes, into `work_precision.json`."""
    from benchmarks.wp_cases import build_cases
    from benchmarks.wp_measure import run_case

    records: list[dict] = []
    floors, titles = {}, {}
    for case in build_cases(quick=False):
        if case.key in WP_SCENES:
            print(f"== {case.title}", flush=True)
            case_records, floors[case.key] = run_case(case, False, TIMING)
            records += case_records
            titles[case.key] = case.title
    data = dict(
        meta=_meta("CPU process"), floors=floors, titles=titles, records=records
    )
    (out / "work_precision.json").write_text(json.dumps(data, indent=1, default=str))


def measure_scaling(out: Path, budget: float) -> None:
    """Both scaling studies (full sizes and batches), into `scaling.json`."""
    import tempfile

    from benchmarks import scaling

    with tempfile.TemporaryDirectory() as scratch:  # its CSVs and PNG: not kept
        studies = scaling.run_all(Path(scratch), False, TIMING, budget)
    meta = dict(_meta("CPU process"), sympy_budget_s=budget)
    data = dict(meta=meta, **studies["data"])
    (out / "scaling.json").write_text(json.dumps(data, indent=1, default=str))


def draw(out: Path) -> None:
    """The figures whose data files are in `out`."""
    from benchmarks import rigid_long_horizon_report, scaling, wp_report

    if (out / "work_precision.json").exists():
        wp = json.loads((out / "work_precision.json").read_text())
        caption = _caption(wp["meta"])
        wp_report.write_diagrams(out, wp["records"], wp["titles"], caption)
    if (out / "scaling.json").exists():
        sizes = json.loads((out / "scaling.json").read_text())
        caption = _caption(sizes["meta"])
        scaling.plot(out, sizes["scaling"], sizes["throughput"], caption)
    if (out / "taylor_frontier.json").exists():
        from benchmarks import taylor_frontier

        results = json.loads((out / "taylor_frontier.json").read_text())
        taylor_frontier.draw(results, str(out / "taylor_frontier.png"))
    if (out / "rigid_long_horizon.md").exists():
        report = (out / "rigid_long_horizon.md").read_text()
        records = rigid_long_horizon_report.records_from_markdown(report)
        title = report.splitlines()[0].lstrip("# ")
        caption = (
            "data: the full run in rigid_long_horizon.md (run time = wall-clock "
            f"time); redrawn {time.strftime('%Y-%m-%d', time.gmtime())}"
        )
        path = out / "rigid_long_horizon.png"
        rigid_long_horizon_report.plot(records, title, path, caption)


def _caption(meta: dict) -> str:
    return (
        f"measured {meta['date']} ({meta['mode']} run, {meta['machine']}, jax "
        f"{meta['jax']}); run time = {meta['clock']} time"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--measure", nargs="*", choices=("wp", "scaling"), default=[])
    parser.add_argument("--out", type=Path, default=FIGURES)
    parser.add_argument("--sympy-budget", type=float, default=60.0)
    options = parser.parse_args()
    if options.measure:
        use_cpu_clock()
    if "wp" in options.measure:
        measure_work_precision(options.out)
    if "scaling" in options.measure:
        measure_scaling(options.out, options.sympy_budget)
    draw(options.out)


if __name__ == "__main__":
    main()
