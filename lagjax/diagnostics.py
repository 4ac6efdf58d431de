r"""Measurements on runs: energy error, final-state error, convergence order, timing.

These are the yardsticks of the benchmarks (`benchmarks/work_precision.py`) and of
the tests, exposed so that users can judge their own runs the same way:

| helper | measures |
|---|---|
| `energy_error(run)` | $\max_t \lvert E(t) - E_0\rvert / \lvert E_0\rvert$ along a saved run |
| `final_state_error(state, reference)` | $\lVert y - y_{\rm ref}\rVert_2 / \lVert y_{\rm ref}\rVert_2$, final (q, q̇) |
| `sample_times(t0, t1, count, dt)` | save times for `energy_error` that see every phase |
| `convergence_order(dts, errors)` | least-squares slope of $\log e$ against $\log\Delta t$ |
| `time_run(fn, *args)` | compile seconds and the median of warm, blocked runs |
| `median_ratio(a, b)` | median of a/b over paired points (a method against its twin) |
| `failure_reason(error)` | the one line of a failed run's error meant for the user |

Errors are relative and unit-free so that one error level ("1e-6") means the same
thing for every scene. States are compared as (q, q̇) — not (q, p) — so that a run
integrated as a Hamiltonian, one integrated as a Lagrangian and a peer written by
hand (scipy, SymPy) meet on the same coordinates.

References: Hairer, Nørsett & Wanner, *Solving Ordinary Differential Equations I*,
2nd ed., Springer 1993, §II.10 (work-precision diagrams, error at the end point);
Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed., Springer 2006,
§I.1 and §IX.8 (energy error of symplectic methods: bounded, no drift).
"""

from __future__ import annotations

import math
import re
import statistics
import time
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from lagjax._core.host_callbacks import MISSING_CPU_MESSAGE, is_missing_cpu_error
from lagjax.trajectory import Trajectory


class Timing(NamedTuple):
    """What `time_run` measured.

    - `compile_seconds`: tracing (which includes lagjax's derivation by autodiff)
      plus XLA compilation; 0.0 for a function run without `jit`.
    - `run_seconds`: the median of the timed runs, each ended by
      `block_until_ready`.
    - `runs`: every timed run, in seconds.
    - `output`: what the function returned (from the last run).
    """

    compile_seconds: float
    run_seconds: float
    runs: tuple[float, ...]
    output: Any


def time_run(
    fn: Callable[..., Any],
    *args: Any,
    repeats: int = 5,
    warmup: int = 1,
    max_seconds: float | None = None,
    jit: bool = True,
) -> Timing:
    """Compile `fn(*args)` once, then time `repeats` warm runs; report the median.

    **Arguments:**
    - `fn`: with `jit=True`, a JAX-traceable function of `args`, which must be
      arrays or pytrees of arrays (close over anything else); with `jit=False`, any
      Python callable (a scipy run; pass `warmup=0` if a first call costs no more
      than the others).
    - `repeats`: at most this many timed runs (at least one).
    - `warmup`: untimed runs first, so that caches and allocators are warm.
    - `max_seconds`: stop repeating once the timed runs add up to this much, so a
      sweep over slow points stays bounded; the median is of the runs made.

    Why the median: the machine is shared, and a few runs slowed by another process
    move the mean but not the median.
    """
    if jit:
        start = time.perf_counter()
        call = jax.jit(fn).lower(*args).compile()
        compile_seconds = time.perf_counter() - start
    else:
        call, compile_seconds = fn, 0.0
    output = None
    for _ in range(warmup):
        output = jax.block_until_ready(call(*args))
    runs: list[float] = []
    while len(runs) < max(1, repeats):
        start = time.perf_counter()
        output = jax.block_until_ready(call(*args))
        runs.append(time.perf_counter() - start)
        if max_seconds is not None and sum(runs) >= max_seconds:
            break
    return Timing(compile_seconds, statistics.median(runs), tuple(runs), output)


