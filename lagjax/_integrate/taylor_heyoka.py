"""`simulate` with `lj.Taylor(backend="heyoka")`: a system's run, and its events,
on heyoka's compiled Taylor integrator.

The vector field on the flat state y (`taylor_run.FlatVectorField`) is translated
into heyoka's expressions once per system and `args` signature, every scalar of
`args` a heyoka parameter (`lagjax.taylor.heyoka_cache`); the run is a
`HeyokaRunner` (`lagjax.taylor.heyoka_runs`) reached directly for concrete inputs
and through `jax.pure_callback` under `jit`/`vmap`, where a whole `vmap` batch is
one call of heyoka's batch mode (`lagjax.taylor.heyoka_callback`).

**Events.** `event=diffrax.Event(cond_fn, direction=...)` with real-valued
conditions `cond_fn(t, y, args)` — `y` in `y0`'s convention, as for every other
solver — become heyoka terminal events: each condition's jaxpr is translated
like the vector field, and heyoka finds its zero on every step's Taylor
polynomial (to machine precision; `root_finder` is not needed). The run ends at
the first event: `result` is `RESULTS.event_occurred`, `stats["event_mask"]`
says which condition fired, and the saves are those of diffrax: with `ts`, the
ones before the event (the rest t = inf); without, the state at the event.

References: F. Biscani & D. Izzo, "Revisiting high-order Taylor methods for
astrodynamics and celestial mechanics", MNRAS 504 (2021) 2614 (event detection
on the Taylor polynomial); the diffrax documentation, `diffrax.Event`.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
from jax.core import Tracer

from lagjax.taylor.heyoka_backend import heyoka_tolerance
from lagjax.taylor.heyoka_cache import translated
from lagjax.taylor.heyoka_callback import heyoka_member_run
from lagjax.taylor.heyoka_expressions import translate_function
from lagjax.taylor.heyoka_runs import (
    BAD_TIMES,
    FIRST_EVENT,
    NON_FINITE,
    STEP_LIMIT,
    SUCCESS,
    HeyokaEvent,
    HeyokaRunner,
    Rows,
    outcome_name,
)
from lagjax.taylor.solver import Taylor
from lagjax.trajectory import Trajectory

SOLVER_NAME = "Taylor[heyoka]"

BAD_TIMES_MESSAGE = (
    "lj.Taylor(backend='heyoka'): the save times ts must be strictly ordered from "
    "t0 to t1"
)


def heyoka_runner(
    field: Any, n: int, args: Any, solver: Taylor, rtol: float, atol: float,
    max_steps: int, event: Any, final_only: bool,
) -> tuple[HeyokaRunner, Any]:  # fmt: skip
    """The run configuration, and the structure of the event's conditions (None
    without an event)."""
    example = _shapes(args)
    system = translated(field, n, example)
    events, structure = _events(event, field, n, example)
    tol = heyoka_tolerance(_concrete("rtol", rtol), _concrete("atol", atol))
    runner = HeyokaRunner(system, tol, max_steps, events, final_only)
    return runner, structure


def heyoka_member(
    runner: HeyokaRunner, flat0: Any, args: Any, t0: Any, t1: Any, ts: Any
) -> Rows:
    """One member's `Rows` (see `heyoka_callback.heyoka_member_run`)."""
    dtype = flat0.dtype
    grid = (t1 if ts is None else ts, t0, t1)
    if any(isinstance(x, Tracer) for x in jax.tree_util.tree_leaves(
        (flat0, args, grid)
    )):  # fmt: skip
        leaves = [jnp.ravel(x).astype(dtype) for x in jax.tree_util.tree_leaves(args)]
        pars = jnp.concatenate(leaves) if leaves else jnp.zeros(0, dtype)
        times = jnp.atleast_1d(jnp.asarray(grid[0], dtype))
        t0, t1 = jnp.asarray(t0, dtype), jnp.asarray(t1, dtype)
    else:  # the times in the run's dtype, as traced ones: t1 is the last save
        pars = concrete_pars(args, dtype)
        times = np.atleast_1d(np.asarray(grid[0], dtype))
        t0, t1 = np.asarray(t0, dtype), np.asarray(t1, dtype)
    return heyoka_member_run(runner, flat0, pars, t0, t1, times)


def concrete_pars(args: Any, dtype: Any) -> np.ndarray:
    """Every scalar of concrete `args` in `dtype`, in the order of heyoka's
    parameters."""
    leaves = [np.ravel(x).astype(dtype) for x in jax.tree_util.tree_leaves(args)]
    return np.concatenate(leaves) if leaves else np.zeros(0, dtype)


