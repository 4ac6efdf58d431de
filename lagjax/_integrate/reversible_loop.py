r"""Reverse mode through a fixed-step run without storing it: the states are
recomputed backward by stepping with −h.

A symmetric one-step method satisfies $\Phi_{-h} = \Phi_h^{-1}$ (Hairer, Lubich &
Wanner §V.1), so from the final state $y_N$ the run can be walked back,
$y_{k} = \Phi_{-h}(y_{k+1})$, and the cotangent pulled through one step at a time,

$$\bar y_k = \Big(\frac{\partial \Phi_h}{\partial y}(y_k)\Big)^{\!\top} \bar y_{k+1},
\qquad \bar\theta \mathrel{+}= \Big(\frac{\partial \Phi_h}{\partial \theta}(y_k)
\Big)^{\!\top} \bar y_{k+1},$$

each by `jax.vjp` of one step. Memory is that of the states kept at the *marks*:
the final state, the saved states and optional checkpoints every K steps — never
one per step. The reconstruction is exact up to round-off: each step back commits
the round-off of one step, which accumulates like a forward run's (a random walk,
∝ √steps); the marks restart it from the forward run's own states, so checkpoints
bound it for very long runs or float32.

What is carried from step to step is the solver's whole state beside y (the
splittings' first-same-as-last force and Kahan compensation, the implicit
methods' stage guess, RATTLE's multiplier), with its cotangent: a step back
starts from the forward run's state at the mark and produces the state the
forward step from $y_k$ starts from. A Kahan compensation started from the forward
run's keeps the reconstruction compensated too (the true state is y + c either
way), and it takes no part in the derivative: a compensated sum has the Jacobian
of the plain one, its compensation's derivative is zero (exactly so in floating
point, c̄ − c̄). The guesses of the implicit methods' stage solves are
differentiated implicitly by optimistix (zero derivative), so a step back that
starts its solve from a worse guess changes nothing but the iteration count.

Marks are uniform — `lead` steps to mark 0, then `every` steps between marks,
loops of static length unrolled as the forward loop is — or irregular (`Marks.at`:
off-grid saves, checkpoints around saves with no divisor near their spacing),
loops of traced length (`reversible_steps`).

Two walks share this loop. The splittings walk back stage by stage
(`reversible_splitting`): one linearization per stage serves both the step back
and the pullback, and the cotangents are summed with Kahan compensation. Every
other symmetric solver takes a whole step back with −h and then `jax.vjp` of the
forward step from the state reached (`_GenericWalk`).

References: Gomez, Ren, Urtasun & Grosse, "The reversible residual network:
backpropagation without storing activations", NeurIPS 2017; Hairer, Lubich &
Wanner, *Geometric Numerical Integration*, 2nd ed. (2006), §V.1; diffrax issue
#685 (reversible solves, not implemented there).
"""

from __future__ import annotations

import itertools
from typing import Any, NamedTuple

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp

from lagjax._integrate.reversible_lattice import LatticeWalk
from lagjax._integrate.reversible_splitting import SplittingWalk
from lagjax._integrate.reversible_steps import repeat_steps
from lagjax._integrate.scan_body import (
    TrackingCarry,
    all_finite,
    fast_step_function,
    step_times,
    steps_per_trip,
)
from lagjax.solvers.bit_reversible import BitReversible
from lagjax.solvers.splitting_engine import AbstractSplittingSolver


class Clock(NamedTuple):
    """The step grid: step k runs from t0 + k·dt to t0 + (k + 1)·dt, the step
    `last_step` ending at t1 (a shortened last step), times in `dtype`."""

    t0: float
    dt: float
    dtype: Any
    last_step: int | None = None
    t1: float | None = None

    def times(self, k) -> tuple[Any, Any]:
        return step_times(self.t0, self.dt, k, self.dtype, self.last_step, self.t1)

    def first_times(self) -> tuple[Any, Any]:
        """The times `solver.init` sees, as the plain scan gives them."""
        start, end = self.t0, self.t0 + self.dt
        return jnp.asarray(start, self.dtype), jnp.asarray(end, self.dtype)


