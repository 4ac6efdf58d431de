"""Refuse a bad `simulate` call before anything is traced, with the remedy.

`check_simulate_inputs` runs first in `simulate`. It looks only at what is known
when the call is made — the Python types, the pytree structures and shapes, and the
values of concrete (not traced) numbers — so it costs nothing in the compiled run
and nothing at all under `jit`, where the values are tracers and only structures
are checked. Every refusal names the problem and what to do instead:

| input | refused when | remedy named |
|---|---|---|
| `system` | not a lagjax system (a bare function, a class, …) | `Lagrangian(L)`, `Hamiltonian(H)`, `Scene()` |
| `solver` | a class, a string, a non-solver, an SDE or IMEX solver | `Tsit5()`, a lagjax solver instance |
| `max_steps` | not a positive integer | a positive `int` or None |
| `t0`, `t1`, `dt` | NaN, inf, not a real number; `dt = 0`; more than 10⁹ steps; `dt` under 64 ulps of the largest time | finite times, a larger `dt`, time shifted to start at 0 |
| `t0`, `t1` (adaptive) | a span under 64 ulps of the largest time (t0 = 1e15, t1 = t0 + 1) | time shifted to start at 0 |
| `rtol`, `atol` (adaptive) | both under ε/100 of the working precision (float32 at 1e-12) | rtol ≥ 10 ε, or float64 |
| `args` | a NaN anywhere (infinities are allowed) | finite parameters |
| `y0` | float64 arrays while JAX's x64 mode is off (a warning) | `jax.config.update("jax_enable_x64", True)` |
| `ts` | NaN, not 1-D, unsorted, outside [t0, t1] | sorted times inside the span |
| `ts` with `saveat` | both given (`saveat` would drop `ts`) | one of them (`check_save_choice`) |
| `y0` | not a pair; q and its partner of different structure or shape; no coordinates (q0 of size 0); NaN/inf; float16; complex or boolean | `(q0, qdot0)` / `(q0, p0)` of matching shapes, float32/64 |
| `y0` of a `RigidBody` | quaternion not of shape (4,), zero; momentum not (3,) | a unit quaternion, e.g. `(1, 0, 0, 0)` |
| `rtol`, `atol` | NaN, negative, or both zero | positive tolerances |
| `y0` of a constrained `Lagrangian` | off the constraints (residuals named) | a start on the manifold |

The `y0` rows are checked in `lagjax._integrate.checks.initial_state`. Integer entries in `y0`
are accepted (documented) and converted to floats there: `(1, 0)` starts the same
run as `(1.0, 0.0)`. Half precision (float16, bfloat16) is
refused rather than promoted: its 3 significant digits cannot meet any stopping
test of the implicit stage or Legendre solves, and a silent promotion would hide
that the run is not in the precision asked for.

What cannot be known before the run — a blow-up, a failed stage solve, a
constraint-violating start — is diagnosed by the loop and `Trajectory.result`.
"""

from __future__ import annotations

import math
import numbers
import typing
import warnings
from typing import Any

import jax
import numpy as np
from jax.core import Tracer

from lagjax._core.precision import working_dtype
from lagjax._integrate.checks.initial_state import (
    check_initial_state,
)
from lagjax._integrate.checks.system_and_solver import (
    check_solver,
    check_solver_fits,
    check_system,
    user_system,
)

# More steps than this cannot finish in a session (at ~10 ns a step, 10⁹ steps
# take 10 s for the cheapest system; a typical one takes minutes).
MAX_FIXED_STEPS = 10**9
# The smallest normal float64: a span below it is subnormal, steps in it lose bits.
_TINY = float(np.finfo(np.float64).tiny)


def check_simulate_inputs(
    system: Any,
    y0: Any,
    t0: Any,
    t1: Any,
    dt: Any,
    solver: Any,
    ts: Any,
    args: Any,
    max_steps: Any,
    rtol: Any = 1e-8,
    atol: Any = 1e-8,
) -> Any:
    """Check the arguments of `simulate`; return `y0` with integers made floats.

    Raises `TypeError` (wrong kind of object) or `ValueError` (wrong value) with a
    message that names the argument, what is wrong and the remedy. Checks that need
    values are made only for concrete values (not under `jit`/`vmap`).
    """
    check_system(system)
    check_solver(solver)
    check_solver_fits(user_system(system), solver)
    check_max_steps(max_steps)
    check_tolerances(rtol, atol)
    check_times(t0, t1, dt)
    check_save_times(ts, t0, t1)
    check_args_not_nan(args)
    warn_float64_without_x64(y0)
    y0 = check_initial_state(system, y0)
    dtype = working_dtype(y0)
    check_time_resolution(t0, t1, dt, dtype)
    if dt is None:
        check_tolerance_resolution(rtol, atol, dtype)
    return y0


