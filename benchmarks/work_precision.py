r"""Work-precision report: error against run time for every scene, solver and peer.

For each scene, every solver family is swept — step counts for fixed-step solvers,
tolerances (rtol = atol) for adaptive ones — and every point is measured the same
way (`lagjax.diagnostics`): compile time apart, run time the median of warm runs
ended by `block_until_ready`, the relative error of the final (q, q̇) against the
exact solution or a float64 reference (Dopri8 at rtol = 10⁻¹⁴; its difference from
rtol = 10⁻¹³ is reported as the reference's floor), and the maximum relative energy
error along the run (from a second, untimed run saved at 200 stratified random
times on the step grid, `diagnostics.sample_times`). Peers run beside lagjax in the
same process (`peers.py`): the equations written by hand and integrated with
diffrax, scipy's `solve_ivp` on numpy right-hand sides, and the SymPy route with
its derivation time. The scaling and throughput studies are in `scaling.py`.

The parts: the scenes and their sweeps in `wp_cases.py`, the solvers and peers as
lines of a diagram in `wp_methods.py`, the measuring in `wp_measure.py`, and the
CSV, JSON, diagrams and summary in `wp_report.py`.

Writes to `--out` (default `benchmarks/results/`): `work_precision.csv`,
`report.json`, one `wp_<scene>.png` per scene and `summary.md` (the fastest method
per scene and error level, peer ratios), plus what `scaling.py` writes.

    python -m benchmarks.work_precision [--quick] [--out DIR] [--skip-scaling]

References: Hairer, Nørsett & Wanner, *Solving Ordinary Differential Equations I*,
2nd ed., §II.10 (work-precision diagrams); Hairer, Lubich & Wanner, *Geometric
Numerical Integration*, 2nd ed., §I.2 (Hénon–Heiles), §I.5 (Fermi–Pasta–Ulam).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

from benchmarks.wp_cases import build_cases  # noqa: E402
from benchmarks.wp_measure import run_case  # noqa: E402
from benchmarks.wp_report import write_report  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a CI-sized run (< 60 s)")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    parser.add_argument("--skip-scaling", action="store_true")
    options = parser.parse_args(argv)
    options.out.mkdir(parents=True, exist_ok=True)
    quick = options.quick
    timing = (
        dict(repeats=3, max_seconds=0.3) if quick else dict(repeats=5, max_seconds=2.0)
    )
    started = time.perf_counter()
    records, floors, titles = [], {}, {}
    for case in build_cases(quick):
        print(f"== {case.title}", flush=True)
        case_records, floors[case.key] = run_case(case, quick, timing)
        records += case_records
        titles[case.key] = case.title
    studies: dict = {}
    if not options.skip_scaling:
        from benchmarks import scaling

        studies = scaling.run_all(options.out, quick, timing)
    write_report(options.out, records, floors, titles, studies, quick)
    print(f"total {time.perf_counter() - started:.0f} s; results in {options.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