def member_trajectory(
    field: Any, rows: Rows, structure: Any, max_steps: int, system: Any, args: Any
) -> Trajectory:
    """The `Trajectory` of one member's rows: each flat state unravelled to
    (q, second) by the vector field's layout (`taylor_run.FlatVectorField`), in
    NumPy for concrete rows; the statistics of `run_statistics`, `bad_times`
    among them."""
    stats = run_statistics(rows, structure, max_steps)
    stats["bad_times"] = bad_times(rows)
    result = stats.pop("result")
    if isinstance(rows.ys, np.ndarray):  # NumPy to the end on the CPU route
        ys = rows_as_states(field.layout, rows.ys)
    else:
        ys = jax.vmap(field.unravel)(rows.ys)
    return _trajectory(rows.ts, ys, system, args, stats, result)


def rows_as_states(layout: tuple, flat_ys: np.ndarray) -> Any:
    """Each row of `flat_ys` as (q, second), in NumPy, a leading axis per leaf;
    `layout` is (treedef, shapes, dtypes) of the state."""
    treedef, shapes, _ = layout
    count, start, leaves = len(flat_ys), 0, []
    for shape in shapes:  # views, by slicing (np.split costs 10x on a few leaves)
        end = start + math.prod(shape)
        leaves.append(flat_ys[:, start:end].reshape((count, *shape)))
        start = end
    return jax.tree_util.tree_unflatten(treedef, leaves)


_TRAJECTORY_FIELDS = ("ts", "ys", "system", "args", "run_stats", "result")


@functools.cache
def _trajectory_structure() -> tuple[Any, list[int]]:
    """A heyoka `Trajectory`'s tree structure with each field a leaf, and which
    field each leaf is (`_TRAJECTORY_FIELDS`; dense output last)."""
    marks: dict[str, Any] = {name: i for i, name in enumerate(_TRAJECTORY_FIELDS)}
    marked = Trajectory(
        solver_name=SOLVER_NAME, dense_output=len(_TRAJECTORY_FIELDS), **marks
    )
    leaves, structure = jax.tree_util.tree_flatten(marked)
    return structure, leaves


def _trajectory(ts, ys, system, args, stats, result) -> Trajectory:
    """`Trajectory(...)` of a heyoka run, built the way JAX rebuilds a jitted
    function's output (`tree_unflatten`): equinox's `__init__` flattens every
    field, the system's functions included, for its checks — 0.2 ms a call, a
    tenth of a 2 ms heyoka run — and a Trajectory has no invariant to check.
    (Setting the fields on a bare object, as equinox's unflatten does inside,
    saved another 25 µs of a 4 ms run: not worth leaning on equinox's internals.)"""
    structure, fields = _trajectory_structure()
    values = (ts, ys, system, args, stats, result, None)
    return jax.tree_util.tree_unflatten(structure, [values[i] for i in fields])


def run_statistics(rows: Rows, structure: Any, max_steps: int) -> dict[str, Any]:
    """`traj.stats` of a heyoka run (NumPy for concrete rows, JAX for traced),
    and its `diffrax.RESULTS`, under the key "result"."""
    codes = rows.codes
    if structure is None and isinstance(codes, np.ndarray) and codes.ndim == 0:
        return _one_member_statistics(rows, max_steps)
    return _statistics(rows, structure, max_steps)


def _statistics(rows: Rows, structure: Any, max_steps: int) -> dict[str, Any]:
    """`run_statistics` for any rows: a batch, traced, or with events."""
    codes = rows.codes
    xp = np if isinstance(codes, np.ndarray) else jnp
    unused = xp.isinf(rows.ts)[..., None]  # saves after an event
    stats: dict[str, Any] = {
        "num_steps": rows.num_steps,
        "num_accepted_steps": rows.num_steps,
        "num_rejected_steps": 0 * rows.num_steps,
        "max_steps": max_steps,
        "finite": (xp.isfinite(rows.ys) | unused).all(axis=(-2, -1)),
        "succeeded": (codes == SUCCESS) | (codes >= FIRST_EVENT),
        "result": _as_result(codes),
    }
    if structure is not None:
        count = structure.num_leaves
        fired = [codes == FIRST_EVENT + i for i in range(count)]
        stats["event_mask"] = jax.tree_util.tree_unflatten(structure, fired)
    if xp is np and codes.ndim == 0:
        stats["heyoka_status"] = outcome_name(codes)
    return stats


def _one_member_statistics(rows: Rows, max_steps: int) -> dict[str, Any]:
    """`run_statistics` of one concrete member's run without events, the same
    values and types, on Python values: no event, no save after one (no t = inf
    to exempt), the code one integer, and a small state's finiteness read from
    its floats. After a heyoka run each NumPy
    function's first call is cold (caches and predictors full of heyoka's loop,
    10–100 µs a call): the general path cost 0.18 ms a call there, a twentieth
    of the double pendulum's run to t = 100."""
    code, steps = int(rows.codes), rows.num_steps
    return {
        "num_steps": steps,
        "num_accepted_steps": steps,
        "num_rejected_steps": steps.dtype.type(0),  # the type of 0 * steps
        "max_steps": max_steps,
        "finite": all_finite(rows.ys),
        "succeeded": np.bool_(code == SUCCESS or code >= FIRST_EVENT),
        "result": _result_of(code),
        "heyoka_status": outcome_name(code),
    }


