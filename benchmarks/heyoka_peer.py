r"""heyoka as a peer: its Taylor integrator beside lagjax's Dopri8, and lagjax's
equations run by heyoka through the backend (`lagjax.taylor.heyoka_backend`).

The routes, on one pinned core: **heyoka** — the equations derived by heyoka
itself (`heyoka.lagrangian`) and integrated by `taylor_adaptive` /
`taylor_adaptive_batch`; **heyoka(translation)** — heyoka's integrator compiled
from lagjax's translation (below) and called as heyoka's own users call it, no
lagjax code around the run: what the translation alone costs; **lagjax→heyoka**
— the equations derived by lagjax (`lj.Lagrangian(L).acceleration`), their jaxpr
translated into heyoka's expressions (`heyoka_integrate`); **lagjax Taylor (JAX)** — the JAX-native Taylor integrator
(`lagjax.taylor.taylor_integrate`, jitted: its coefficients from the jaxpr, the
orders on a tape, `lagjax.taylor.tape`); **lagjax Dopri8** — `lj.simulate` with `diffrax.Dopri8` at
rtol = atol = 1e-14, jitted; **simulate(Taylor heyoka)** — what a user writes,
`lj.simulate(lag, y0, solver=lj.Taylor(backend="heyoka"))`, checks and all, the
solver made once like any diffrax solver (making an `lj.Taylor` is an equinox
Module's `__init__`, 0.1–0.2 ms); **jit(simulate heyoka)** — that call for one
trajectory under `jax.jit`, one `jax.pure_callback`; and for the batch
**vmap(simulate heyoka)** —
`jax.jit(jax.vmap(...))` of that call, one `pure_callback` into heyoka's batch
mode (`lagjax.taylor.heyoka_callback`). Cases, unit masses and rods, g = 9.81:

(a) the double pendulum from θ = (0.5, 0.3), q̇ = 0, to t = 100; heyoka at tol 1e-12
    and 1e-15; the error is the largest difference of the final state from heyoka
    in long double at tol 1e-18;
(b) 1024 double pendulums, θ₁ ∈ linspace(0.1, 1), θ₂ = 0.3, to t = 10, heyoka's
    batch mode at its SIMD width against `jax.jit(jax.vmap(...))`, tol 1e-9,
    1e-12 and 1e-15;
(c) the n-link pendulum, n = 2, 4, 8, released at rest from 0.5 rad, to t = 10:
    first call (derivation, translation, compilation) and run.

Runs are medians of warm calls in the process's CPU time (`time.process_time`,
as `benchmarks/taylor.py`), those of one case's heyoka routes taken in turn (a
change in the machine's load falls on all alike; 31 rounds for one trajectory,
11 for the batch); compilation is timed apart. The process keeps to
the first core it may use (`taskset -c 1 python -m benchmarks.heyoka_peer` pins
core 1). heyoka is optional (`pip install heyoka`). `--quick` shortens every
run (CI check).

Measured (core 0 of the 2-core machine, 2026-11-28, while a 2-worker test run
kept the load at 3.3, so absolute times are about 3× a quiet machine's; the
ratios are of routes taken in turn in one process): one trajectory to t = 100,
heyoka(translation) / heyoka 0.94× at tol 1e-12 and 0.97× at 1e-15 (the folded
translation: 41 terms against heyoka's own 49, `lagjax.taylor.heyoka_signs`);
simulate(Taylor heyoka) 1.04× and 1.02×; jit(simulate heyoka) 1.10× and 1.07×;
×1024 to t = 10, heyoka(translation) / heyoka's batch mode 0.93×, 0.90×, 1.01×
at tol 1e-9, 1e-12, 1e-15, vmap(simulate heyoka) 0.99×, 0.99×, 1.10×; the
states agreeing with heyoka's to within each tolerance's error. The n-link chains
run 2.1× (4 links) and 2.7× (8 links) heyoka's time: lagjax's derived equations
of a long chain are larger than heyoka's own `lagrangian`.

References: F. Biscani & D. Izzo, "Revisiting high-order Taylor methods for
astrodynamics and celestial mechanics", MNRAS 504 (2021) 2614; À. Jorba & M. Zou,
Experimental Mathematics 14 (2005) 99.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from collections.abc import Callable
from typing import Any

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

import lagjax as lj
from benchmarks.scaling_size import n_link_pendulum_lagrangian
from benchmarks.taylor import in_blocks
from lagjax._core.cpu_loops import enable_fast_cpu_loops
from lagjax.taylor import taylor_integrate
from lagjax.taylor.heyoka_backend import heyoka_integrate, heyoka_integrate_batch
from lagjax.taylor.heyoka_cache import heyoka_integrator, translated
from lagjax.taylor.heyoka_expressions import import_heyoka

# CPU time of this process, not wall time (as benchmarks/taylor.py): on the shared
# machine another process's load or a preemption then stays out of the figures
# (the process is pinned to one core, so its threads' time is the core's).
clock = time.process_time
DOPRI8_TOL = 1e-14
REFERENCE_TOL = 1e-18
FULL = dict(
    single_t1=100.0,
    single_tols=(1e-12, 1e-15),
    single_repeats=31,
    batch=1024,
    batch_repeats=11,
    batch_t1=10.0,
    batch_tols=(1e-9, 1e-12, 1e-15),
    links=(2, 4, 8),
    chain_t1=10.0,
    chain_tol=1e-14,
)
QUICK = dict(
    single_t1=5.0,
    single_tols=(1e-12,),
    single_repeats=5,
    batch=16,
    batch_repeats=5,
    batch_t1=1.0,
    batch_tols=(1e-9,),
    links=(2,),
    chain_t1=1.0,
    chain_tol=1e-9,
)


def median_seconds(call: Callable[[], Any], repeats: int = 5) -> float:
    call()
    runs = []
    for _ in range(repeats):
        start = clock()
        jax.block_until_ready(call())
        runs.append(clock() - start)
    return statistics.median(runs)


def interleaved_medians(calls: list[Callable[[], Any]], repeats: int) -> list[float]:
    """Medians of warm calls taken in turn, so that a change in the machine's
    load falls on every route alike (their ratios are the figures)."""
    for call in calls:
        call()
    runs: list[list[float]] = [[] for _ in calls]
    for _ in range(repeats):
        for call, times in zip(calls, runs):
            start = clock()
            jax.block_until_ready(call())
            times.append(clock() - start)
    return [statistics.median(times) for times in runs]


def timed(call: Callable[[], Any]) -> tuple[float, Any]:
    start = clock()
    out = jax.block_until_ready(call())
    return clock() - start, out


class Chain:
    """The n-link pendulum three ways: heyoka's equations, lagjax's vector field,
    lagjax's Lagrangian."""

    def __init__(self, n: int) -> None:
        hy = import_heyoka()
        self.n = n
        qs = [hy.make_vars(f"q{i}") for i in range(n)]
        qds = [hy.make_vars(f"qd{i}") for i in range(n)]
        self.heyoka_equations = hy.lagrangian(
            n_link_pendulum_lagrangian(hy, qs, qds), qs, qds
        )
        self.lagrangian = lj.Lagrangian(
            lambda q, qd: n_link_pendulum_lagrangian(jnp, q, qd)
        )

    def vector_field(self, t: Any, y: Any, args: Any) -> Any:
        q, qd = y[: self.n], y[self.n :]
        return jnp.concatenate([qd, self.lagrangian.acceleration(q, qd, t, args)])

    def heyoka(self, y0: np.ndarray, tol: float, fp_type: Any = float, width: int = 0):
        hy = import_heyoka()
        compact = 2 * self.n > 6
        if width:
            state = np.repeat(y0[:, None], width, axis=1)
            return hy.taylor_adaptive_batch(self.heyoka_equations, state, tol=tol,
                                            compact_mode=compact)  # fmt: skip
        return hy.taylor_adaptive(self.heyoka_equations, y0.astype(fp_type), tol=fp_type(tol),
                                  compact_mode=compact, fp_type=fp_type)  # fmt: skip

    def dopri8(self, t1: float) -> Callable[[Any], Any]:
        def final(y0):
            run = lj.simulate(self.lagrangian, (y0[: self.n], y0[self.n :]), t1=t1,
                              solver=diffrax.Dopri8(), rtol=DOPRI8_TOL, atol=DOPRI8_TOL,
                              max_steps=10**6)  # fmt: skip
            return jnp.concatenate([run.q[-1], run.qdot[-1]])

        return final