class Marks(NamedTuple):
    """Where the forward run keeps its state: after `lead` steps, then every
    `every` steps, `count` marks in all; or, when `gaps` is given (irregular
    marks, `Marks.at`), `gaps[i]` steps between marks i and i + 1."""

    lead: int
    every: int
    count: int
    gaps: tuple[int, ...] | None = None

    @classmethod
    def at(cls, positions) -> Marks:
        """The marks after `positions[i]` steps (increasing): uniform when evenly
        spaced (the unrolled loops), irregular otherwise."""
        positions = [int(k) for k in positions]
        gaps = tuple(b - a for a, b in itertools.pairwise(positions))
        if len(set(gaps)) <= 1:
            return cls(positions[0], gaps[0] if gaps else 1, len(positions))
        return cls(positions[0], 0, len(positions), gaps)

    def positions(self) -> list[int]:
        """The step count at each mark."""
        if self.gaps is None:
            return [self.lead + i * self.every for i in range(self.count)]
        return [self.lead + sum(self.gaps[:i]) for i in range(self.count)]

    def stretches(self) -> Any:
        """The lengths of the stretches between marks as the loops take them: one
        Python int for uniform marks, an array for irregular ones."""
        return self.every if self.gaps is None else jnp.asarray(self.gaps)


def _stacked(first: Any, later: Any) -> Any:
    return jax.tree_util.tree_map(
        lambda a, b: jnp.concatenate([jnp.asarray(a)[None], b]), first, later
    )


def _forward(y0, terms, args, solver, clock: Clock, marks: Marks):
    """The run: `(states, solver_states, results)` at the marks (stacked), with
    the blocked loop's lean step body (`scan_body.fast_step_function`)."""
    fast_step = fast_step_function(
        terms, solver, clock.t0, clock.dt, args, clock.dtype, clock.last_step, clock.t1
    )
    state0 = solver.init(terms, *clock.first_times(), y0, args)
    k0 = jnp.asarray(0)
    carry = TrackingCarry(y0, state0, diffrax.RESULTS.successful, k0, None, k0)

    def one(carry):
        return fast_step(carry, None)[0]

    def steps(carry, length):
        return repeat_steps(one, carry, length, steps_per_trip(solver))

    if marks.lead:
        carry = steps(carry, marks.lead)

    def kept(carry: TrackingCarry):
        return carry.y, carry.solver_state, carry.result

    def interval(carry, gap):
        carry = steps(carry, marks.every if gap is None else gap)
        return carry, kept(carry)

    gaps = None if marks.gaps is None else jnp.asarray(marks.gaps)
    _, later = jax.lax.scan(interval, carry, gaps, length=marks.count - 1)
    return _stacked(kept(carry), later)


@eqx.filter_custom_vjp
def reversible_run(differentiable, solver, clock: Clock, marks: Marks):
    """`(states, results, solver_states)` at the marks of a fixed-step run from
    `y0`; `differentiable = (y0, terms, args)`. Reverse mode recomputes the states
    backward (module docstring); the solver states are returned for their values
    only (a continuous extension started at a mark): their cotangents are
    dropped."""
    y0, terms, args = differentiable
    states, solver_states, results = _forward(y0, terms, args, solver, clock, marks)
    return states, results, solver_states


@reversible_run.def_fwd
def _reversible_run_fwd(perturbed, differentiable, solver, clock, marks):
    del perturbed
    y0, terms, args = differentiable
    states, solver_states, results = _forward(y0, terms, args, solver, clock, marks)
    return (states, results, solver_states), (states, solver_states)


@reversible_run.def_bwd
def _reversible_run_bwd(residuals, cotangents, perturbed, differentiable, solver,
                        clock, marks):  # fmt: skip
    states, solver_states = residuals
    state_cotangents = _dense_cotangents(cotangents[0], states)
    y0, terms, args = differentiable
    params, static = eqx.partition((terms, args), eqx.is_inexact_array)
    if isinstance(solver, AbstractSplittingSolver):
        walk = SplittingWalk(solver, static, clock)
    elif isinstance(solver, BitReversible):
        walk = LatticeWalk(solver, static, clock)
    else:
        walk = _GenericWalk(solver, static, clock, y0)

    def at(index, tree):
        return jax.tree_util.tree_map(lambda x: x[index], tree)

    positions = marks.positions()
    carry = walk.start(at(-1, state_cotangents), at(-1, states),
                       at(-1, solver_states), params, positions[-1])  # fmt: skip

    def interval(carry, inputs):
        y, state, lower_cotangent, end, gap = inputs
        length = marks.every if gap is None else gap
        carry = walk.back(carry, y, state, end, length, params, lower_cotangent)
        return carry, None

    later = (
        at(slice(1, None), states),
        at(slice(1, None), solver_states),
        at(slice(None, -1), state_cotangents),
        jnp.asarray(positions[1:], dtype=int),
        None if marks.gaps is None else marks.stretches(),
    )
    carry, _ = jax.lax.scan(interval, carry, later, reverse=True)
    if marks.lead:
        carry = walk.back(carry, at(0, states), at(0, solver_states), marks.lead,
                          marks.lead, params, None)  # fmt: skip
    y0_cotangent, params_cotangent = walk.finish(carry, params)
    gradient = (y0_cotangent, *params_cotangent)
    return jax.tree_util.tree_map(
        lambda g, p: g if p else None, gradient, perturbed, is_leaf=_is_none
    )


