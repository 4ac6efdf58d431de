r"""Repeated `simulate(..., solver=lj.Taylor(backend="heyoka"))` calls at the cost
of heyoka's own run: what a first call decided is kept, and a call of the same
structure runs only the checks that read values.

A first call goes the whole way (`taylor_run.run_taylor`): every input check of
`simulate`, the system resolved, its vector field translated into heyoka's
expressions, the integrator compiled. Each later call that way spent 4–8 ms in
Python around heyoka's run (double pendulum to t = 0.01, one core of a loaded
2-core machine, heyoka's own call 0.08 ms; a run to t = 100 takes 2–4 ms on a
quiet one): each access to a method of an equinox Module builds a bound-method
Module whose checks flatten the whole system (~80 µs, a dozen accesses), the
translation cache hashes the system, the batch machinery handles one member as
a block of lanes, and `Trajectory.__init__` flattens the system again. A
repeat spends 0.5 ms there (0.16–0.2 ms on a quieter machine): 1.04× heyoka's
time to t = 100 at tol 1e-12 and 0.99× at 1e-15, where the first-call path
gave 1.60× and 1.31× (`benchmarks/heyoka_peer.py`).

What a first call decides depends on the call's *structure*, which keys a kept
`_Repeat` (least recently used dropped): the system — by identity, as the
translation treats a function like `jax.jit` does (a changed closure is not
seen) —, the tree structure, types, shapes and dtypes of `y0` and `args`,
whether `ts` is given, `rtol`, `atol`, `max_steps`, the solver's fields and
JAX's x64 mode. A later call of that structure checks again only what reads
values:

| check | on a repeat |
|---|---|
| system, solver, `max_steps`, tolerances and their resolution, y0's pair, types and shapes, a constrained system refused | kept: same structure, same verdict |
| t0, t1 finite, distinct, resolvable in the working precision | run again (skipped for the last (t0, t1) that passed) |
| `ts` sorted inside [t0, t1]; `args` free of NaN; `y0` finite; the system's own checks of `y0` (`checked_state_pair`, `check_start`) | run again, with the system's methods fetched once |

A check that fails on a repeat hands the call to the first-call path, which
raises its error the same way; so does anything a repeat does not cover: a
traced input, events, `dt`, `dense`, `saveat` and the other options `run_taylor`
refuses, `t1=None`, and a system with a NumPy array in it (mutable in place, so
its identity does not fix its equations). The run itself is heyoka's: one
`propagate_until` to t1 (`HeyokaRunner.final_state`), or the runner's grid for
`ts`; the `Trajectory` is the first-call path's (`member_trajectory`).

References: F. Biscani & D. Izzo, MNRAS 504 (2021) 2614 (heyoka); the equinox
documentation, `equinox.Module` (bound methods as Modules).
"""

from __future__ import annotations

import numbers
from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import Any

import jax
import numpy as np
from jax.core import Tracer

from lagjax._core.precision import working_dtype
from lagjax._integrate.checks.initial_state import check_initial_state
from lagjax._integrate.checks.inputs import (
    check_args_not_nan,
    check_save_times,
    check_time_resolution,
    check_times,
    warn_float64_without_x64,
)
from lagjax._integrate.checks.late_failure import raise_if_failed
from lagjax._integrate.taylor_heyoka import (
    concrete_pars,
    heyoka_member,
    heyoka_runner,
    member_trajectory,
)
from lagjax._integrate.taylor_run import flat_vector_field, run_taylor
from lagjax.taylor.solver import Taylor
from lagjax.trajectory import Trajectory

KEPT = 32  # call structures remembered, least recently used dropped


def run_taylor_reusing_checks(
    system: Any, y0: Any, t0: Any, t1: Any, dt: Any, solver: Taylor, ts: Any,
    args: Any, rtol: Any, atol: Any, max_steps: Any, throw: bool,
    event: Any = None, **options: Any,
) -> Trajectory:  # fmt: skip
    """`run_taylor`, or a repeat of a heyoka call of the same structure (module
    docstring): the same trajectory, or the same error."""
    covered = (
        solver.backend == "heyoka"
        and dt is None
        and event is None
        and t1 is not None
        and all(value in (None, False) for value in options.values())
    )
    key = (
        _structure(system, y0, t0, t1, solver, ts, args, rtol, atol, max_steps)
        if covered
        else None
    )
    try:
        repeat = None if key is None else _REPEATS.get(key)
    except TypeError:  # an unhashable value in the key: not covered
        key = repeat = None
    if repeat is not None:
        _REPEATS.move_to_end(key)
        trajectory = repeat.run(y0, t0, t1, ts, args, rtol, throw)
        if trajectory is not None:
            return trajectory
    trajectory = run_taylor(system, y0, t0, t1, dt, solver, ts, args, rtol, atol,
                            max_steps, throw, event=event, **options)  # fmt: skip
    if key is not None and repeat is None:
        kept = _Repeat.of(system, y0, solver, ts, args, rtol, atol, max_steps)
        if kept is not None:
            _REPEATS[key] = kept
            while len(_REPEATS) > KEPT:
                _REPEATS.popitem(last=False)
    return trajectory