def check_max_steps(max_steps: Any) -> None:
    """`max_steps` must be None or a positive integer."""
    if max_steps is None:
        return
    if isinstance(max_steps, bool) or not isinstance(max_steps, numbers.Integral):
        raise TypeError(
            f"max_steps must be a positive int or None, got {max_steps!r} "
            f"({type(max_steps).__name__}); e.g. max_steps=100_000"
        )
    if max_steps <= 0:
        raise ValueError(
            f"max_steps must be positive, got {max_steps}; pass None for the default "
            "(the exact count for fixed steps, 10⁵ adaptive)"
        )


def check_tolerances(rtol: Any, atol: Any) -> None:
    """`rtol` and `atol` must be finite, non-negative and not both zero."""
    values = {
        "rtol": _concrete_scalar(rtol, "rtol"),
        "atol": _concrete_scalar(atol, "atol"),
    }
    for name, value in values.items():
        if value is not None and not (math.isfinite(value) and value >= 0):
            raise ValueError(
                f"{name} must be a finite non-negative number, got {value}; the "
                "default 1e-8 suits most runs"
            )
    if values["rtol"] == 0 and values["atol"] == 0:
        raise ValueError(
            "rtol and atol are both 0: no step could ever be accepted; give at least "
            "one a positive value (e.g. rtol=1e-10, atol=1e-12)"
        )


def check_times(t0: Any, t1: Any, dt: Any) -> None:
    """Finite real times, t1 ≠ t0; a finite, non-zero `dt` pointing from t0 to t1
    that does not ask for ≥ 10⁹ steps. Traced times are not checked."""
    start, end = _concrete_scalar(t0, "t0"), _concrete_scalar(t1, "t1")
    step = None if dt is None else _concrete_scalar(dt, "dt")
    for name, value in (("t0", start), ("t1", end), ("dt", step)):
        if value is not None and not math.isfinite(value):
            raise ValueError(
                f"{name} = {value} is not a finite number; the times of a run must "
                "be finite (a NaN often comes from a computed time: check it)"
            )
    if start is not None and start == end:
        raise ValueError(f"t1 must differ from t0, both are {start}")
    if start is not None and end is not None and abs(end - start) < _TINY:
        raise ValueError(
            f"the span t1 - t0 = {end - start:g} is below the smallest normal float "
            f"({_TINY:g}): no step can resolve it; give a span of a meaningful size "
            "(choose units in which the times are nearer 1)"
        )
    if step is None:
        return
    if step == 0:
        raise ValueError(
            f"dt must be a finite non-zero number, got {step}: pass a step dt > 0 "
            "(or dt=None for adaptive stepping)"
        )
    if start is None or end is None:
        return
    if (end - start) * step < 0:
        raise ValueError(
            f"dt = {step} points away from t1 = {end} (t0 = {start}); use dt of the "
            "same sign as t1 - t0"
        )
    steps = abs(end - start) / abs(step)
    if steps > MAX_FIXED_STEPS:
        raise ValueError(
            f"dt = {step:g} over [{start:g}, {end:g}] means {steps:.3g} steps, more "
            f"than {MAX_FIXED_STEPS:.0e}: the run would never finish. Pass a larger "
            "dt (the scene's own scale is usually 1e-3 to 1e-2 of a period), or "
            "dt=None for adaptive stepping"
        )


# A step must span this many ulps of the largest time. The grid t0 + k·dt rounds
# each step by up to an ulp: at 64 ulps the steps wobble by 1.6 %, which a
# symplectic run still takes at round-off energy error (float32 Kepler, 100
# orbits at 103 ulps, `tests/test_precision.py`); far below, the steps round to
# 0 or one ulp (t0 = 1e15, dt = 0.01: 0.5398 instead of 0.5403 at t0 = 0).
_STEP_IN_ULPS = 64


