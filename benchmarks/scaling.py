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

    python benchmarks/scaling.py [--quick] [--out DIR]

References: SymPy documentation, `sympy.physics.mechanics.LagrangesMethod`;
JAX documentation, automatic vectorization (`jax.vmap`).
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

import jax

jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import matplotlib  # noqa: E402

matplotlib.use("Agg")  # files only, no display
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import peers  # noqa: E402

import lagjax as lj  # noqa: E402
from lagjax import diagnostics  # noqa: E402
from lagjax.scenes.chains import FermiPastaUlamChain  # noqa: E402
from lagjax.scenes.pendulums import DoublePendulum  # noqa: E402

TOLERANCE = 1e-8
PENDULUM_T1, CHAIN_T1 = 2.0, 10.0
THROUGHPUT_STEPS, THROUGHPUT_DT, CHUNK = 200, 0.01, 4096
ONCE = dict(repeats=1)  # for runs that take many seconds


def n_link_pendulum_lagrangian(m: Any, q: Any, qd: Any, gravity: float = 9.81):
    """n unit masses on n unit rods, angles from the downward vertical.

    Written once for both backends: `m` is jax.numpy (lagjax) or sympy; `q`, `qd`
    are indexed by link.
    """
    x_dot = y_dot = height = kinetic = potential = 0
    for k in range(len(qd)):
        x_dot = x_dot + m.cos(q[k]) * qd[k]
        y_dot = y_dot + m.sin(q[k]) * qd[k]
        height = height - m.cos(q[k])
        kinetic = kinetic + (x_dot**2 + y_dot**2) / 2
        potential = potential + gravity * height
    return kinetic - potential


def lagjax_row(system: Any, y0: Any, t1: float, args: Any, timing: dict) -> dict:
    def run(y0):
        trajectory = lj.simulate(
            system, y0, t1=t1, solver=diffrax.Dopri8(), args=args,
            rtol=TOLERANCE, atol=TOLERANCE, max_steps=10**6,
        )  # fmt: skip
        return trajectory.q[-1], trajectory.stats["num_steps"]

    measured = diagnostics.time_run(run, y0, **timing)
    return dict(
        build_s=measured.compile_seconds,
        run_s=measured.run_seconds,
        steps=int(measured.output[1]),
    )


def scipy_row(route: peers.NumpyRoute, t1: float, timing: dict) -> dict:
    from scipy.integrate import solve_ivp

    def run():
        return solve_ivp(
            route.rhs, (0.0, t1), route.initial_state, method="DOP853",
            rtol=TOLERANCE, atol=TOLERANCE,
        )  # fmt: skip

    measured = diagnostics.time_run(run, jit=False, warmup=0, **timing)
    return dict(
        build_s=route.derivation_seconds,
        run_s=measured.run_seconds,
        steps=len(measured.output.t) - 1,
        evaluations=int(measured.output.nfev),
    )


def derive_symbolic_rhs(size: int) -> tuple[Any, float]:
    """q̈ solved by SymPy (`LagrangesMethod.rhs`) and lambdified: (f, seconds)."""
    import sympy as sp
    from sympy.physics.mechanics import LagrangesMethod, dynamicsymbols

    start = time.perf_counter()
    q = list(dynamicsymbols(f"q1:{size + 1}"))
    qd = [coordinate.diff(dynamicsymbols._t) for coordinate in q]
    method = LagrangesMethod(n_link_pendulum_lagrangian(sp, q, qd), q)
    method.form_lagranges_equations()
    x, v = sp.symbols(f"x0:{size}"), sp.symbols(f"v0:{size}")
    plain = list(zip(qd, v)) + list(zip(q, x))
    rhs = sp.lambdify([x, v], method.rhs().subs(plain), "numpy")
    return rhs, time.perf_counter() - start


def _numpy_route(rhs: Any, start: np.ndarray, seconds: float) -> peers.NumpyRoute:
    return peers.NumpyRoute(rhs, start, lambda xp, y: y, seconds)


def measured_or_estimated(
    route: peers.NumpyRoute, t1: float, like: dict, budget: float
) -> dict:
    """scipy DOP853 on `route`; or, when one evaluation (median of three) times the
    evaluation count of `like` — the same equations at the same tolerance — exceeds
    budget/4, that product, marked as an estimate."""
    call = diagnostics.time_run(
        route.rhs, 0.0, route.initial_state, jit=False, warmup=0, repeats=3
    )
    estimate = call.run_seconds * like["evaluations"]
    if estimate >= budget / 4:
        return dict(build_s=route.derivation_seconds, run_s=estimate,
                    steps=like["steps"], estimated=True)  # fmt: skip
    return dict(scipy_row(route, t1, ONCE), estimated=False)


