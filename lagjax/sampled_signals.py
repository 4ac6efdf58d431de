"""Measurements on sampled trajectories.

Closed forms predict times (a period, a flip, a turning point); trajectories are
saved at discrete times. These helpers read such times off the samples to far better
than the sampling interval, using the saved derivative as well as the value.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

# Newton's method on a cubic from the linear-interpolation guess: quadratic
# convergence, so a handful of iterations reach round-off.
_CROSSING_NEWTON_ITERATIONS = 8


def zero_crossing_times(
    ts: jax.Array, x: jax.Array, xdot: jax.Array, count: int
) -> jax.Array:
    """The first `count` times at which a sampled x(t) changes sign; NaN if fewer.

    Each crossing is refined by Newton's method on the cubic Hermite interpolant of
    (x, ẋ) between the samples around it. Its error is O(Δt⁴): samples 0.03 of the
    motion's time scale apart place a crossing to ~1e-12 of that scale.
    """
    changes = jnp.signbit(x[:-1]) != jnp.signbit(x[1:])
    (index,) = jnp.nonzero(changes, size=count, fill_value=0)
    step = ts[index + 1] - ts[index]
    x0, x1 = x[index], x[index + 1]
    v0, v1 = step * xdot[index], step * xdot[index + 1]
    # x(s) on s ∈ [0, 1], as polynomial coefficients, highest power first.
    cubic = [2 * (x0 - x1) + v0 + v1, 3 * (x1 - x0) - 2 * v0 - v1, v0, x0]
    slope = [3 * cubic[0], 2 * cubic[1], cubic[2]]
    s = x0 / (x0 - x1)
    for _ in range(_CROSSING_NEWTON_ITERATIONS):
        s = s - jnp.polyval(jnp.stack(cubic), s) / jnp.polyval(jnp.stack(slope), s)
    found = jnp.arange(count) < jnp.sum(changes)
    return jnp.where(found, ts[index] + s * step, jnp.nan)
