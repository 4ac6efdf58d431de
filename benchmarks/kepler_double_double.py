r"""Kepler's energy at the pericentre: the time-transformed run in double-double
against heyoka in double and in long double (issue 30's first target).

Kepler's problem (GM = a = 1, period 2π) from pericentre, e = 0.99, 0.999, 0.9999,
1000 periods (`--quick`: 100, e = 0.99 alone), 101 saves at multiples of 10
periods — all at the pericentre, where float64 round-off in the log Hamiltonian
the method keeps shows up 2/(1 − e) times enlarged in the energy
(`benchmarks/time_transformed.py --round-off`). Rows, timed interleaved in one
process (process time, medians; compilation apart), one pinned core:

- `TimeTransformed(Yoshida4())`, ds = 0.05, float64 (Kahan's sum): the floor;
- `TimeTransformed(Yoshida4(), precision="double-double")`, ds = 0.05;
- `TimeTransformed(KahanLi8(), precision="double-double")`, ds = 0.1: its timing
  error (the only truncation error: the orbit itself is exact) comparable to
  heyoka's position error;
- heyoka, tol 1e-16 in double, and in long double (`fp_type=np.longdouble`) at
  tol 1e-16: what heyoka needs for an energy below 1e-12 at e ≥ 0.99.

`--batch` adds `jax.vmap` of the double-double Yoshida4 run over 1024
eccentricities in [0.5, 0.999] (`benchmarks/time_transformed.batch_run`), the
largest energy error and pericentre drift over the batch.

Columns: time and its ratio to heyoka in long double, the largest relative energy
error over the saves, the pericentre (Runge–Lenz) drift, the position error
against Kepler's equation.

Run from the repository root: `python -m benchmarks.kepler_double_double [--quick]`.

References: Mikkola & Tanikawa, Celest. Mech. 74, 287 (1999); Biscani & Izzo,
MNRAS 504, 2614 (2021) (heyoka); Hida, Li & Bailey, ARITH-15 (2001).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from collections.abc import Callable

import jax
import numpy as np

import lagjax as lj
from benchmarks.time_transformed import (
    BATCH,
    PERIOD,
    batch_run,
    conserved_errors,
    heyoka_run,
    lagjax_run,
    measures,
    pericentre_state,
)


def heyoka_long_double_run(e: float, ts: np.ndarray, tol: float) -> Callable | None:
    try:
        import heyoka as hy
    except ImportError:
        return None
    x, y, vx, vy = hy.make_vars("x", "y", "vx", "vy")
    r3 = (x**2 + y**2) ** 1.5
    system = [(x, vx), (y, vy), (vx, -x / r3), (vy, -y / r3)]
    start = np.concatenate(pericentre_state(e)).astype(np.longdouble)
    integrator = hy.taylor_adaptive(
        system, list(start), tol=np.longdouble(tol), fp_type=np.longdouble
    )
    grid = ts.astype(np.longdouble)

    def run():
        integrator.time = np.longdouble(0.0)
        integrator.state[:] = start
        states = integrator.propagate_grid(grid)[-1].astype(float)
        return states[:, :2], states[:, 2:]

    return run


def runs_for(e: float, ts: np.ndarray) -> dict[str, Callable | None]:
    double_double = dict(precision="double-double")
    return {
        "TT(Yoshida4) ds=0.05": lagjax_run(
            e, ts, lj.TimeTransformed(lj.Yoshida4()), dt=0.05
        ),
        "TT(Yoshida4) double-double ds=0.05": lagjax_run(
            e, ts, lj.TimeTransformed(lj.Yoshida4(), **double_double), dt=0.05
        ),
        "TT(KahanLi8) double-double ds=0.1": lagjax_run(
            e, ts, lj.TimeTransformed(lj.KahanLi8(), **double_double), dt=0.1
        ),
        "heyoka tol=1e-16": heyoka_run(e, ts),
        "heyoka long double tol=1e-16": heyoka_long_double_run(e, ts, 1e-16),
    }


def trend(q: np.ndarray, p: np.ndarray) -> dict:
    """The largest relative energy error over the first and the last fifth of the
    saves: a secular trend shows as a last fifth well above the first."""
    energy = 0.5 * np.sum(p**2, -1) - 1 / np.linalg.norm(q, axis=-1)
    error = np.abs(energy / -0.5 - 1)
    fifth = max(1, error.size // 5)
    return dict(
        energy_first_fifth=float(np.max(error[1 : fifth + 1])),
        energy_last_fifth=float(np.max(error[-fifth:])),
    )


def rows_for(e: float, periods: int, repeats: int) -> list[dict]:
    ts = np.linspace(0, periods * PERIOD, 101)
    runs = {name: run for name, run in runs_for(e, ts).items() if run is not None}
    results, firsts = {}, {}
    for name, run in runs.items():
        start = time.perf_counter()
        results[name] = run()
        firsts[name] = time.perf_counter() - start
    times: dict[str, list[float]] = {name: [] for name in runs}
    for _ in range(repeats):
        for name, run in runs.items():
            start = time.process_time()
            run()
            times[name].append(time.process_time() - start)
    reference = np.median(times.get("heyoka long double tol=1e-16", [np.nan]))
    rows = []
    for name in runs:
        warm = float(np.median(times[name]))
        row = dict(e=e, periods=periods, method=name, first_s=firsts[name],
                   run_s=warm, ratio_to_heyoka_long_double=warm / reference)  # fmt: skip
        row.update(measures(*results[name], ts, e))
        row.update(trend(*results[name]))
        rows.append(row)
        print(f"e={e:<6} {name:36s} {warm * 1e3:8.1f} ms ({warm / reference:5.2f}x "
              f"heyoka ld)  energy {row['energy']:.1e} (first / last fifth "
              f"{row['energy_first_fifth']:.1e} / {row['energy_last_fifth']:.1e})  "
              f"pericentre {row['pericentre_drift']:.1e} rad  position "
              f"{row['position']:.1e}  (first {firsts[name]:.1f} s)", flush=True)  # fmt: skip
    return rows


def batch_row(periods: int) -> dict:
    ts = np.linspace(0, periods * PERIOD, 101)
    eccentricities = np.linspace(0.5, 0.999, BATCH)
    solver = lj.TimeTransformed(lj.Yoshida4(), precision="double-double")
    run = batch_run(eccentricities, ts, solver, ds=0.05)
    start = time.perf_counter()
    q, p = run()
    first = time.perf_counter() - start
    start = time.process_time()
    run()
    warm = time.process_time() - start
    row = dict(method=f"TT(Yoshida4) double-double ds=0.05 vmap x{BATCH}",
               periods=periods, first_s=first, run_s=warm)  # fmt: skip
    row.update(conserved_errors(q, p))
    print(f"e in [0.5, 0.999] x{BATCH} {row['method']}: {warm:.1f} s ("
          f"{warm / BATCH * 1e3:.1f} ms a member, first {first:.1f} s)  max energy "
          f"{row['energy']:.1e}  max pericentre {row['pericentre_drift']:.1e} rad",
          flush=True)  # fmt: skip
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--batch", action="store_true", help="the vmap row too")
    parser.add_argument("--json", help="write the rows here")
    options = parser.parse_args()
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # taskset -c 1 holds
    lj.enable_fast_cpu_loops()
    jax.config.update("jax_enable_x64", True)
    periods = 100 if options.quick else 1000
    eccentricities = (0.99,) if options.quick else (0.99, 0.999, 0.9999)
    rows = []
    for e in eccentricities:
        rows.extend(rows_for(e, periods, 3 if options.quick else 5))
    if options.batch:
        rows.append(batch_row(10 if options.quick else periods))
    if options.json:
        meta = dict(mode="quick" if options.quick else "full")
        with open(options.json, "w") as file:
            json.dump(dict(meta=meta, rows=rows), file, indent=1)


if __name__ == "__main__":
    main()