def heyoka_until(ta: Any, y0: np.ndarray, t1: float) -> np.ndarray:
    fp = ta.state.dtype.type
    ta.time, ta.state[:] = fp(0.0), y0.astype(fp)
    ta.propagate_until(fp(t1))
    return ta.state.copy()


def reference(chain: Chain, y0: np.ndarray, t1: float) -> np.ndarray:
    ta = chain.heyoka(y0, REFERENCE_TOL, fp_type=np.longdouble)
    return heyoka_until(ta, y0, t1).astype(float)


def row(
    case: str, route: str, tol: float, first_s: float, call: Callable, exact,
    run_s: float | None = None,
) -> dict:  # fmt: skip
    """One table row: `call()` returns the final state(s), compared with `exact`;
    its run time `run_s`, or the median of its own warm calls."""
    error = np.max(np.abs(np.asarray(call(), dtype=float) - exact))
    run_s = median_seconds(call) if run_s is None else run_s
    return dict(case=case, route=route, tol=tol, first_s=first_s, run_s=run_s,
                error=float(error))  # fmt: skip


def heyoka_rows(case: str, chain: Chain, y0, t1: float, tol: float, exact,
                repeats: int, derive_s: float = 0.0) -> list[dict]:  # fmt: skip
    """heyoka's own equations, and lagjax's through the backend, at `tol`."""
    compile_s, ta = timed(lambda: chain.heyoka(y0, tol))

    def backend():
        return heyoka_integrate(chain.vector_field, y0, 0.0, t1, tol=tol).ys[-1]

    solver = lj.Taylor(backend="heyoka")  # made once, as a diffrax solver is

    def simulate_taylor():
        n = chain.n
        run = lj.simulate(chain.lagrangian, (y0[:n], y0[n:]), t1=t1, rtol=tol,
                          atol=tol, solver=solver)  # fmt: skip
        return np.concatenate([run.q[-1], run.qdot[-1]])

    def heyoka():
        return heyoka_until(ta, y0, t1)

    n = chain.n

    @jax.jit
    def jitted(y):  # one member under jit: one pure_callback
        run = lj.simulate(chain.lagrangian, (y[:n], y[n:]), t1=t1, rtol=tol,
                          atol=tol, solver=solver)  # fmt: skip
        return jnp.concatenate([run.q[-1], run.qdot[-1]])

    def simulate_jit():
        return jitted(y0)

    first_s, _ = timed(backend)
    # heyoka's integrator compiled from lagjax's translation, called directly
    translation_s, translation = timed(
        lambda: heyoka_integrator(
            translated(chain.vector_field, 2 * n, None), tol, 1, np.float64, None
        )
    )

    def heyoka_translation():
        return heyoka_until(translation, y0, t1)

    simulate_first_s, _ = timed(simulate_taylor)
    jit_first_s, _ = timed(simulate_jit)
    calls = [heyoka, heyoka_translation, backend, simulate_taylor, simulate_jit]
    runs = interleaved_medians(calls, repeats)
    return [
        row(case, "heyoka", tol, derive_s + compile_s, heyoka, exact, runs[0]),
        row(case, "heyoka(translation)", tol, first_s + translation_s,
            heyoka_translation, exact, runs[1]),
        row(case, "lagjax->heyoka", tol, first_s, backend, exact, runs[2]),
        # what a user writes: lj.simulate(lag, y0, solver=lj.Taylor(backend="heyoka"))
        row(case, "simulate(Taylor heyoka)", tol, simulate_first_s, simulate_taylor,
            exact, runs[3]),
        row(case, "jit(simulate heyoka)", tol, jit_first_s, simulate_jit, exact,
            runs[4]),
    ]  # fmt: skip