def all_finite(ys: np.ndarray) -> np.bool_:
    """`np.isfinite(ys).all()`; for a few float64 or float32 values, from their
    Python floats (one NumPy call, not two ufuncs)."""
    if ys.size <= _FEW and ys.dtype.type in (np.float64, np.float32):
        return np.bool_(all(map(math.isfinite, ys.ravel().tolist())))
    return np.isfinite(ys).all()


_FEW = 64  # values whose check in Python stays under a cold ufunc's cost


_RESULTS = {
    SUCCESS: diffrax.RESULTS.successful,
    STEP_LIMIT: diffrax.RESULTS.max_steps_reached,
    NON_FINITE: diffrax.RESULTS.nonfinite,
}


def _as_result(codes: Any) -> Any:
    """Outcome codes as `diffrax.RESULTS`: by look-up for one concrete code (no
    JAX dispatch), by `where` for traced or batched codes."""
    if isinstance(codes, np.ndarray) and codes.ndim == 0:
        return _result_of(int(codes))
    where = diffrax.RESULTS.where
    return where(
        (codes == SUCCESS),
        diffrax.RESULTS.successful,
        where(
            codes >= FIRST_EVENT,
            diffrax.RESULTS.event_occurred,
            where(
                codes == STEP_LIMIT,
                diffrax.RESULTS.max_steps_reached,
                where(
                    codes == NON_FINITE,
                    diffrax.RESULTS.nonfinite,  # pyright: ignore[reportArgumentType]
                    diffrax.RESULTS.internal_error,
                ),
            ),
        ),
    )


def _result_of(code: int) -> Any:
    """One outcome code's `diffrax.RESULTS`."""
    if code >= FIRST_EVENT:
        return diffrax.RESULTS.event_occurred
    result = _RESULTS.get(code)
    return diffrax.RESULTS.internal_error if result is None else result


def bad_times(rows: Rows) -> Any:
    """Where the save times were refused; for one concrete code, compared in
    Python (the same `np.bool_`)."""
    codes = rows.codes
    if isinstance(codes, np.ndarray) and codes.ndim == 0:
        return np.bool_(int(codes) == BAD_TIMES)
    return codes == BAD_TIMES


def _shapes(args: Any) -> Any:
    """`args` as shapes and dtypes: what the translation depends on."""
    return jax.tree_util.tree_map(
        lambda x: jax.ShapeDtypeStruct(np.shape(x), jnp.result_type(x)), args
    )


def _concrete(name: str, value: Any) -> float:
    if isinstance(value, Tracer):
        raise TypeError(
            f"lj.Taylor(backend='heyoka') compiles heyoka's integrator for one "
            f"tolerance: {name} must be a number, not a traced value"
        )
    return float(value)


def _events(event: Any, field: Any, n: int, example: Any):
    """The event's conditions as heyoka events, and their structure."""
    if event is None:
        return (), None
    if not isinstance(event, diffrax.Event):
        raise TypeError(
            f"event must be a diffrax.Event (diffrax.Event(cond_fn)), got "
            f"{type(event).__name__}"
        )
    conditions, structure = jax.tree_util.tree_flatten(event.cond_fn, is_leaf=callable)
    direction = event.direction
    if direction is None or isinstance(direction, bool):
        directions = [direction] * len(conditions)
    else:
        directions = jax.tree_util.tree_leaves(direction, is_leaf=lambda x: x is None)
    events = tuple(
        HeyokaEvent(_condition(fn, field, n, example), {None: 0, True: 1, False: -1}[d])
        for fn, d in zip(conditions, directions, strict=True)
    )
    return events, structure


def _condition(fn: Any, field: Any, n: int, example: Any) -> Any:
    """One condition g(t, y, args), y in `y0`'s convention, as an expression."""

    def on_flat_state(t, y, args):
        return jnp.asarray(fn(t, field.unravel(y), args))

    elements, shape, dtype, *_ = translate_function(on_flat_state, n, example)
    if shape != () or not jnp.issubdtype(dtype, jnp.floating):
        raise ValueError(
            "lj.Taylor(backend='heyoka') locates an event where a real-valued "
            "condition crosses zero (on the step's Taylor polynomial); this "
            f"condition returns {dtype}{list(shape)}. Return one float, e.g. "
            "`lambda t, y, args: y[0]` rather than `y[0] < 0`."
        )
    return elements[0]
