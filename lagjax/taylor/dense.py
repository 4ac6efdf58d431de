r"""Dense output of a Taylor run: every step's polynomial, kept and evaluated later.

Step i starts at $t_i$ (kept in double length, $t_i + \ell_i$, as the loop keeps
time) and its polynomial $P_i(\tau) = \sum_k y_{i,k} \tau^k$ is the solution on the
whole step. Keeping $(t_i, \ell_i, y_{i,0..p})$ for every step, the state at any t
of the run is $P_i((t - t_i) - \ell_i)$ for the last step that starts at or before
t (in the direction of the run), by Horner's rule: the polynomials the loop's
saves at `ts` are taken from, so dense values and saves agree to rounding.

The buffer has one row per allowed step (`max_steps` rows of (p + 1) × n
coefficients), allocated before the run, as diffrax's dense output is.

References: Jorba & Zou, Experimental Mathematics 14 (2005); Biscani & Izzo,
MNRAS 504 (2021), §4 (dense output of the Taylor method).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from .step import horner


class DenseBuffer(NamedTuple):
    """What the loop carries: one row per step (unused rows start at ±inf)."""

    starts: jax.Array  # (rows,)
    lows: jax.Array  # (rows,)
    coeffs: jax.Array  # (rows, p + 1, n)


def empty_buffer(
    rows: int, p: int, y0: jax.Array, direction: jax.Array
) -> DenseBuffer:  # fmt: skip
    """Rows for `rows` steps; unused starts lie beyond any time of the run."""
    return DenseBuffer(
        starts=jnp.full(rows, jnp.inf, y0.dtype) * direction,
        lows=jnp.zeros(rows, y0.dtype),
        coeffs=jnp.zeros((rows, p + 1, *y0.shape), y0.dtype),
    )


def keep_step(
    buffer: DenseBuffer, row: jax.Array, t: jax.Array, t_low: jax.Array, coeffs
) -> DenseBuffer:
    """Step `row`'s start and polynomial written into the buffer."""
    return DenseBuffer(
        starts=buffer.starts.at[row].set(t),
        lows=buffer.lows.at[row].set(t_low),
        coeffs=buffer.coeffs.at[row].set(coeffs),
    )


class TaylorDense(eqx.Module):
    """The run's step polynomials over [t0, end] (end: t1, or the event that
    ended the run); `evaluate(t)` gives the flat state."""

    buffer: DenseBuffer
    count: jax.Array  # the steps taken (rows filled)
    t0: jax.Array
    end: jax.Array
    direction: jax.Array

    def evaluate(self, t: Any) -> jax.Array:
        """The flat state at time(s) `t` of the span; a leading axis for an array.
        A time outside [t0, end] is a run-time error (`eqx.error_if`)."""
        t = jnp.asarray(t, self.t0.dtype)
        if t.ndim:
            return jax.vmap(self.evaluate)(t)
        outside = (self.direction * (t - self.t0) < 0) | (
            self.direction * (t - self.end) > 0
        )
        t = eqx.error_if(
            t,
            outside,
            "Trajectory.evaluate: t lies outside the integrated span; the dense "
            "output covers [t0, t1] (or up to the event that ended the run)",
        )
        keys = self.direction * self.buffer.starts
        row = jnp.searchsorted(keys, self.direction * t, side="right") - 1
        row = jnp.clip(row, 0, jnp.maximum(self.count - 1, 0))
        tau = (t - self.buffer.starts[row]) - self.buffer.lows[row]
        return horner(self.buffer.coeffs[row], tau)