def dopri8_row(case: str, chain: Chain, y0s, t1: float, exact) -> dict:
    """lagjax's Dopri8, jitted (and vmapped for a batch of initial states)."""
    final = chain.dopri8(t1)
    final = jax.jit(jax.vmap(final) if np.ndim(y0s) == 2 else final)
    first_s, _ = timed(lambda: final(jnp.asarray(y0s)))
    return row(case, "lagjax Dopri8", DOPRI8_TOL, first_s, lambda: final(jnp.asarray(y0s)),
               exact)  # fmt: skip


def jax_taylor_row(case: str, chain: Chain, y0, t1: float, tol: float, exact) -> dict:
    """lagjax's JAX-native Taylor integrator, jitted, at `tol`."""
    final = jax.jit(lambda y: taylor_integrate(chain.vector_field, y, 0.0, t1,
                                               rtol=tol, atol=tol).ys[-1])  # fmt: skip
    first_s, _ = timed(lambda: final(jnp.asarray(y0)))
    return row(case, "lagjax Taylor (JAX)", tol, first_s,
               lambda: final(jnp.asarray(y0)), exact)  # fmt: skip


def single_case(config: dict) -> list[dict]:
    chain, t1 = Chain(2), config["single_t1"]
    y0 = np.array([0.5, 0.3, 0.0, 0.0])
    exact = reference(chain, y0, t1)
    rows = [r for tol in config["single_tols"]
            for r in [*heyoka_rows("single", chain, y0, t1, tol, exact,
                                   config["single_repeats"]),
                      jax_taylor_row("single", chain, y0, t1, tol, exact)]]  # fmt: skip
    return [*rows, dopri8_row("single", chain, y0, t1, exact)]