def _flat(tree: Any) -> np.ndarray:
    """All leaves of a pytree as one float64 vector."""
    leaves = jax.tree_util.tree_leaves(tree)
    return np.concatenate([np.ravel(np.asarray(leaf, dtype=float)) for leaf in leaves])


def _final_position_velocity(state: Any) -> Any:
    """(q, q̇) at the last saved time of a `Trajectory`; anything else as given."""
    if isinstance(state, Trajectory):
        if jnp.ndim(state.ts) != 1:
            raise ValueError(
                "final_state_error compares one run; index a batched trajectory first"
            )
        return jax.tree_util.tree_map(lambda x: x[-1], (state.q, state.qdot))
    return state


def final_state_error(state: Any, reference: Any, *, relative: bool = True) -> float:
    r"""$\|y - y_{\rm ref}\|_2 / \|y_{\rm ref}\|_2$ over every component of the state.

    `state` and `reference` are each a `Trajectory` (its final q and q̇ are used) or
    a pytree such as `(q, qdot)`; both must have the same leaves in the same order.
    With `relative=False` the plain Euclidean distance is returned.
    """
    values = _flat(_final_position_velocity(state))
    expected = _flat(_final_position_velocity(reference))
    if values.shape != expected.shape:
        raise ValueError(
            f"state has {values.size} components, reference {expected.size}"
        )
    distance = float(np.linalg.norm(values - expected))
    if not relative:
        return distance
    return distance / max(float(np.linalg.norm(expected)), np.finfo(float).tiny)


def energy_error(run: Any, reference: Any = None) -> Any:
    r"""Maximum relative energy error along a run, $\max_t |E(t) - E_0| / |E_0|$.

    **Arguments:**
    - `run`: a `Trajectory` saved at several times (its `energy()`: H, or the Jacobi
      integral of L), or an array of energies with time on the last axis.
    - `reference`: $E_0$; default the energy at the first saved time.

    A batched run (time on the last axis, batch in front) gives one error per
    member. Where $E_0 = 0$ the absolute error is returned instead. For a system
    that is not conservative (friction, a drive, explicit time dependence) this
    measures the change of the Jacobi integral, not an error.
    """
    energies = run.energy() if isinstance(run, Trajectory) else jnp.asarray(run)
    if jnp.ndim(energies) == 0:
        raise ValueError("energy_error needs energies at several saved times")
    start = energies[..., 0] if reference is None else jnp.asarray(reference)
    scale = jnp.where(start == 0, 1.0, jnp.abs(start))
    deviation = jnp.max(jnp.abs(energies - start[..., None]), axis=-1)
    return deviation / scale


def sample_times(
    t0: float, t1: float, count: int, dt: float | None = None, seed: int = 0
) -> np.ndarray:
    r"""`count` increasing save times from `t0`, one at a random place in each of
    `count` equal slices of [t0, t1]; with `dt`, on the step grid $t_0 + k\,\Delta t$.

    What to pass as `ts` when measuring `energy_error`. Evenly spaced samples can be
    commensurate with the motion — a run of 100 Kepler periods saved 101 times sees
    every orbit at the same phase — and then miss the peaks of the error, by orders
    of magnitude; stratified random samples see every phase. On the grid, the saved
    states are the method's own, not interpolated between steps. The first time is
    `t0`, so `energy_error` measures from the initial energy.
    """
    offsets = np.random.default_rng(seed).uniform(size=count)
    offsets[0] = 0.0
    fractions = (np.arange(count) + offsets) / count
    if dt is None:
        return t0 + (t1 - t0) * fractions
    steps = round(abs((t1 - t0) / dt))
    if steps < count:
        raise ValueError(f"{steps} steps cannot hold {count} distinct save times")
    edges = np.arange(count + 1) * steps // count  # whole steps per slice
    picks = edges[:-1] + np.floor(offsets * np.diff(edges)).astype(int)
    return t0 + dt * picks


