r"""Equal accuracy, each side at its best: lagjax's Taylor route against heyoka.

Issue 28's targets are errors, not tolerances: "error ≤ 1e-12 one trajectory",
"error ≤ 1e-11 for 1024 trajectories". A tolerance means different errors to
different integrators (the double pendulum to t = 100 at tol 1e-12: heyoka
7.9e-13, lagjax's rule 1.9e-12), and each side may pick any setting. So this
script sweeps both:

- **heyoka**: `taylor_adaptive` (one trajectory) or its batch mode at the SIMD
  width (`benchmarks.taylor.heyoka_batch`), over a grid of tolerances;
- **lagjax**: `jax.jit(simulate(lag, y0, solver=lj.Taylor(rtol=tol, atol=tol,
  order=p)))` — for the batch `jax.jit(jax.vmap(...))`, as users write it — over
  the same tolerances at the order of Jorba & Zou's rule and at higher orders
  (`order=`), where the batch loop's fixed cost per order makes fewer, longer
  steps cheaper;
- **lagjax → heyoka**: the same `simulate` calls with `lj.Taylor(...,
  backend="heyoka")` (lagjax's derived equations translated into heyoka's
  expressions and run by its integrator; one trajectory eagerly, the batch through
  `jax.jit(jax.vmap(...))`, which hands it to heyoka's batch mode), over the
  tolerances;

times every setting in turn in one process (CPU time of the process, pinned to
one core, medians of interleaved rounds, compilation apart), measures its error
against heyoka in long double at tol 1e-19 (or, without heyoka, lagjax's Taylor
at order 26 and tol 1e-16) — for one trajectory the median over nine starts
10⁻⁴ apart (`probe_states`: a single run's error is a draw of the rounding) — and
for each target error reports each side's fastest setting that meets it and the
ratio of their times. The double pendulum (m = l = 1, g = 9.81) as in `benchmarks/taylor.py`.

    python -m benchmarks.taylor_frontier [--quick] [--json PATH] [--figure PATH]

`--figure` draws error against run time, every setting a point and each side's
front (the settings no other setting beats in both) a line.

References: Jorba & Zou, Experimental Mathematics 14 (2005) (the order and step
rule); Biscani & Izzo, MNRAS 504 (2021) (heyoka).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

import lagjax as lj
from lagjax._core.cpu_loops import enable_fast_cpu_loops
from lagjax.taylor.step import order_from_tolerance

from .taylor import LAGRANGIAN, heyoka_batch

G = 9.81
clock = time.process_time  # the process's CPU time: another process's load stays out
SIDES = ("heyoka", "lagjax", "lagjax->heyoka")
LABELS = ("heyoka", "lagjax Taylor (JAX)", "lagjax → heyoka")
# All three run Taylor's method (one colour in `benchmarks.palette`'s sense);
# here the colour tells the implementation apart.
TINTS = ("#333333", "#1f77b4", "#9467bd")


class Case(NamedTuple):
    name: str
    members: int  # 0: one trajectory
    t1: float
    targets: tuple[float, ...]
    heyoka_tols: tuple[float, ...]
    lagjax_tols: tuple[float, ...]
    extra_orders: tuple[int, ...]  # added to the rule's order
    rounds: int


FULL = (
    Case("one trajectory", 0, 100.0, (1e-12, 1e-14),
         (1e-11, 3e-12, 1e-12, 3e-13, 1e-13, 1e-14, 1e-15, 1e-16),
         (1e-11, 3e-12, 1e-12, 5e-13, 1e-13, 1e-14, 1e-15), (0, 1, 2, 4), 21),
    Case("1024 trajectories", 1024, 10.0, (1e-11,),
         (3e-11, 1e-11, 3e-12, 1e-12, 1e-13),
         (1e-11, 3e-12, 1e-12, 3e-13), (0, 2, 4, 6), 7),
)  # fmt: skip
QUICK = (
    Case("one trajectory", 0, 10.0, (1e-11,), (1e-12,), (1e-12,), (0, 2), 3),
    Case("8 trajectories", 8, 1.0, (1e-11,), (1e-12,), (1e-12,), (0,), 3),
)


def initial_states(members: int) -> np.ndarray:
    """θ = (0.5, 0.3) from rest, or θ₁ ∈ [0.1, 1], θ₂ = 0.3 for a batch: (B, 4)."""
    if members == 0:
        return np.array([[0.5, 0.3, 0.0, 0.0]])
    th1 = np.linspace(0.1, 1.0, members)
    return np.stack([th1, np.full(members, 0.3), 0 * th1, 0 * th1], 1)


def heyoka_system():
    import heyoka as hy

    a, b, wa, wb = hy.make_vars("a", "b", "wa", "wb")
    lagrangian = wa**2 + 0.5 * wb**2 + wa * wb * hy.cos(a - b)
    lagrangian += 2 * G * hy.cos(a) + G * hy.cos(b)
    return hy, hy.lagrangian(lagrangian, [a, b], [wa, wb])


def reference(y0s: np.ndarray, t1: float) -> tuple[np.ndarray, str]:
    """Final states to ~1e-18: heyoka in long double, else Taylor p = 26."""
    try:
        hy, system = heyoka_system()
    except ImportError:
        final = jax.jit(jax.vmap(lambda y: lagjax_final(y, t1, 1e-16, 26)))
        return np.asarray(final(jnp.asarray(y0s))), "lagjax Taylor p=26 tol 1e-16"
    ld = np.longdouble
    ta = hy.taylor_adaptive(system, np.zeros(4, ld), tol=ld(1e-19), fp_type=ld)
    out = np.empty_like(y0s)
    for i, y0 in enumerate(y0s):
        ta.time = ld(0.0)
        ta.state[:] = y0.astype(ld)
        ta.propagate_until(ld(t1))
        out[i] = ta.state.astype(float)
    return out, "heyoka long double tol 1e-19"


def lagjax_final(y, t1: float, tol: float, order: int | None, backend: str = "jax"):
    solver = lj.Taylor(rtol=tol, atol=tol, order=order, backend=backend)
    run = lj.simulate(LAGRANGIAN, (y[:2], y[2:]), t1=t1, solver=solver)
    eager = isinstance(run.q, np.ndarray)  # heyoka's route on NumPy values
    return (np.concatenate if eager else jnp.concatenate)([run.q[-1], run.qdot[-1]])


def heyoka_call(y0s: np.ndarray, case: Case, tol: float) -> Callable | None:
    """A call from initial states (k, 4) to final states (k, 4): for a batch,
    heyoka's batch mode on `y0s` (bound here); for one trajectory, one run per row."""
    if case.members:
        batch = heyoka_batch(y0s, case.t1, tol)
        return None if batch is None else (lambda states: batch())
    try:
        hy, system = heyoka_system()
    except ImportError:
        return None
    ta = hy.taylor_adaptive(system, y0s[0], tol=tol)

    def run(states: np.ndarray) -> np.ndarray:
        out = np.empty_like(states)
        for i, y0 in enumerate(states):
            ta.time = 0.0
            ta.state[:] = y0
            ta.propagate_until(case.t1)
            out[i] = ta.state
        return out

    return run