class _Backward(NamedTuple):
    """What the backward pass carries: the cotangents of y and of the solver's
    state at the current step, and the parameters' cotangent summed so far."""

    y: Any
    state: Any
    params: Any


class _GenericWalk(eqx.Module):
    """The backward pass of any symmetric solver: a step back with −h, then the
    pullback of the forward step from the state reached (`jax.vjp` of
    `solver.step`)."""

    solver: Any
    static: Any
    clock: Any
    y0: Any

    def start(self, cotangent, y, state, params, steps: int) -> _Backward:
        del y, steps
        floating = eqx.filter(state, eqx.is_inexact_array)
        return _Backward(cotangent, _zeros(floating), _zeros(params))

    def back(self, carry: Any, y, state, end, length: Any, params,
             saved) -> _Backward:  # fmt: skip
        carry = _steps_back(carry, y, state, end, length, params, self.static,
                            self.solver, self.clock)  # fmt: skip
        return carry if saved is None else carry._replace(y=_add(carry.y, saved))

    def finish(self, carry: Any, params):
        return _through_init(carry, self.y0, params, self.static, self.solver,
                             self.clock)  # fmt: skip


def _steps_back(carry: _Backward, y, state, end, length, params, static, solver,
                clock: Clock) -> _Backward:  # fmt: skip
    """Walk back `length` steps from the state `(y, state)` after step `end` − 1,
    pulling the cotangents through each step."""

    def step(y, state, params, times):
        terms, args = eqx.combine(params, static)
        start, stop = times
        y1, _, _, state1, _ = solver.step(terms, start, stop, y, args, state, False)
        return y1, state1

    def one_back(inner):
        y, state, k, cotangent = inner
        start, stop = clock.times(k - 1)
        y, state = step(y, state, params, (stop, start))
        # Integer parts of the state (a lattice's units) have no cotangent.
        floating, exact = eqx.partition(state, eqx.is_inexact_array)

        def forward(y, floating, params):
            y1, state1 = step(y, eqx.combine(floating, exact), params, (start, stop))
            return y1, eqx.filter(state1, eqx.is_inexact_array)

        _, pullback = jax.vjp(forward, y, floating, params)
        y_bar, state_bar, params_bar = pullback((cotangent.y, cotangent.state))
        cotangent = _Backward(y_bar, state_bar, _add(cotangent.params, params_bar))
        return y, state, k - 1, cotangent

    inner = (y, state, jnp.asarray(end), carry)
    # Unrolled as the forward loop is (`steps_per_trip`): Störmer–Verlet's short
    # step pays the loop's own cost per trip, not per step.
    inner = repeat_steps(one_back, inner, length, steps_per_trip(solver))
    return inner[-1]


def _through_init(carry: _Backward, y0, params, static, solver, clock: Clock):
    """The cotangents of y0 and the parameters, with the solver state's cotangent
    pulled through `solver.init` (the first force of a splitting, say)."""

    def init(y0, params):
        terms, args = eqx.combine(params, static)
        state = solver.init(terms, *clock.first_times(), y0, args)
        return eqx.filter(state, eqx.is_inexact_array)

    _, pullback = jax.vjp(init, y0, params)
    y0_bar, params_bar = pullback(carry.state)
    return _add(carry.y, y0_bar), _add(carry.params, params_bar)


def _is_none(x: Any) -> bool:
    return x is None


def _add(a: Any, b: Any) -> Any:
    return jax.tree_util.tree_map(lambda x, y: x + y, a, b)


def _zeros(tree: Any) -> Any:
    return jax.tree_util.tree_map(jnp.zeros_like, tree)


def _dense_cotangents(cotangents: Any, states: Any) -> Any:
    """The states' cotangents with zeros where none came (an unused output)."""
    if cotangents is None:
        return _zeros(states)
    return jax.tree_util.tree_map(
        lambda c, s: jnp.zeros_like(s) if c is None else c,
        cotangents,
        states,
        is_leaf=_is_none,
    )


def finite_marks(states: Any, results: Any) -> jax.Array:
    """Which marks the run reached without failing: the solver's result at each
    and a finite state up to it."""
    good = (results == diffrax.RESULTS.successful) & jax.vmap(all_finite)(states)
    return jnp.cumprod(good.astype(jnp.int32)).astype(bool)