def convergence_order(dts: Any, errors: Any) -> float:
    r"""Least-squares slope of $\log e$ against $\log\Delta t$: the observed order.

    A method of order $p$ has $e \approx C\,\Delta t^p$ while truncation dominates,
    so the slope is $p$; pass only points above round-off and below the region
    where the error saturates. Costs work too: against the number of steps the
    slope is $-p$.
    """
    steps, sizes = np.asarray(dts, dtype=float), np.asarray(errors, dtype=float)
    if steps.shape != sizes.shape or steps.ndim != 1 or steps.size < 2:
        raise ValueError("convergence_order needs two or more (dt, error) pairs")
    values = np.concatenate([steps, sizes])
    if not (np.all(np.isfinite(values)) and np.all(values > 0)):
        raise ValueError("step sizes and errors must be positive and finite")
    slope, _ = np.polyfit(np.log(steps), np.log(sizes), 1)
    return float(slope)


def median_ratio(numerators: Any, denominators: Any) -> float:
    """Median of elementwise ratios, e.g. run times of a method against a twin.

    NaN where nothing pairs up. Used to summarise "lagjax takes r× the time of the
    hand-written version" over a sweep without letting one noisy point decide.
    """
    ratios = [
        a / b
        for a, b in zip(np.ravel(numerators), np.ravel(denominators))
        if b > 0 and math.isfinite(a) and math.isfinite(b)
    ]
    return float(statistics.median(ratios)) if ratios else math.nan


def failure_reason(error: BaseException) -> str:
    """The one line of a failed run's error that says what went wrong.

    Errors raised inside `jit` (`eqx.error_if`, diffrax's `throw=True`) arrive
    wrapped in a long message; the line after "EquinoxRuntimeError:" is the one
    written for the user. A host callback that found no CPU device
    (`JAX_PLATFORMS` without "cpu") gets its remedy. Anything else: its type and
    first line.
    """
    text = str(error)
    if is_missing_cpu_error(error):
        return MISSING_CPU_MESSAGE
    raised = re.findall(r"EquinoxRuntimeError: (.+)", text)
    if raised:
        return raised[-1].strip()
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    return f"{type(error).__name__}: {lines[0] if lines else ''}"


class WorkPrecisionPoint(NamedTuple):
    """One measured run of a work-precision diagram: a method at one setting."""

    method: str
    setting: float
    run_seconds: float
    error: float


def fastest_within(points: Any, level: float) -> WorkPrecisionPoint | None:
    """The fastest point whose error is at most `level`; None when none reaches it.

    Reading a work-precision diagram at a fixed accuracy — "which method gets to
    1e-6 first?" — is how methods are compared (Hairer, Nørsett & Wanner §II.10).
    """
    reached = [
        point for point in points if math.isfinite(point.error) and point.error <= level
    ]
    return min(reached, key=lambda point: point.run_seconds, default=None)


def plot_work_precision(points: Any, *, title: str = "", ax: Any = None) -> Any:
    """Log error against log run time, one line per method; returns the axes.

    Methods whose label starts with "lagjax" are drawn solid, others dashed.
    """
    import matplotlib.pyplot as plt

    if ax is None:
        ax = plt.subplots(figsize=(7.5, 5))[1]
    for method in dict.fromkeys(point.method for point in points):
        line = sorted(
            (p.run_seconds, p.error)
            for p in points
            if p.method == method and p.error > 0 and math.isfinite(p.run_seconds)
        )
        if line:
            style = "-o" if method.startswith("lagjax") else "--s"
            ax.loglog(*zip(*line), style, label=method, markersize=4)
    ax.set_xlabel("run time [s] (median of warm runs, compile excluded)")
    ax.set_ylabel("relative error of the final (q, q̇)")
    ax.set_title(title)
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    return ax
