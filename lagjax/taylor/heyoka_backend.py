r"""Taylor integration on the CPU by heyoka, from a lagjax vector field.

heyoka (Biscani & Izzo 2021) integrates an ODE system by Taylor's method with
adaptive order and step: at each step it computes the Taylor coefficients of the
solution to an order set by the tolerance (about $-\tfrac12 \ln\varepsilon + 1$)
through the recurrences of its elementary operations (Jorba & Zou 2005), compiled
by LLVM, and picks the step from the last two coefficients. Its batch mode runs
`batch_size` members side by side in the SIMD lanes, each with its own step.

This module runs lagjax's derived equations there: `vector_field(t, y, args)` is
translated once into heyoka's expressions (`heyoka_expressions.jaxpr_to_heyoka`),
every scalar of `args` a heyoka parameter, and compiled once per (system,
tolerance, batch size, precision) — a new `y0`, time span or `args` reuses the
compiled integrator. The translation is cached per function (like `jax.jit`, a
function is traced once per signature: a changed closure is not seen; pass what
changes in `args`).

**Tolerance.** heyoka takes one tolerance ε and keeps the local error below
ε·max(1, ‖y‖∞): absolute for a state of norm below one, relative above. The
`rtol`/`atol` of lagjax map to ε = min(rtol, atol) — never looser than either at
unit scale; pass `tol=` to set ε directly.

**Outside JAX.** heyoka is compiled C++: it runs on NumPy values, not under
`jax.jit`, `jax.grad` or `jax.vmap`. A traced input is refused by name; use the
JAX-native `lj.Taylor` (or `lj.simulate`) for gradients and transformations, and
`heyoka_integrate_batch` for batches.

heyoka is optional (`pip install heyoka`, or the `heyoka` extra); it is imported
when a function here is first called.

References: F. Biscani & D. Izzo, "Revisiting high-order Taylor methods for
astrodynamics and celestial mechanics", MNRAS 504 (2021) 2614; À. Jorba & M. Zou,
"A software package for the numerical integration of ODEs by means of high-order
Taylor methods", Experimental Mathematics 14 (2005) 99.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import Any, NamedTuple

import jax
import numpy as np

from lagjax.taylor.heyoka_expressions import (
    HeyokaSystem,
    flatten_args,
    import_heyoka,
    jaxpr_to_heyoka,
)
from lagjax.taylor.heyoka_rules import UnsupportedPrimitiveError

__all__ = [
    "HeyokaSolution",
    "UnsupportedPrimitiveError",
    "heyoka_cache_info",
    "heyoka_integrate",
    "heyoka_integrate_batch",
    "heyoka_tolerance",
    "jaxpr_to_heyoka",
]

CACHE_SIZE = 32  # translations and compiled integrators kept, least recent dropped
# State dimension above which heyoka compiles in compact mode (loops over the
# operations instead of straight-line code). Measured, 4-link pendulum (dimension
# 8): straight-line 15 s to compile, 10 ms to run; compact 2.3 s and 24 ms.
COMPACT_ABOVE = 6
DEFAULT_MAX_STEPS = 100_000

VectorField = Callable[[Any, Any, Any], Any]


class HeyokaSolution(NamedTuple):
    """A heyoka run: `ts` (T,), `ys` (T, n) — or (B, T, n) for a batch —,
    `num_steps` and `status` (heyoka's outcome: "time_limit" when the run reached
    its end, "step_limit" when it ran out of `max_steps`, "err_nf_state" when the
    state became non-finite), one per member for a batch."""

    ts: np.ndarray
    ys: np.ndarray
    num_steps: Any
    status: Any


class _Caches:
    """Translations per function and signature; integrators per system."""

    def __init__(self) -> None:
        self.systems: OrderedDict[Hashable, HeyokaSystem] = OrderedDict()
        self.integrators: OrderedDict[Hashable, Any] = OrderedDict()
        self.translations = 0
        self.compilations = 0


_CACHES = _Caches()


def heyoka_cache_info() -> dict[str, int]:
    """How many translations and compilations this process has made so far."""
    return dict(translations=_CACHES.translations, compilations=_CACHES.compilations)


def heyoka_tolerance(rtol: float, atol: float, tol: float | None = None) -> float:
    """heyoka's single tolerance for lagjax's `rtol`, `atol`: min(rtol, atol), or
    `tol` where given; a tolerance that is not a finite positive number is refused."""
    for name, value in (("rtol", rtol), ("atol", atol), ("tol", tol)):
        if value is not None and not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a finite positive number, got {value}.")
    return float(tol) if tol is not None else float(min(rtol, atol))


def heyoka_integrate(
    vector_field: VectorField,
    y0: Any,
    t0: float,
    t1: float,
    *,
    ts: Any = None,
    args: Any = None,
    rtol: float = 1e-12,
    atol: float = 1e-12,
    tol: float | None = None,
    max_steps: int = DEFAULT_MAX_STEPS,
    throw: bool = True,
    fp_type: Any = np.float64,
    compact_mode: bool | None = None,
) -> HeyokaSolution:
    """Integrate y' = `vector_field(t, y, args)` from `y0` (shape (n,)) at `t0` to
    `t1` with heyoka's adaptive Taylor method.

    - `ts`: times to save at (monotonic, between t0 and t1); default only t1.
    - `rtol`, `atol`, `tol`: see `heyoka_tolerance`.
    - `max_steps`: steps allowed over the whole run.
    - `throw`: raise on failure; with False, return what was computed (rows not
      reached are NaN) and the outcome in `status`.
    - `fp_type`: `np.float64`, or `np.longdouble` for a reference (heyoka in
      extended precision; the translated constants stay double).
    - `compact_mode`: heyoka's compact mode (faster to compile, slower to run);
      default for state dimensions above `COMPACT_ABOVE`.
    """
    _refuse_traced("heyoka_integrate", y0=y0, t0=t0, t1=t1, ts=ts, args=args)
    y0 = np.asarray(y0, dtype=fp_type)
    if y0.ndim != 1:
        raise ValueError(f"y0 must be one state of shape (n,); got shape {y0.shape}.")
    system = _translate(vector_field, y0.shape[0], args)
    ta = _integrator(
        system, heyoka_tolerance(rtol, atol, tol), 1, fp_type, compact_mode
    )
    ta.time, ta.state[:] = fp_type(t0), y0
    ta.pars[:] = flatten_args(args).astype(fp_type)
    grid = _save_times(ts, t0, t1, fp_type)
    status, steps = "time_limit", 0
    if grid[0] != t0:
        outcome, _, _, steps, *_ = ta.propagate_until(grid[0], max_steps=max_steps)
        status = outcome.name
    rows = np.full((grid.shape[0], y0.shape[0]), np.nan, dtype=fp_type)
    if grid.size == 1 and status == "time_limit":
        rows[0] = ta.state
    elif status == "time_limit":
        outcome, _, _, more, _, states = ta.propagate_grid(
            grid, max_steps=max(max_steps - steps, 1)
        )
        status, steps = outcome.name, steps + more
        rows[: states.shape[0]] = states
    _check(status, throw, max_steps, system)
    return HeyokaSolution(grid, rows, steps, status)


def heyoka_integrate_batch(
    vector_field: VectorField,
    y0s: Any,
    t0: float,
    t1: float,
    *,
    ts: Any = None,
    args: Any = None,
    args_batch: Any = None,
    rtol: float = 1e-12,
    atol: float = 1e-12,
    tol: float | None = None,
    max_steps: int = DEFAULT_MAX_STEPS,
    throw: bool = True,
    batch_size: int | None = None,
    fp_type: Any = np.float64,
    compact_mode: bool | None = None,
) -> HeyokaSolution:
    """`heyoka_integrate` for every row of `y0s` (B, n), on heyoka's batch mode.

    - `args_batch`: parameters with a leading batch axis on every leaf (as for
      `lj.sweep`), or None to share `args` across the batch.
    - `batch_size`: members per SIMD batch; default heyoka's recommended SIMD
      width (`heyoka.recommended_simd_size()`); the batch runs in chunks of that
      size, the last one padded with copies of its final member.

    Each member takes its own steps, so results equal single runs up to rounding.
    """
    _refuse_traced(
        "heyoka_integrate_batch",
        y0s=y0s,
        t0=t0,
        t1=t1,
        ts=ts,
        args=args,
        args_batch=args_batch,
    )
    hy = import_heyoka()
    y0s = np.asarray(y0s, dtype=fp_type)
    if y0s.ndim != 2:
        raise ValueError(f"y0s must have shape (B, n); got shape {y0s.shape}.")
    members, n = y0s.shape
    pars = _batch_pars(args, args_batch, members).astype(fp_type)
    example = args if args_batch is None else _first_member(args_batch)
    system = _translate(vector_field, n, example)
    width = batch_size or hy.recommended_simd_size(fp_type=fp_type)
    ta = _integrator(
        system, heyoka_tolerance(rtol, atol, tol), width, fp_type, compact_mode
    )
    grid = _save_times(ts, t0, t1, fp_type)
    ys = np.full((members, grid.shape[0], n), np.nan, dtype=fp_type)
    steps, status = np.zeros(members, int), np.empty(members, dtype=object)
    for start in range(0, members, width):
        chunk = np.minimum(np.arange(start, start + width), members - 1)
        live = chunk[: min(width, members - start)]
        rows, chunk_steps, chunk_status = _run_chunk(
            ta, y0s[chunk], pars[chunk], t0, grid, max_steps
        )
        ys[live], steps[live] = rows[: live.size], chunk_steps[: live.size]
        status[live] = chunk_status[: live.size]
    for outcome in dict.fromkeys(status):
        _check(outcome, throw, max_steps, system)
    return HeyokaSolution(grid, ys, steps, status)


def _run_chunk(
    ta: Any,
    y0s: np.ndarray,
    pars: np.ndarray,
    t0: float,
    grid: np.ndarray,
    max_steps: int,
):
    """One SIMD batch from `t0` over `grid`: states (width, T, n), steps, outcomes."""
    width = y0s.shape[0]
    ta.set_time(np.full(width, t0, dtype=y0s.dtype))
    ta.state[:] = y0s.T
    ta.pars[:] = pars.T
    steps = np.zeros(width, int)
    if grid[0] != t0:
        ta.propagate_until(grid[0], max_steps=max_steps)
        steps += [res[3] for res in ta.propagate_res]
    rows = np.full((width, grid.shape[0], y0s.shape[1]), np.nan, dtype=y0s.dtype)
    if grid[0] != t0:
        outcomes = np.array([res[0].name for res in ta.propagate_res], dtype=object)
        if grid.size == 1 or set(outcomes) != {"time_limit"}:
            reached = outcomes == "time_limit"
            rows[reached, 0] = ta.state.T[reached]
            return rows, steps, outcomes
    block = np.repeat(grid[:, None], width, axis=1)
    _, states = ta.propagate_grid(block, max_steps=max_steps)
    steps += [res[3] for res in ta.propagate_res]
    outcomes = np.array([res[0].name for res in ta.propagate_res], dtype=object)
    rows[:, : states.shape[0]] = np.transpose(states, (2, 0, 1))
    return rows, steps, outcomes


def _refuse_traced(function: str, **values: Any) -> None:
    for name, value in values.items():
        if any(
            isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(value)
        ):
            raise TypeError(
                f"{function} got a traced `{name}`: heyoka runs compiled C++ on NumPy "
                "values and cannot be used under jax.jit, jax.grad or jax.vmap. For "
                "gradients and JAX transformations use the JAX-native lj.Taylor (or "
                "lj.simulate); for many initial states, heyoka_integrate_batch."
            )


def _check(status: str, throw: bool, max_steps: int, system: HeyokaSystem) -> None:
    if not throw or status == "time_limit":
        return
    if status == "step_limit":
        raise RuntimeError(
            f"heyoka reached max_steps = {max_steps} before the end of the run; "
            "raise max_steps (or pass throw=False to keep what was computed)."
        )
    if status == "err_nf_state":
        where = (
            f" It may have reached a state where the vector field needs a branch "
            f"the backend replaced by NaN (primitives {sorted(set(system.poisoned))})"
            if system.poisoned
            else ""
        )
        raise FloatingPointError(
            "the state became non-finite during the heyoka run (a singular mass "
            f"matrix, a collision, a blow-up).{where} Pass throw=False to keep what "
            "was computed."
        )
    raise RuntimeError(f"heyoka stopped with outcome {status}.")


def _save_times(ts: Any, t0: float, t1: float, fp_type: Any) -> np.ndarray:
    grid = np.array([t1] if ts is None else ts, dtype=fp_type).ravel()
    forward = t1 >= t0
    steps = np.diff(np.concatenate([[t0], grid, [t1]]))
    if grid.size == 0 or not np.all(steps >= 0 if forward else steps <= 0):
        raise ValueError("ts must be monotonic and lie between t0 and t1.")
    return grid


def _batch_pars(args: Any, args_batch: Any, members: int) -> np.ndarray:
    if args_batch is None:
        return np.tile(flatten_args(args), (members, 1))
    leaves = jax.tree_util.tree_leaves(args_batch)
    if any(np.shape(leaf)[:1] != (members,) for leaf in leaves):
        raise ValueError(f"every leaf of args_batch needs a leading axis of {members}.")
    return np.stack([flatten_args(_member(args_batch, i)) for i in range(members)])


def _member(tree: Any, i: int) -> Any:
    return jax.tree_util.tree_map(lambda leaf: np.asarray(leaf)[i], tree)


def _first_member(tree: Any) -> Any:
    return _member(tree, 0)


def _signature(args: Any) -> Hashable:
    leaves, treedef = jax.tree_util.tree_flatten(args)
    return treedef, tuple((np.shape(x), np.asarray(x).dtype.str) for x in leaves)


def _translate(vector_field: VectorField, n: int, args: Any) -> HeyokaSystem:
    """The translation of `vector_field`, cached per function and signature."""
    try:
        key = (vector_field, n, _signature(args))
        hash(key)
    except TypeError:
        key = None
    if key is not None and key in _CACHES.systems:
        _CACHES.systems.move_to_end(key)
        return _CACHES.systems[key]
    system = jaxpr_to_heyoka(vector_field, n, args)
    _CACHES.translations += 1
    if key is not None:
        _remember(_CACHES.systems, key, system)
    return system


def _integrator(
    system: HeyokaSystem,
    tol: float,
    width: int,
    fp_type: Any,
    compact_mode: bool | None,
) -> Any:
    """A compiled heyoka integrator for `system`, cached per system, tolerance,
    batch width and precision (the expressions are the key: a function traced
    anew to the same equations reuses the compilation)."""
    hy = import_heyoka()
    key = (system.key, tol, width, np.dtype(fp_type).str, compact_mode)
    if key in _CACHES.integrators:
        _CACHES.integrators.move_to_end(key)
        return _CACHES.integrators[key]
    n = len(system.equations)
    compact = n > COMPACT_ABOVE if compact_mode is None else compact_mode
    options = dict(tol=fp_type(tol), compact_mode=compact, fp_type=fp_type)
    if width == 1:
        ta = hy.taylor_adaptive(
            list(system.equations),
            np.zeros(n, fp_type),
            pars=np.zeros(system.num_pars, fp_type),
            **options,
        )
    else:
        ta = hy.taylor_adaptive_batch(
            list(system.equations),
            np.zeros((n, width), fp_type),
            pars=np.zeros((system.num_pars, width), fp_type),
            **options,
        )
    _CACHES.compilations += 1
    _remember(_CACHES.integrators, key, ta)
    return ta


def _remember(cache: OrderedDict, key: Hashable, value: Any) -> None:
    cache[key] = value
    while len(cache) > CACHE_SIZE:
        cache.popitem(last=False)