def heyoka_installed() -> bool:
    try:
        import heyoka  # noqa: F401
    except ImportError:
        return False
    return True


def heyoka_route_call(y0s: np.ndarray, case: Case, tol: float) -> Callable:
    """As `lagjax_call`, through `lj.Taylor(backend="heyoka")`: the batch by
    `jax.jit(jax.vmap(simulate))`, one trajectory by `simulate` on NumPy values
    (no JAX: the call goes to heyoka directly)."""
    final = lambda y: lagjax_final(y, case.t1, tol, None, backend="heyoka")
    if case.members:
        batch = jax.jit(jax.vmap(final))
        run = lambda states: np.asarray(batch(jnp.asarray(states)))
    else:
        run = lambda states: np.stack([np.asarray(final(y)) for y in states])
    run(y0s)  # translate and compile apart
    return run


def lagjax_call(y0s: np.ndarray, case: Case, tol: float, order: int) -> Callable:
    """As `heyoka_call`: `jax.jit(jax.vmap(simulate))` on the batch, or
    `jax.jit(simulate)` once per row."""
    final = lambda y: lagjax_final(y, case.t1, tol, order)
    if case.members:
        batch = jax.jit(jax.vmap(final))
        run = lambda states: np.asarray(batch(jnp.asarray(states)))
    else:
        one = jax.jit(final)
        run = lambda states: np.stack([np.asarray(one(jnp.asarray(y))) for y in states])
    run(y0s)  # compile apart
    return run


def settings(y0s: np.ndarray, case: Case) -> list[dict]:
    """Every setting of both sides with its call (compiled)."""
    rows = []
    for tol in case.heyoka_tols:
        call = heyoka_call(y0s, case, tol)
        if call is not None:
            rows.append(dict(side="heyoka", tol=tol, order=None, call=call))
    for tol in case.lagjax_tols if heyoka_installed() else ():
        call = heyoka_route_call(y0s, case, tol)
        rows.append(dict(side="lagjax->heyoka", tol=tol, order=None, call=call))
    for tol in case.lagjax_tols:
        rule = order_from_tolerance(tol)
        for extra in case.extra_orders:
            call = lagjax_call(y0s, case, tol, rule + extra)
            rows.append(dict(side="lagjax", tol=tol, order=rule + extra, call=call))
    return rows


def probe_states(case: Case) -> np.ndarray:
    """Where each setting's error is measured. One trajectory's error at t = 100 is
    a draw of the rounding (the double pendulum amplifies each rounding error:
    one setting reads 3e-13, its neighbour 2e-12), so a setting's error is the
    median over nine starts θ₁ = 0.5 + i·10⁻⁴ (i = −4..4, θ₂ = 0.3): the same
    dynamics, nine draws; their largest is kept too. A batch: its members."""
    if case.members:
        return initial_states(case.members)
    th1 = 0.5 + 1e-4 * np.arange(-4, 5)
    return np.stack([th1, np.full(9, 0.3), 0 * th1, 0 * th1], 1)


