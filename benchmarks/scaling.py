r"""How costs grow: with the number of coordinates, and with the batch size.

**Size.** An n-link pendulum, n = 1 … 10 (unit masses and rods, all links released
at rest from 0.5 rad), and a 100-particle Fermi–Pasta–Ulam chain. For lagjax the
"build" time is tracing — which includes the derivation by autodiff — plus XLA
compilation of `lj.simulate`; the run is adaptive Dopri8 at rtol = atol = 10⁻⁸. For
SymPy the build is `LagrangesMethod` and `lambdify`; two variants are timed:
lambdifying M and f and solving M q̈ = f numerically at every call (the route of
`peers.derive_with_sympy`), and asking SymPy for q̈ itself (`LagrangesMethod.rhs`),
whose expressions swell with n. Both run in scipy's DOP853 at the same tolerance.
SymPy is capped by a time budget: n stops growing once the next derivation,
extrapolated from the last two, would exceed `--sympy-budget` seconds (the
symbolic variant's run time is then estimated from one right-hand-side evaluation
times the numeric variant's evaluation count, and marked so).

**Batch.** Trajectory-steps per second for the double pendulum, 200 fixed Tsit5
steps per trajectory, batch 1 … 65536 in chunks of 4096 (memory stays bounded by a
chunk): `jax.vmap` of `lj.simulate` against `jax.vmap` of a hand-written
`diffrax.diffeqsolve`. `lj.sweep` is timed as called (it compiles on every call).

The size study is in `scaling_size.py`, the batch study in `scaling_throughput.py`;
this file runs both and writes their CSV files, figure and summary.

    python -m benchmarks.scaling [--quick] [--out DIR]

References: SymPy documentation, `sympy.physics.mechanics.LagrangesMethod`;
JAX documentation, automatic vectorization (`jax.vmap`).
"""

from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import matplotlib  # noqa: E402

matplotlib.use("Agg")  # files only, no display
import matplotlib.pyplot as plt  # noqa: E402

from benchmarks import palette  # noqa: E402
from benchmarks.scaling_size import TOLERANCE, chain_scaling, pendulum_scaling  # noqa: E402
from benchmarks.scaling_throughput import THROUGHPUT_STEPS, throughput  # noqa: E402


def _write_csv(path: Path, rows: list[dict]) -> None:
    fields = list(dict.fromkeys(key for row in rows for key in row))
    with open(path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=fields)
        writer.writeheader()
        writer.writerows(rows)


def plot(
    out: Path, scaling_rows: list[dict], throughput_rows: list[dict], caption: str = ""
) -> None:
    """scaling.png: build and run time against size, throughput against batch, in
    the colours of `benchmarks.palette` (the routes run Dopri8/DOP853, and Tsit5
    for the throughput); `caption` (the date, the clock) below."""
    figure, (build, run, rate) = plt.subplots(1, 3, figsize=(15, 4.5))
    for route in dict.fromkeys(r["route"] for r in scaling_rows):
        for chain in (False, True):  # the 100-particle chain is a point of its own
            rows = sorted(
                (r for r in scaling_rows
                 if r["route"] == route and r["system"].startswith("FPU") == chain),
                key=lambda r: r["n"],
            )  # fmt: skip
            if not rows:
                continue
            style = palette.style(route, method="Dopri8")
            label = route
            if chain:  # a hollow marker of the route's own shape, no line
                label = f"{route}, FPU chain"
                style = {**style, "linestyle": "none", "markersize": 9,
                         "markerfacecolor": "none", "markeredgewidth": 1.5}  # fmt: skip
            ns = [r["n"] for r in rows]
            build.loglog(ns, [r["build_s"] for r in rows], label=label, **style)
            run.loglog(ns, [r["run_s"] for r in rows], label=label, **style)
            for r in rows:
                if r.get("estimated") in (True, "True"):
                    run.plot(r["n"], r["run_s"], "kx", markersize=9)
    build.set(
        xlabel="coordinates n (n-link pendulum; n = 100: FPU chain)",
        ylabel="derivation + compile [s]",
        title="Build time against system size",
    )
    run.set(xlabel="coordinates n", ylabel="warm run time [s] (× = estimated)",
            title=f"Run time, Dopri8/DOP853 at rtol {TOLERANCE:g}")  # fmt: skip
    for route in dict.fromkeys(r["route"] for r in throughput_rows):
        rows = [r for r in throughput_rows if r["route"] == route]
        rate.loglog(
            [r["batch"] for r in rows],
            [r["steps_per_s"] for r in rows],
            label=route,
            **palette.style(route, method="Tsit5"),
        )
    rate.set(xlabel="batch size", ylabel="trajectory-steps per second",
             title=f"Double pendulum, Tsit5, {THROUGHPUT_STEPS} fixed steps")  # fmt: skip
    for axes in (build, run, rate):
        axes.grid(True, alpha=0.3)
        axes.legend(fontsize=7)
    if caption:
        figure.supxlabel(caption, fontsize=7, color="0.3")
    figure.tight_layout()
    figure.savefig(out / "scaling.png", dpi=120)
    plt.close(figure)


def markdown(
    scaling_rows: list[dict], throughput_rows: list[dict], budget: float
) -> list[str]:
    lines = ["## Scaling with system size", "",
             f"SymPy is stopped once its next derivation is extrapolated to exceed {budget:g} s.", "",
             "| system | route | derivation + compile [s] | run [s] |", "|---|---|---|---|"]  # fmt: skip
    for r in scaling_rows:
        note = " (estimated)" if r.get("estimated") else ""
        lines.append(
            f"| {r['system']} | {r['route']} | {r['build_s']:.2f} | {r['run_s']:.2e}{note} |"
        )
    lines += ["", "## Batched throughput (double pendulum)", "",
              "| batch | route | trajectory-steps/s |", "|---|---|---|"]  # fmt: skip
    lines += [
        f"| {r['batch']} | {r['route']} | {r['steps_per_s']:.3g} |"
        for r in throughput_rows
    ]
    return lines


def run_all(out: Path, quick: bool, timing: dict, budget: float = 60.0) -> dict:
    """Both studies; writes scaling.csv, throughput.csv and scaling.png to `out`."""
    started = time.perf_counter()
    print("== Scaling with system size", flush=True)
    sizes = range(1, 3) if quick else range(1, 11)
    scaling_rows = pendulum_scaling(sizes, budget, timing)
    scaling_rows += chain_scaling(timing, not quick, budget)
    print("== Batched throughput", flush=True)
    batches = (1, 64) if quick else tuple(4**k for k in range(9))
    sweep_batches = (64,) if quick else (1024, 65536)
    throughput_rows = throughput(batches, sweep_batches, timing)
    _write_csv(out / "scaling.csv", scaling_rows)
    _write_csv(out / "throughput.csv", throughput_rows)
    plot(out, scaling_rows, throughput_rows)
    print(f"  ({time.perf_counter() - started:.0f} s)")
    return dict(
        data=dict(scaling=scaling_rows, throughput=throughput_rows),
        markdown=markdown(scaling_rows, throughput_rows, budget),
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    parser.add_argument("--sympy-budget", type=float, default=60.0)
    options = parser.parse_args()
    options.out.mkdir(parents=True, exist_ok=True)
    timing = (
        dict(repeats=3, max_seconds=0.3)
        if options.quick
        else dict(repeats=5, max_seconds=2.0)
    )
    studies = run_all(options.out, options.quick, timing, options.sympy_budget)
    (options.out / "scaling.md").write_text("\n".join(studies["markdown"]) + "\n")


if __name__ == "__main__":
    main()