def symbolic_row(size: int, numeric: dict, budget: float) -> dict:
    """SymPy solving for q̈ itself: its build time, and its run time."""
    rhs, seconds = derive_symbolic_rhs(size)
    start = np.concatenate([np.full(size, 0.5), np.zeros(size)])

    def field(t, y):
        return np.concatenate([y[size:], np.ravel(rhs(y[:size], y[size:]))[size:]])

    route = _numpy_route(field, start, seconds)
    return measured_or_estimated(route, PENDULUM_T1, numeric, budget)


def _next_exceeds(times: list[float], budget: float) -> bool:
    """Whether the next derivation, extrapolated geometrically, exceeds `budget`."""
    if not times:
        return False
    growth = times[-1] / times[-2] if len(times) > 1 and times[-2] > 0 else 2.0
    return times[-1] * max(growth, 1.0) > budget


def pendulum_scaling(sizes: range, budget: float, timing: dict) -> list[dict]:
    """lagjax and both SymPy variants for n-link pendulums of the given sizes."""
    rows: list[dict] = []
    built: dict[str, list[float]] = {"numeric": [], "symbolic": []}
    for n in sizes:
        lag = lj.Lagrangian(
            lambda q, qd: n_link_pendulum_lagrangian(jnp, q, qd),
            quadratic_in_velocity=True,
        )
        y0 = (jnp.full(n, 0.5), jnp.zeros(n))
        rows.append(
            dict(n=n, route="lagjax", **lagjax_row(lag, y0, PENDULUM_T1, None, timing))
        )
        if not (peers.have_sympy() and peers.have_scipy()):
            continue
        if _next_exceeds(built["numeric"], budget):
            continue
        rhs, seconds = peers.derive_with_sympy(n_link_pendulum_lagrangian, n)
        start = np.concatenate([np.full(n, 0.5), np.zeros(n)])
        numeric = scipy_row(_numpy_route(rhs, start, seconds), PENDULUM_T1, timing)
        built["numeric"].append(seconds)
        rows.append(dict(n=n, route="SymPy, numeric solve of M", **numeric))
        if not _next_exceeds(built["symbolic"], budget):
            symbolic = symbolic_row(n, numeric, budget)
            built["symbolic"].append(symbolic["build_s"])
            rows.append(dict(n=n, route="SymPy, symbolic rhs()", **symbolic))
    for row in rows:
        print(_row_line(dict(system=f"{row['n']}-link pendulum", **row)), flush=True)
    return [dict(system=f"{row['n']}-link pendulum", **row) for row in rows]


def _row_line(row: dict) -> str:
    note = " (estimated)" if row.get("estimated") else ""
    return (
        f"  {row['system']:22s} {row['route']:28s} build {row['build_s']:7.2f} s, "
        f"run {row['run_s']:9.2e} s{note}, steps {row['steps']}"
    )


def chain_scaling(timing: dict, with_sympy: bool, budget: float) -> list[dict]:
    """A 100-particle FPU chain: lagjax, hand-written diffrax and (full mode) SymPy."""
    chain = FermiPastaUlamChain(frequency=50.0, pairs=50)
    system = dict(system="FPU chain, 100 particles", n=100)
    rows = [
        dict(
            system,
            route="lagjax",
            **lagjax_row(chain, chain.initial_state(), CHAIN_T1, None, timing),
        )
    ]
    peer = peers.fermi_pasta_ulam(chain)
    final = peers.diffrax_final(peer, diffrax.Dopri8(), CHAIN_T1, TOLERANCE)
    measured = diagnostics.time_run(final, jnp.asarray(peer.initial_state), **timing)
    rows.append(dict(system, route="hand-written diffrax", build_s=measured.compile_seconds,
                     run_s=measured.run_seconds, steps=-1))  # fmt: skip
    if with_sympy and peers.have_sympy() and peers.have_scipy():
        hand = scipy_row(peers.hand_written_numpy(peer), CHAIN_T1, timing)
        rows.append(dict(system, route="scipy DOP853, hand-written numpy", **hand))
        route = peers.sympy_numpy(peer)
        sympy = measured_or_estimated(route, CHAIN_T1, hand, budget)
        rows.append(dict(system, route="SymPy, numeric solve of M", **sympy))
    for row in rows:
        print(_row_line(row), flush=True)
    return rows