def errors(final: np.ndarray, exact: np.ndarray, case: Case) -> tuple[float, float]:
    """(the setting's error, the largest): the maximum over a batch's members
    and the state's components; for one trajectory the median over the probes."""
    each = np.max(np.abs(final - exact), axis=1)
    typical = np.max(each) if case.members else np.median(each)
    return float(typical), float(np.max(each))


def measure(case: Case) -> dict:
    timed, probes = initial_states(case.members), probe_states(case)
    exact, source = reference(probes, case.t1)
    rows = settings(probes, case)
    times: list[list[float]] = [[] for _ in rows]
    for _ in range(case.rounds):  # in turn: a change of load falls on every row
        for row, row_times in zip(rows, times):
            start = clock()
            row["call"](timed)
            row_times.append(clock() - start)
    for row, row_times in zip(rows, times):
        row["seconds"] = float(np.median(row_times))
        row["fastest"] = float(np.min(row_times))
        row["error"], row["error_max"] = errors(row.pop("call")(probes), exact, case)
    best = {target: best_at(rows, target) for target in case.targets}
    return dict(case=case.name, t1=case.t1, members=case.members, reference=source,
                rows=rows, best=best)  # fmt: skip


def best_at(rows: list[dict], target: float) -> dict:
    """Each side's fastest setting with error ≤ target, and lagjax/heyoka."""
    out: dict = {}
    for side in SIDES:
        meeting = [r for r in rows if r["side"] == side and r["error"] <= target]
        out[side] = min(meeting, key=lambda r: r["seconds"]) if meeting else None
    for side, key in (("lagjax", "ratio"), ("lagjax->heyoka", "heyoka_route_ratio")):
        if out["heyoka"] and out[side]:
            out[key] = out[side]["seconds"] / out["heyoka"]["seconds"]
    return out


def describe(row: dict | None) -> str:
    if row is None:
        return "none meets it"
    order = "" if row["order"] is None else f", order {row['order']}"
    return (f"tol {row['tol']:.0e}{order}: {row['seconds'] * 1e3:.2f} ms "
            f"(fastest {row['fastest'] * 1e3:.2f}), error {row['error']:.1e} "
        f"(largest {row['error_max']:.1e})")  # fmt: skip


def report(result: dict) -> None:
    print(
        f"\n{result['case']} to t = {result['t1']} (reference: {result['reference']})"
    )
    for row in sorted(result["rows"], key=lambda r: (r["side"], r["seconds"])):
        print(f"  {row['side']:14s} {describe(row)}")
    for target, best in result["best"].items():
        print(f"  error <= {target:.0e}:")
        for side in SIDES:
            key = {"lagjax": "ratio", "lagjax->heyoka": "heyoka_route_ratio"}.get(side)
            ratio = f"  ({best[key]:.2f}x heyoka)" if key in best else ""
            print(f"    {side:14s} {describe(best[side])}{ratio}")


def front(rows: list[dict]) -> list[dict]:
    """The settings that no other setting beats in both time and error."""
    ordered = sorted(rows, key=lambda r: (r["seconds"], r["error"]))
    kept, lowest = [], np.inf
    for row in ordered:
        if row["error"] < lowest:
            kept.append(row)
            lowest = row["error"]
    return kept


def draw(results: list[dict], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(results), figsize=(5.5 * len(results), 4.2))
    for ax, result in zip(np.atleast_1d(axes), results):
        for side, label, tint in zip(SIDES, LABELS, TINTS):
            rows = [r for r in result["rows"] if r["side"] == side]
            kept = front(rows)
            ax.loglog([r["seconds"] * 1e3 for r in rows], [r["error"] for r in rows],
                      ".", color=tint, alpha=0.4)  # fmt: skip
            ax.loglog([r["seconds"] * 1e3 for r in kept], [r["error"] for r in kept],
                      "-o", color=tint, label=label)  # fmt: skip
        for target in result["best"]:
            ax.axhline(float(target), color="grey", lw=0.8, ls=":")  # a JSON key
        ax.set_xlabel("run time, ms (CPU time, one core)")
        spread = "largest member" if result["members"] else "median of 9 starts"
        ax.set_ylabel(f"error of the final state ({spread})")
        ax.set_title(f"double pendulum, {result['case']}, t = {result['t1']:g}")
        ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a CI-sized run")
    parser.add_argument("--json", help="write the rows and the best settings here")
    parser.add_argument("--figure", help="draw error against time to this PNG")
    options = parser.parse_args()
    enable_fast_cpu_loops()  # before the first JAX computation
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # one core, as heyoka
    jax.config.update("jax_enable_x64", True)
    results = []
    for case in QUICK if options.quick else FULL:
        results.append(measure(case))
        report(results[-1])
    if options.json:
        with open(options.json, "w") as f:
            json.dump(results, f, indent=1)
    if options.figure:
        draw(results, options.figure)


if __name__ == "__main__":
    main()
