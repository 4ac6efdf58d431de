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
| system, solver, `max_steps`, tolerances and their resolution, y0's pair, types and shapes (the default `checked_state_pair`), a constrained system refused | kept: same structure, same verdict |
| t0, t1 finite, distinct, resolvable in the working precision | run again (skipped for the last (t0, t1) that passed) |
| `ts` sorted inside [t0, t1]; `args` free of NaN; `y0` finite; the system's own checks of `y0` (`check_start`, a `checked_state_pair` of its own) | run again, the system's methods bound once |

A check that fails on a repeat hands the call to the first-call path, which
raises its error the same way; so does anything a repeat does not cover: a
traced input, events, `dt`, `dense`, `saveat` and the other options `run_taylor`
refuses, `t1=None`, and a system with a NumPy array in it (mutable in place, so
its identity does not fix its equations). The run itself is heyoka's: one
`propagate_until` to t1 (`HeyokaRunner.final_state`), or the runner's grid for
`ts`; the `Trajectory` is the first-call path's (`member_trajectory`).

After heyoka's run every NumPy, pytree or equinox call on the way out is cold
(its code and data evicted by heyoka's loop: 10–100 µs a call where a warm one
costs 1–10 µs), and so is every call before the next run: a repeat of the
common call — `y0` a tuple of NumPy arrays, `args` None — makes few of them
(its key without a pytree flatten, y0 flattened by one `concatenate`, the
statistics of one member on Python values). The double pendulum to t = 100 at
tol 1e-12, one core, each call after a heyoka run: 340–480 µs of Python around
`propagate_until`, from 580–700 µs; 0.95–0.99× heyoka's own time, from
1.03–1.08× (the translated integrator alone: 0.85–0.86×). Those figures had the
`Trajectory`'s fields set on a bare object (25 µs less), since taken back for
the public `tree_unflatten` (`taylor_heyoka._trajectory`).

References: F. Biscani & D. Izzo, MNRAS 504 (2021) 2614 (heyoka); the equinox
documentation, `equinox.Module` (bound methods as Modules).
"""

from __future__ import annotations

import functools
import numbers
from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import Any

import jax
import numpy as np
from jax.core import Tracer

from lagjax._core.precision import working_dtype
from lagjax._core.system import AbstractSystem
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
    all_finite,
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
        # the default pair check reads only y0's structure and shapes, which the
        # key fixes: its verdict is kept (it returns the pair as given)
        default_pair = type(system).checked_state_pair is _DEFAULT_PAIR_CHECK
        self.checked_state_pair: Callable | None = (
            None if default_pair else _method(system, "checked_state_pair")
        )
        self.resolve: Callable = _method(system, "resolve")
        self.check_start: Callable = _method(resolved, "check_start")
        self.dtype, self.field, self.runner = dtype, field, runner
        self.integrator = runner.integrator() if runner.final_only else None
        self.max_steps = max_steps
        self.no_pars = np.zeros(0, dtype)  # the parameters of `args` None
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
            pars = self.no_pars if args is None else concrete_pars(args, self.dtype)
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
        check_pair = self.checked_state_pair
        pair = tuple(y0) if check_pair is None else check_pair(*y0)
        start, flat0 = _start_and_flat(pair, self.dtype)
        if not all_finite(flat0):
            return None
        system, args = self.resolve(args)
        self.check_start(start, t0, args, self.dtype)
        return flat0, system, args


def _method(module: Any, name: str) -> Callable:
    """`module.name` as its function bound by `functools.partial`: equinox's
    bound-method Module reads its own fields through a Python
    `__getattribute__` on every call (three calls a repeat, cold after a
    heyoka run)."""
    return functools.partial(getattr(type(module), name), module)


_DEFAULT_PAIR_CHECK = AbstractSystem.checked_state_pair


def _start_and_flat(pair: Any, dtype: np.dtype) -> tuple[Any, np.ndarray]:
    """y0's checked pair with its leaves in `dtype`, and flat. A tuple of NumPy
    arrays already in `dtype` is its own converted pair (`np.asarray` returns
    each array): one `concatenate`, no pytree flatten or unflatten, each a
    cold call after a heyoka run."""
    if type(pair) is tuple and all(
        type(x) is np.ndarray and x.dtype == dtype for x in pair
    ):
        return pair, np.concatenate(pair, axis=None)
    leaves, treedef = jax.tree_util.tree_flatten(pair)
    leaves = [np.asarray(x, dtype=dtype) for x in leaves]
    flat0 = np.concatenate([np.ravel(x) for x in leaves])
    return jax.tree_util.tree_unflatten(treedef, leaves), flat0


_REPEATS: OrderedDict[Hashable, _Repeat] = OrderedDict()


def _structure(system, y0, t0, t1, solver, ts, args, rtol, atol, max_steps):
    """The key of a call's structure (module docstring), or None for a call a
    repeat does not cover: traced or non-numeric times, traced leaves (and,
    found on look-up, anything unhashable)."""
    if not (_real_number(t0) and _real_number(t1)) or isinstance(ts, Tracer):
        return None
    y0_key = _plain_tuple(y0)
    if y0_key is None:
        y0_key = _tree_key(y0)
    args_key = None if args is None else _tree_key(args)
    if y0_key is None or (args_key is None and args is not None):
        return None
    return (
        id(system), y0_key, args_key, ts is None, rtol, atol, max_steps,
        _solver_fields(solver), bool(jax.config.read("jax_enable_x64")),
    )  # fmt: skip


def _tree_key(tree: Any) -> tuple | None:
    """A pytree's structure and leaf types, or None for traced leaves."""
    leaves, structure = jax.tree_util.tree_flatten(tree)
    if any(isinstance(x, Tracer) for x in leaves):
        return None
    return structure, _leaf_types(leaves)


def _plain_tuple(y0: Any) -> tuple | None:
    """`_tree_key` of a plain tuple of NumPy arrays and floats (the common
    `(q0, qdot0)`) without a pytree flatten, a cold call after a heyoka run:
    its length fixes its structure. None for any other y0."""
    if type(y0) is not tuple:
        return None
    types = []
    for x in y0:
        kind = type(x)
        if kind is np.ndarray:
            types.append((kind, x.shape, x.dtype))
        elif kind is float:
            types.append((kind, (), None))  # as `_leaf_types` has a float
        else:
            return None
    return "tuple", tuple(types)


def _real_number(value: Any) -> bool:
    kind = type(value)
    if kind is float or kind is int:
        return True
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