def _batched_starts(batch: int) -> tuple[jax.Array, jax.Array]:
    """The scene's start with θ₁ spread by up to 10⁻³ rad across the batch."""
    q0, qdot0 = DoublePendulum().initial_state()
    spread = 1e-3 * jnp.linspace(-1.0, 1.0, batch)[:, None] * jnp.array([1.0, 0.0])
    return q0 + spread, jnp.broadcast_to(qdot0, (batch, 2))


def _chunked_rate(single: Any, starts: Any, batch: int, timing: dict) -> dict:
    """Compile `vmap(single)` for one chunk, then time the whole batch chunk by chunk."""
    size = min(batch, CHUNK)
    chunks = [
        jax.tree_util.tree_map(lambda x, k=k: x[k : k + size], starts)
        for k in range(0, batch, size)
    ]
    began = time.perf_counter()
    compiled = jax.jit(jax.vmap(single)).lower(chunks[0]).compile()
    build = time.perf_counter() - began
    measured = diagnostics.time_run(
        lambda: [compiled(chunk) for chunk in chunks], jit=False, **timing
    )
    rate = batch * THROUGHPUT_STEPS / measured.run_seconds
    return dict(build_s=build, run_s=measured.run_seconds, steps_per_s=rate)


def throughput(batches: tuple[int, ...], sweep_batches: tuple[int, ...], timing: dict):
    """Trajectory-steps per second of the double pendulum against the batch size."""
    scene, t1 = DoublePendulum(), THROUGHPUT_STEPS * THROUGHPUT_DT
    peer = peers.double_pendulum(scene)
    term = diffrax.ODETerm(lambda t, y, args: peer.vector_field(jnp, y))

    def ours(y0):
        solver = diffrax.Tsit5()
        return lj.simulate(scene, y0, t1=t1, dt=THROUGHPUT_DT, solver=solver).ys

    def hand(y0):
        return diffrax.diffeqsolve(
            term, diffrax.Tsit5(), 0.0, t1, THROUGHPUT_DT, y0,
            saveat=diffrax.SaveAt(t1=True), max_steps=THROUGHPUT_STEPS + 1,
        ).ys  # fmt: skip

    rows = []
    for batch in batches:
        q0, qdot0 = _batched_starts(batch)
        for route, single, starts in (
            ("lagjax (vmap of lj.simulate)", ours, (q0, qdot0)),
            ("hand-written diffrax (vmap)", hand, jnp.concatenate([q0, qdot0], -1)),
        ):
            rows.append(
                dict(
                    batch=batch,
                    route=route,
                    **_chunked_rate(single, starts, batch, timing),
                )
            )
    for batch in sweep_batches:  # lj.sweep as a user calls it: it compiles each time
        starts = _batched_starts(batch)
        measured = diagnostics.time_run(
            lambda starts=starts: lj.sweep(scene, starts, t1=t1, dt=THROUGHPUT_DT,
                                           solver=diffrax.Tsit5(), chunk_size=CHUNK).ys,
            jit=False, warmup=0, repeats=1,
        )  # fmt: skip
        rate = batch * THROUGHPUT_STEPS / measured.run_seconds
        rows.append(dict(batch=batch, route="lj.sweep (per call)", build_s=0.0,
                         run_s=measured.run_seconds, steps_per_s=rate))  # fmt: skip
    for row in rows:
        print(f"  batch {row['batch']:6d} {row['route']:30s} {row['steps_per_s']:9.3g} "
              f"trajectory-steps/s (run {row['run_s']:.2e} s)", flush=True)  # fmt: skip
    return rows


def _write_csv(path: Path, rows: list[dict]) -> None:
    fields = list(dict.fromkeys(key for row in rows for key in row))
    with open(path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=fields)
        writer.writeheader()
        writer.writerows(rows)


def plot(out: Path, scaling_rows: list[dict], throughput_rows: list[dict]) -> None:
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
            label, style = (f"{route}, FPU chain", "D") if chain else (route, "o-")
            ns = [r["n"] for r in rows]
            build.loglog(ns, [r["build_s"] for r in rows], style, label=label)
            run.loglog(ns, [r["run_s"] for r in rows], style, label=label)
            for r in rows:
                if r.get("estimated"):
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
            "o-",
            label=route,
        )
    rate.set(xlabel="batch size", ylabel="trajectory-steps per second",
             title=f"Double pendulum, Tsit5, {THROUGHPUT_STEPS} fixed steps")  # fmt: skip
    for axes in (build, run, rate):
        axes.grid(True, alpha=0.3)
        axes.legend(fontsize=7)
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
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
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
