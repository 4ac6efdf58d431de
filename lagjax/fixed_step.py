"""Fixed-step integration as a plain `lax.scan` over a diffrax solver's `step`.

`diffrax.diffeqsolve` runs every solver inside a general adaptive loop: it carries
the previous and next times, the step-size controller's state, dense output and
save state, and selects accepted/rejected values every step. For a fixed step with
only the final state saved none of that is needed, and on CPU it is what separates
a diffrax run from a hand-written loop (measured in `benchmarks/solver_overhead.py`).
`simulate` therefore takes this path for `dt` given, final state only, default
adjoint and no progress meter. The solver and its `step` are the same diffrax
objects, so results match `diffeqsolve` with `ConstantStepSize` (including the
shortened last step) to round-off.
"""

from __future__ import annotations

import math
from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp


def fixed_step_count(t0: float, t1: float, dt: float) -> int:
    """Number of steps of size |dt| to cover [t0, t1], the last one shortened.

    A span that is an integer multiple of dt up to round-off is not given an extra
    sliver of a step.
    """
    ratio = abs((t1 - t0) / dt)
    nearest = round(ratio)
    if nearest >= 1 and abs(ratio - nearest) <= 1e-9 * ratio:
        return nearest
    return max(1, math.ceil(ratio))


# Compiled once per (terms, solver, times, state structure): terms and solvers are
# equinox Modules that compare by value, so repeated runs reuse the compilation.
@eqx.filter_jit
def integrate_fixed_steps(
    terms: Any,
    solver: diffrax.AbstractSolver,
    t0: float,
    t1: float,
    dt: float,
    y0: Any,
    args: Any,
    dtype: Any = float,
) -> tuple[Any, Any, int]:
    """Take fixed steps from t0 to t1; return `(y1, result, steps)`.

    `result` is the first unsuccessful diffrax `RESULTS` of any step (e.g. a failed
    implicit solve), or `successful`. Grid times t0 + k·dt are formed in the default
    float precision and handed to the solver in the state's `dtype`. Steps after a
    failure still run — the scan has a fixed length — but the state reported then
    is that of a failed run.
    """
    steps = fixed_step_count(t0, t1, dt)
    dt = math.copysign(abs(dt), t1 - t0)
    state = solver.init(
        terms, jnp.asarray(t0, dtype), jnp.asarray(t0 + dt, dtype), y0, args
    )

    # The step index is carried, not scanned over: with `xs = arange(steps)` XLA on
    # CPU launched the fused pieces of a larger step body one by one (measured
    # 10× on Kepler with Yoshida4, 2× on a rigid body; bit-identical results).
    def one_step(carry, _):
        y, solver_state, result, k = carry
        start = (t0 + k * dt).astype(dtype)
        end = jnp.where(k == steps - 1, t1, t0 + (k + 1) * dt).astype(dtype)
        y, _, _, solver_state, step_result = solver.step(
            terms, start, end, y, args, solver_state, False
        )
        result = diffrax.RESULTS.where(
            result == diffrax.RESULTS.successful, step_result, result
        )
        return (y, solver_state, result, k + 1), None

    initial = (y0, state, diffrax.RESULTS.successful, jnp.asarray(0))
    (y1, _, result, _), _ = jax.lax.scan(one_step, initial, None, length=steps)
    return y1, result, steps
