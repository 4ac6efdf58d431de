r"""Save times that are traced (under the caller's `jit` or `vmap`), checked at run time.

`check_save_times` refuses a concrete `ts` that is not finite, not sorted from t0
towards t1, or outside the span, before anything compiles. A traced `ts` has no
values then, and diffrax's saving reads it as it is: a NaN compares false with
every step time, so the run saved t = [0.5, inf, inf] for ts = [0.5, NaN, 1.0] and
reported success. Here the same three conditions become one run-time error
(`eqx.branched_error_if`, one branch on the whole array, outside the loop), whose
message names the first condition that fails. A `throw=False` run raises it too:
a save grid that cannot be read is a bad input, not a failure of the integration
that a `Trajectory.result` could report.

References: the equinox documentation of `equinox.error_if` and
`equinox.branched_error_if` (run-time checks of traced values).
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp

_REMEDY = (
    "pass save times that are finite, sorted from t0 towards t1 and inside [t0, t1] "
    "(e.g. jnp.linspace(t0, t1, n))"
)
_MESSAGES = (
    f"simulate: ts holds a NaN or inf; {_REMEDY}",
    f"simulate: ts is not sorted from t0 towards t1; {_REMEDY}",
    f"simulate: ts holds a time outside [t0, t1]; {_REMEDY}",
)


def checked_traced_save_times(ts: jax.Array, t0: Any, t1: Any) -> jax.Array:
    """`ts` with a run-time error attached for non-finite, unordered or
    out-of-span entries; its shape (1-D, not empty) is refused at trace time."""
    if jnp.ndim(ts) != 1 or jnp.size(ts) == 0:
        raise ValueError(
            f"ts must be a non-empty 1-D array of times, got shape {jnp.shape(ts)}; "
            "e.g. ts=jnp.linspace(t0, t1, 101)"
        )
    direction = jnp.where(t1 >= t0, 1.0, -1.0)
    low, high = jnp.minimum(t0, t1), jnp.maximum(t0, t1)
    # A NaN makes the order and span tests false too: the first flag names it.
    flags = jnp.stack(
        [
            jnp.any(~jnp.isfinite(ts)),
            jnp.any(jnp.diff(ts) * direction < 0),
            jnp.any((ts < low) | (ts > high)),
        ]
    )
    return eqx.branched_error_if(ts, jnp.any(flags), jnp.argmax(flags), _MESSAGES)