def check_time_resolution(t0: Any, t1: Any, dt: Any, dtype: Any) -> None:
    """Refuse a `dt` the run's time cannot resolve (t0 = 1e15, dt = 0.01 in float64:
    the times round to steps of 0 or 0.125, and the answer silently differs from
    the same run started at 0); without `dt`, a span the adaptive steps cannot
    resolve (t0 = 1e15, t1 = t0 + 1: 8 ulps wide, and a step shorter than half an
    ulp leaves t where it was, so the controller shrinks it until max_steps)."""
    times = [_concrete_scalar(x, n) for x, n in ((t0, "t0"), (t1, "t1"))]
    step = None if dt is None else _concrete_scalar(dt, "dt")
    if any(x is None for x in times) or (dt is not None and step is None):
        return
    start, end = typing.cast(list[float], times)
    largest = max(abs(start), abs(end))
    ulp = float(np.spacing(np.asarray(largest, dtype=dtype)))
    if step is None:
        if abs(end - start) >= _STEP_IN_ULPS * ulp:
            return
        problem = (
            f"the span [{start:g}, {end:g}] is only {abs(end - start) / ulp:.3g} ulps "
            f"of t wide in {np.dtype(dtype)} (one ulp there is {ulp:g}): adaptive "
            "steps shorter than an ulp cannot advance t, and the run would stall"
        )
    elif abs(step) >= _STEP_IN_ULPS * ulp:
        return
    else:
        problem = (
            f"dt = {step:g} is too fine for times near {largest:g} in "
            f"{np.dtype(dtype)} (one ulp of t there is {ulp:g}): the grid t0 + k·dt "
            "would round each step to a multiple of that ulp, and the run would "
            "take steps of the wrong length"
        )
    raise ValueError(
        f"{problem}. Shift time so the run starts at 0 (t0=0, t1=t1-t0; a system "
        "that uses t can take the offset through args)"
        + (", or use a larger dt" if step is not None else "")
        + (", or run in float64 (y0 as float64, with "
           "jax.config.update('jax_enable_x64', True))"
           if np.dtype(dtype).itemsize < 8 else "")
    )  # fmt: skip


def warn_float64_without_x64(y0: Any) -> None:
    """Warn when float64 data in `y0` will run in float32 (x64 is off)."""
    if jax.config.read("jax_enable_x64"):
        return
    leaves = jax.tree_util.tree_leaves(y0)
    if any(getattr(leaf, "dtype", None) == np.float64 for leaf in leaves):
        warnings.warn(
            "y0 holds float64 values, but JAX's 64-bit mode is off, so the run "
            "works in float32 (about 7 significant digits). To run in float64, "
            'call jax.config.update("jax_enable_x64", True) at the start of the '
            "program, before any JAX array is made",
            stacklevel=3,
        )


# An adaptive run's tolerances must stay above this fraction of the working
# precision's ε. Measured on float32 (ε = 1.2e-7), oscillator to t = 10: at 1e-8
# (the default) Tsit5 takes 95 steps and is good to 1e-7; at 1e-10 Dopri8 takes
# 12 837 steps and its error grows to 2e-6 (round-off of the many steps); at
# 1e-11 it stalls at max_steps. Below ε/100 no digit is gained and the run only
# slows down or stalls.
_TOLERANCE_IN_EPS = 1e-2


def check_tolerance_resolution(rtol: Any, atol: Any, dtype: Any) -> None:
    """Refuse adaptive tolerances the working precision cannot meet (float32 at
    rtol = atol = 1e-12: the error estimate is round-off, every step is
    rejected, and the run ends at max_steps with the wrong remedy)."""
    values = [_concrete_scalar(x, n) for x, n in ((rtol, "rtol"), (atol, "atol"))]
    eps = float(np.finfo(dtype).eps)
    floor = _TOLERANCE_IN_EPS * eps
    if any(x is None or x >= floor for x in values):
        return
    precision = np.dtype(dtype)
    raise ValueError(
        f"rtol = {values[0]:g} and atol = {values[1]:g} are below the resolution "
        f"of {precision} (ε = {eps:.3g}): no step can meet them, so an adaptive "
        f"run would stall until max_steps. Pass rtol ≥ {10 * eps:.1g} (results "
        f"are good to about ε at best)"
        + (" or run in float64 (y0 as float64, with "
           "jax.config.update('jax_enable_x64', True))"
           if precision.itemsize < 8 else "")
    )  # fmt: skip