class _Repeat:
    """What a first call of one structure decided, and a repeat's run."""

    def __init__(
        self, system: Any, resolved: Any, dtype: np.dtype, field: Any, runner: Any,
        max_steps: int,
    ) -> None:  # fmt: skip
        self.system = system  # kept alive: its id is part of the key
        # equinox builds a bound-method Module (flattening the system) on each
        # access of a method: fetched once here
        self.checked_state_pair: Callable = system.checked_state_pair
        self.resolve: Callable = system.resolve
        self.check_start: Callable = resolved.check_start
        self.dtype, self.field, self.runner = dtype, field, runner
        self.integrator = runner.integrator() if runner.final_only else None
        self.max_steps = max_steps
        self.times: tuple[Any, Any] | None = None  # the last (t0, t1) that passed

    @classmethod
    def of(cls, system, y0, solver, ts, args, rtol, atol, max_steps) -> _Repeat | None:
        """After a first call that passed every check: its decisions, or None for
        a system a NumPy array makes mutable."""
        if any(isinstance(x, np.ndarray) for x in jax.tree_util.tree_leaves(system)):
            return None
        dtype = working_dtype(check_initial_state(system, y0))
        resolved, resolved_args = system.resolve(args)
        state = jax.tree_util.tree_map(lambda x: np.asarray(x, dtype), tuple(y0))
        field, flat0, _ = flat_vector_field(resolved, state)
        steps = max_steps or solver.max_steps
        rtol = rtol if solver.rtol is None else solver.rtol
        atol = atol if solver.atol is None else solver.atol
        runner, _ = heyoka_runner(field, flat0.shape[0], resolved_args, solver, rtol,
                                  atol, steps, None, final_only=ts is None)  # fmt: skip
        return cls(system, resolved, dtype, field, runner, steps)

    def run(self, y0, t0, t1, ts, args, rtol, throw) -> Trajectory | None:
        """The run from these values, or None where a check refused them (the
        first-call path then raises)."""
        try:
            checked = self._checked(y0, t0, t1, ts, args)
        except (TypeError, ValueError):
            return None
        if checked is None:
            return None
        flat0, system, args = checked
        if ts is None:  # the times in the run's dtype, as `heyoka_member` has them
            pars = concrete_pars(args, self.dtype)
            start, end = self.dtype.type(t0), self.dtype.type(t1)
            rows = self.runner.final_state(self.integrator, flat0, pars, start, end)
        else:
            save_ts = np.asarray(ts, dtype=self.dtype)
            rows = heyoka_member(self.runner, flat0, args, t0, t1, save_ts)
        trajectory = member_trajectory(self.field, rows, None, self.max_steps,
                                       system, args)  # fmt: skip
        return (
            raise_if_failed(trajectory, self.max_steps, rtol) if throw else trajectory
        )

    def _checked(self, y0, t0, t1, ts, args) -> tuple[np.ndarray, Any, Any] | None:
        """The checks that read values (module docstring), `simulate`'s own; the
        flat start in the working dtype, the resolved system and `args`."""
        if (t0, t1) != self.times:
            check_times(t0, t1, None)
            check_time_resolution(t0, t1, None, self.dtype)
            self.times = (t0, t1)
        check_save_times(ts, t0, t1)
        if args is not None:  # None holds no NaN (and its check's first call is cold)
            check_args_not_nan(args)
        warn_float64_without_x64(y0)
        pair = self.checked_state_pair(*y0)
        leaves, treedef = jax.tree_util.tree_flatten(pair)
        leaves = [np.asarray(x, dtype=self.dtype) for x in leaves]
        flat0 = np.concatenate([np.ravel(x) for x in leaves])
        if not np.isfinite(flat0).all():
            return None
        system, args = self.resolve(args)
        self.check_start(jax.tree_util.tree_unflatten(treedef, leaves), t0, args,
                         self.dtype)  # fmt: skip
        return flat0, system, args


_REPEATS: OrderedDict[Hashable, _Repeat] = OrderedDict()


def _structure(system, y0, t0, t1, solver, ts, args, rtol, atol, max_steps):
    """The key of a call's structure (module docstring), or None for a call a
    repeat does not cover: traced or non-numeric times, traced leaves (and,
    found on look-up, anything unhashable)."""
    if not all(_real_number(t) for t in (t0, t1)) or isinstance(ts, Tracer):
        return None
    y0_leaves, y0_tree = jax.tree_util.tree_flatten(y0)
    args_leaves, args_tree = jax.tree_util.tree_flatten(args)
    if any(isinstance(x, Tracer) for x in (*y0_leaves, *args_leaves)):
        return None
    return (
        id(system), y0_tree, _leaf_types(y0_leaves), args_tree,
        _leaf_types(args_leaves), ts is None, rtol, atol, max_steps,
        _solver_fields(solver), bool(jax.config.read("jax_enable_x64")),
    )  # fmt: skip


def _real_number(value: Any) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def _leaf_types(leaves: list[Any]) -> tuple:
    return tuple((type(x), np.shape(x), getattr(x, "dtype", None)) for x in leaves)


def _solver_fields(solver: Taylor) -> tuple:
    """Every field of `solver`: its static ones in the tree structure (a
    flatten reads the fields at a tenth of the cost of attribute access on an
    equinox Module), kept per solver (a Module is immutable): the flatten's
    first call after a heyoka run costs 65 µs, cold."""
    kept = _SOLVERS.get(id(solver))
    if kept is not None and kept[0] is solver:
        return kept[1]
    leaves, structure = jax.tree_util.tree_flatten(solver)
    fields = (structure, *leaves)
    _SOLVERS[id(solver)] = (solver, fields)  # the solver kept: its id stays its own
    while len(_SOLVERS) > KEPT:
        _SOLVERS.pop(next(iter(_SOLVERS)))
    return fields


_SOLVERS: dict[int, tuple[Taylor, tuple]] = {}
