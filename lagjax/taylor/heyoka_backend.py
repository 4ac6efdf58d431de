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
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import numpy as np
from jax.core import Tracer

from lagjax.taylor.heyoka_cache import heyoka_cache_info, translated
from lagjax.taylor.heyoka_expressions import (
    HeyokaSystem,
    flatten_args,
    jaxpr_to_heyoka,
)
from lagjax.taylor.heyoka_rules import UnsupportedPrimitiveError
from lagjax.taylor.heyoka_runs import HeyokaRunner, outcome_name

__all__ = [
    "HeyokaSolution",
    "UnsupportedPrimitiveError",
    "heyoka_cache_info",
    "heyoka_integrate",
    "heyoka_integrate_batch",
    "heyoka_tolerance",
    "jaxpr_to_heyoka",
]

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
    run = heyoka_integrate_batch(
        vector_field, y0[None], t0, t1, ts=ts, args=args, rtol=rtol, atol=atol,
        tol=tol, max_steps=max_steps, throw=throw, fp_type=fp_type,
        compact_mode=compact_mode,
    )  # fmt: skip
    return HeyokaSolution(run.ts, run.ys[0], int(run.num_steps[0]), run.status[0])


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
    y0s = np.asarray(y0s, dtype=fp_type)
    if y0s.ndim != 2:
        raise ValueError(f"y0s must have shape (B, n); got shape {y0s.shape}.")
    members, n = y0s.shape
    pars = _batch_pars(args, args_batch, members).astype(fp_type)
    example = args if args_batch is None else _first_member(args_batch)
    system = translated(vector_field, n, example)
    grid = _save_times(ts, t0, t1, fp_type)
    runner = HeyokaRunner(
        system, heyoka_tolerance(rtol, atol, tol), max_steps, final_only=ts is None,
        fp_type=fp_type, compact_mode=compact_mode, batch_size=batch_size,
    )  # fmt: skip
    rows = runner(y0s, pars, np.full(members, t0), np.full(members, t1),
                  np.tile(grid, (members, 1)))  # fmt: skip
    names = {code: outcome_name(code) for code in np.unique(rows.codes)}
    status = np.array([names[code] for code in rows.codes], dtype=object)
    for outcome in dict.fromkeys(status):
        _check(outcome, throw, max_steps, system)
    return HeyokaSolution(grid, rows.ys, rows.num_steps, status)


def _refuse_traced(function: str, **values: Any) -> None:
    for name, value in values.items():
        if any(isinstance(x, Tracer) for x in jax.tree_util.tree_leaves(value)):
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