def check_args_not_nan(args: Any) -> None:
    """Refuse concrete `args` holding NaN: a NaN parameter makes every rate NaN,
    and an adaptive run then rejects every step until max_steps (whose message
    would wrongly say to raise it). Infinite values are left alone: a cutoff or
    wall at infinity can be meant; a run they break is flagged as non-finite."""
    paths = jax.tree_util.tree_flatten_with_path(args)[0]
    for path, leaf in paths:
        if isinstance(leaf, (Tracer, bool, int, str)):
            continue
        try:
            values = np.asarray(leaf)
        except (TypeError, ValueError):
            continue
        if not np.issubdtype(values.dtype, np.inexact):
            continue
        if np.any(np.isnan(values)):
            name = "args" + jax.tree_util.keystr(path)
            raise ValueError(
                f"{name} contains NaN ({values if values.size < 8 else 'array'}): "
                "the equations of motion would be NaN everywhere. Pass finite "
                "parameters (a NaN often comes from a computed value: check it)"
            )


def check_save_times(ts: Any, t0: Any, t1: Any) -> None:
    """`ts`: finite, 1-D, non-empty, ordered from t0 towards t1, inside the span."""
    if ts is None or isinstance(ts, Tracer):
        return
    try:
        times = np.asarray(ts, dtype=float)
    except (TypeError, ValueError):
        raise TypeError(
            f"ts must be an array of times, got {type(ts).__name__}"
        ) from None
    if times.ndim != 1 or times.size == 0:
        raise ValueError(
            f"ts must be a non-empty 1-D array of times, got shape {times.shape}; "
            "e.g. ts=jnp.linspace(t0, t1, 101)"
        )
    bad = np.flatnonzero(~np.isfinite(times))
    if bad.size:
        raise ValueError(
            f"ts[{bad[0]}] = {times[bad[0]]} is not a finite time; every save time "
            "must be a finite number inside [t0, t1]"
        )
    start, end = _concrete_scalar(t0, "t0"), _concrete_scalar(t1, "t1")
    if start is None or end is None:
        return
    direction = 1.0 if end >= start else -1.0
    if np.any(np.diff(times) * direction < 0):
        order = "increasing" if direction > 0 else "decreasing (t1 < t0)"
        raise ValueError(
            f"ts must be sorted, {order}; got {times[:6].tolist()}… — pass np.sort(ts)"
        )
    low, high = min(start, end), max(start, end)
    outside = np.flatnonzero((times < low) | (times > high))
    if outside.size:
        k = outside[0]
        raise ValueError(
            f"ts[{k}] = {times[k]} lies outside [t0, t1] = [{start}, {end}]; save "
            "times must lie inside the run (extend t1 or drop that time)"
        )


def check_save_choice(ts: Any, saveat: Any) -> None:
    """`ts` and `saveat` both say what to save: given together, one would be
    dropped silently (`saveat` wins inside the run)."""
    if ts is None or saveat is None:
        return
    raise ValueError(
        "simulate got both ts and saveat, which both say what to save; pass one: "
        "ts=... alone, or saveat=diffrax.SaveAt(ts=..., ...) with the times inside "
        "it (SaveAt can also combine them with t0=True, t1=True or dense=True)"
    )


def _concrete_scalar(value: Any, name: str) -> float | None:
    """`value` as a Python float, or None when it is traced."""
    if isinstance(value, Tracer):
        return None
    if isinstance(value, (bool, str)):
        raise TypeError(f"{name} must be a real number, got {value!r}")
    try:
        array = np.asarray(value)
    except (TypeError, ValueError):
        raise TypeError(
            f"{name} must be a real number, got {type(value).__name__}"
        ) from None
    if array.shape != ():
        raise ValueError(
            f"{name} must be a scalar, got an array of shape {array.shape}"
        )
    if not (
        np.issubdtype(array.dtype, np.floating)
        or np.issubdtype(array.dtype, np.integer)
    ):
        raise TypeError(f"{name} must be a real number, got {value!r}")
    return float(array)