def batch_rows(
    case: str, chain: Chain, y0s, t1: float, tol: float, exact, repeats: int
) -> list[dict]:
    """heyoka's batch mode at its SIMD width, raw and through the backend."""
    width = import_heyoka().recommended_simd_size()
    compile_s, ta = timed(lambda: chain.heyoka(y0s[0], tol, width=width))

    def blocks(integrator: Any) -> Callable[[], np.ndarray]:
        """The members through a batch integrator, a block of `width` at a time."""
        return in_blocks(integrator, y0s, t1, width)

    raw = blocks(ta)

    def backend():
        return heyoka_integrate_batch(chain.vector_field, y0s, 0.0, t1, tol=tol).ys[
            :, -1
        ]

    solver, n = lj.Taylor(backend="heyoka"), chain.n

    def final(y0):  # under vmap: one pure_callback, heyoka's batch mode
        run = lj.simulate(chain.lagrangian, (y0[:n], y0[n:]), t1=t1, rtol=tol,
                          atol=tol, solver=solver)  # fmt: skip
        return jnp.concatenate([run.q[-1], run.qdot[-1]])

    def vmapped():
        return batched(y0s)

    batched = jax.jit(jax.vmap(final))
    first_s, _ = timed(backend)
    translation_s, translation = timed(
        lambda: heyoka_integrator(
            translated(chain.vector_field, 2 * n, None), tol, width, np.float64, None
        )
    )
    vmap_first_s, _ = timed(vmapped)
    runs = interleaved_medians([raw, blocks(translation), backend, vmapped], repeats)
    return [row(case, "heyoka", tol, compile_s, raw, exact, runs[0]),
            row(case, "heyoka(translation)", tol, first_s + translation_s,
                blocks(translation), exact, runs[1]),
            row(case, "lagjax->heyoka", tol, first_s, backend, exact, runs[2]),
            row(case, "vmap(simulate heyoka)", tol, vmap_first_s, vmapped, exact,
                runs[3])]  # fmt: skip


def batch_case(config: dict) -> list[dict]:
    chain, t1, members = Chain(2), config["batch_t1"], config["batch"]
    y0s = np.stack([[a, 0.3, 0.0, 0.0] for a in np.linspace(0.1, 1.0, members)])
    exact = np.stack([reference(chain, y0, t1) for y0 in y0s])
    case = f"batch x{members}"
    rows = [r for tol in config["batch_tols"]
            for r in batch_rows(case, chain, y0s, t1, tol, exact,
                                config["batch_repeats"])]  # fmt: skip
    return [*rows, dopri8_row(case, chain, y0s, t1, exact)]


def chain_case(config: dict) -> list[dict]:
    rows, t1 = [], config["chain_t1"]
    for n in config["links"]:
        start = clock()
        chain = Chain(n)
        derive_s = clock() - start
        y0 = np.concatenate([np.full(n, 0.5), np.zeros(n)])
        exact = reference(chain, y0, t1)
        case = f"{n}-link"
        rows += heyoka_rows(case, chain, y0, t1, config["chain_tol"], exact,
                            config["single_repeats"], derive_s)  # fmt: skip
        rows.append(jax_taylor_row(case, chain, y0, t1, config["chain_tol"], exact))
        rows.append(dopri8_row(case, chain, y0, t1, exact))
    return rows


def print_table(rows: list[dict]) -> None:
    print(
        f"{'case':<12} {'route':<23} {'tol':>7} {'first call':>11} {'run':>11} {'error':>9}"
    )
    for r in rows:
        print(f"{r['case']:<12} {r['route']:<23} {r['tol']:>7.0e} {r['first_s']:>10.3f}s "
              f"{r['run_s'] * 1e3:>9.2f}ms {r['error']:>9.1e}")  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="short runs (CI check)")
    parser.add_argument("--json", help="write the rows to this path")
    options = parser.parse_args()
    enable_fast_cpu_loops()  # before the first JAX computation
    jax.config.update("jax_enable_x64", True)
    # one core (Linux): the first of those allowed (`taskset -c 1` picks it)
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    config = QUICK if options.quick else FULL
    rows = single_case(config) + batch_case(config) + chain_case(config)
    print_table(rows)
    if options.json:
        with open(options.json, "w") as file:
            json.dump(
                dict(quick=options.quick, config=config, rows=rows), file, indent=1
            )


if __name__ == "__main__":
    main()
