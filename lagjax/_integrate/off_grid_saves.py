r"""Fixed-step runs saving at any times: nested scans and the continuous extension.

A save time $t_j$ off the step grid lies in one step $[t_k, t_{k+1}]$, its
*bracket* $k_j$; the state there is the solver's continuous extension over that
step (`lagjax.solvers.hermite` for lagjax's fixed-step methods, diffrax's own for the
others) evaluated at $s = (t_j - t_k)/(t_{k+1} - t_k)$ — the interpolant
`diffrax.diffeqsolve` evaluates for `SaveAt(ts=...)`, so the saves agree with it
to round-off.

The run is one `lax.scan` over the saves. Save j first takes the plain steps up
to its bracket — $e_j = k_j - k_{j-1} - 1$ of them, by an inner scan of fixed
length $\max_j e_j$ whose surplus steps are computed and not taken (the selects
of `step_bodies.step_function`) — then the bracket step itself with the dense
information, and evaluates the interpolant. A save in the step the previous one
bracketed ($e_j = -1$) reuses that step's dense information. Only bracket steps
evaluate the vector field for the extension (two evaluations per save, four with
the quintic's Jacobian–vector products): the plain steps cost what the
final-state scan costs.

The surplus steps are the price of a fixed-length inner scan: for save times
spaced s steps apart, ⌈s⌉/s steps per needed step (1.2 at s = 3.3, 1.0025 at
s = 400). `off_grid_schedule` refuses schedules that would compute more than
four times the steps needed (save times bunched with long gaps between); those
runs stay on `diffeqsolve`. Every piece is a `lax.scan`, so forward and reverse
differentiation both go through.
"""

from __future__ import annotations

from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from lagjax._integrate.fixed_step_loop import fixed_step_count
from lagjax._integrate.scan_body import (
    all_finite,
    initial_carry,
    step_function,
    step_times,
)
from lagjax.solvers.hermite import HermiteDenseOutput

# Most steps computed per step needed (plain and bracket steps together) before a
# schedule is left to diffeqsolve.
_MOST_WORK = 4


def off_grid_schedule(
    t0: float, t1: float, dt: float, ts: np.ndarray
) -> tuple[np.ndarray, int] | None:
    """`(brackets, most)`: the step each save time lies in and the most plain
    steps before one bracket; None for times the scan does not take (not
    monotone in the run's direction, outside [t0, t1], or too bunched)."""
    if ts.ndim != 1 or ts.size == 0 or not np.all(np.isfinite(ts)):
        return None
    steps = fixed_step_count(t0, t1, dt)
    positions = (ts - t0) / dt
    span = abs((t1 - t0) / dt)
    slack = 1e-9 * max(1.0, span)
    if np.any(np.diff(positions) < 0):
        return None
    if positions[0] < -slack or positions[-1] > span + slack:
        return None
    # A time on the grid belongs to the step it ends (diffrax's "left" side).
    brackets = np.clip(np.ceil(positions) - 1, 0, steps - 1).astype(int)
    plain = brackets - np.concatenate([[0], brackets[:-1] + 1])
    most = max(int(plain.max()), 0)
    needed = int(brackets[-1]) + 1 + ts.size
    if ts.size * (most + 1) > _MOST_WORK * needed:
        return None
    return brackets, most


def _bracket_step(terms, solver, dense_solver, times, y, state, args):
    """One step from (t_k, y) with the dense information: (y1, state, info, result).

    `state` is the plain solver's; a Hermite extension gets its start derivatives
    at (t_k, y) afresh."""
    start, end = times
    wrapped = isinstance(dense_solver, HermiteDenseOutput)
    if wrapped:
        state = dense_solver.state_at(terms, start, y, args, state)
    y1, _, info, state, result = dense_solver.step(
        terms, start, end, y, args, state, False
    )
    if wrapped:
        state = HermiteDenseOutput.inner_state(state)
    result = diffrax.RESULTS.where(
        all_finite(y1),
        result,
        diffrax.RESULTS.nonfinite,  # pyright: ignore[reportArgumentType]
    )
    return y1, state, info, result


@eqx.filter_jit
def integrate_off_grid(
    terms: Any,
    solver: diffrax.AbstractSolver,
    dense_solver: diffrax.AbstractSolver,
    t0: float,
    t1: float,
    dt: float,
    brackets: Any,
    most: int,
    ts: Any,
    y0: Any,
    args: Any,
    dtype: Any = float,
) -> tuple[Any, Any, Any, Any]:
    """The states at `ts` (module docstring): `(ys, result, steps_taken, saved)`.

    `dense_solver` is `solver` with the continuous extension
    (`hermite.with_dense_output`); `brackets` and `most` come from
    `off_grid_schedule` (the brackets traced, so new save times reuse the
    compilation when `most` is the same).
    `saved[j]` is False for the saves a failure kept from being reached.
    """
    last = fixed_step_count(t0, t1, dt) - 1

    def times(k):
        return step_times(t0, dt, k, dtype, last, t1)

    def bracket(y, state, k):
        return _bracket_step(terms, solver, dense_solver, times(k), y, state, args)

    carry = initial_carry(terms, solver, t0, dt, y0, args, dtype)
    k0 = carry[3]
    no_info = jax.tree_util.tree_map(
        jnp.zeros_like, eqx.filter_eval_shape(bracket, y0, carry[1], k0)[2]
    )

    def save(carry, x):
        (y, state, result, k), info, span = carry
        target, t = x
        if most:
            plain = step_function(
                terms, solver, t0, dt, args, dtype, last, t1, until=target
            )
            (y, state, result, k), _ = jax.lax.scan(
                plain, (y, state, result, k), None, length=most
            )
        y1, state1, info1, result1 = bracket(y, state, k)
        # Not taken when the previous save bracketed this step already.
        take = (k == target) & (result == diffrax.RESULTS.successful)
        result = diffrax.RESULTS.where(take, result1, result)
        advance = take & (result == diffrax.RESULTS.successful)
        y, state = jax.tree_util.tree_map(
            lambda new, old: jnp.where(advance, new, old), (y1, state1), (y, state)
        )
        info, span = jax.tree_util.tree_map(
            lambda new, old: jnp.where(take, new, old), (info1, times(k)), (info, span)
        )
        k = jnp.where(advance, k + 1, k)
        value = dense_solver.interpolation_cls(t0=span[0], t1=span[1], **info).evaluate(
            t
        )
        saved = (result == diffrax.RESULTS.successful) & (k == target + 1)
        return ((y, state, result, k), info, span), (value, saved)

    initial = (carry, no_info, times(k0))
    xs = (jnp.asarray(brackets), jnp.asarray(ts, dtype))
    (final, _, _), (ys, saved) = jax.lax.scan(save, initial, xs)
    return ys, final[2], final[3], saved
