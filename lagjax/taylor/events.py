r"""Terminal events on the step polynomial: where a condition g(t, y) crosses zero.

A Taylor step hands over the polynomial $P(\tau) = \sum_k y_k \tau^k$, the solution
on the whole step $[t, t + h]$ to the tolerance. So the condition along the step is
$\gamma(\tau) = g(t + \tau, P(\tau))$, known without another evaluation of f:

- **Detection, in every step.** γ is sampled at `SAMPLES` equally spaced points of
  the step (its value at the step's start is the previous step's last sample), and
  the first pair of neighbours whose signs say "crossed" (in the event's direction,
  diffrax's convention) brackets the crossing. The cost is `SAMPLES` evaluations
  of the polynomial and of g per step, nothing more.
- **Location, once, after the loop.** The run stops after the step that crossed;
  the bracket is bisected on γ down to adjacent floating-point numbers (the
  polynomial is the solution there, so this is round-off, not a tolerance), then
  one Newton step γ/γ' from the result, held out of differentiation, makes the
  event time differentiable by the implicit-function theorem,
  dτ/dθ = −(∂γ/∂θ)/γ'.

A zero of g at the run's start ends no run (as in diffrax and heyoka): it is then
replaced by the sign γ takes just after, from the derivative of g along y' = f.

What sampling cannot see: two crossings closer together than a step / `SAMPLES`
(g varying faster than the solution itself, or grazing the zero) cancel out.
heyoka's route (`backend="heyoka"`) isolates every real root of g's own Taylor
polynomial instead.

References: Biscani & Izzo, "Revisiting high-order Taylor methods for astrodynamics
and celestial mechanics", MNRAS 504 (2021), §5 (events on the step polynomial); the
diffrax documentation, `diffrax.Event` (the crossing conventions).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from .step import horner

# Samples of the condition per step: a crossing is seen when the condition keeps
# one sign over at least a step / SAMPLES on either side of it.
SAMPLES = 8
# Halvings of the bracket (a step / SAMPLES wide): 64 reach adjacent floats.
BISECTIONS = 64


class StepEvent(eqx.Module):
    """Terminal conditions `g(t, y, args) -> float` on the flat state y, and each
    one's direction: +1 upward (from ≤ 0 to > 0), −1 downward (from > 0 to ≤ 0),
    0 either (a change of sign)."""

    conditions: tuple[Callable, ...]
    directions: tuple[int, ...] = eqx.field(static=True)

    def __check_init__(self):
        if len(self.conditions) != len(self.directions) or not self.conditions:
            raise ValueError(
                "StepEvent: one direction per condition, and at least one condition"
            )
        if any(d not in (-1, 0, 1) for d in self.directions):
            raise ValueError(
                f"StepEvent: directions are -1, 0 or +1, got {self.directions}"
            )

    def values(self, t: Any, y: jax.Array, args: Any) -> jax.Array:
        """Every condition at (t, y), shape (K,)."""
        return jnp.stack([jnp.asarray(g(t, y, args), y.dtype) for g in self.conditions])


class Watch(NamedTuple):
    """What the loop carries for an event: the conditions at the current time,
    and, for the step that crossed, its bracket per condition and its polynomial."""

    start_values: jax.Array  # (K,) the conditions where the next step starts
    fired: jax.Array  # (K,) this condition crossed in the last step
    interval: jax.Array  # (K,) the sample interval of its first crossing
    positive_left: jax.Array  # (K,) the condition is > 0 at the bracket's left end
    coeffs: jax.Array  # (p + 1, n) the last step's polynomial
    t: jax.Array  # the last step's start, t + t_low in double length
    t_low: jax.Array
    tau: jax.Array  # the last step's signed length


def start_watch(
    event: StepEvent, vector_field: Callable, t0: Any, y0: jax.Array, args: Any, p: int
) -> Watch:
    """The watch before the first step. A condition that is zero at t0 takes the
    sign of its derivative along the solution, so the start is not a crossing."""

    def along(tau):
        return event.values(t0 + tau, y0 + tau * vector_field(t0, y0, args), args)

    zero = jnp.zeros_like(t0)
    values, rates = jax.jvp(along, (zero,), (jnp.ones_like(t0),))
    count = len(event.conditions)
    return Watch(
        start_values=jnp.where(values == 0, rates, values),
        fired=jnp.zeros(count, bool),
        interval=jnp.zeros(count, jnp.int32),
        positive_left=jnp.zeros(count, bool),
        coeffs=jnp.zeros((p + 1, *y0.shape), y0.dtype),
        t=zero,
        t_low=zero,
        tau=zero,
    )


def _crossed(left: jax.Array, right: jax.Array, direction: int) -> jax.Array:
    """diffrax's test of a crossing between two values of a condition."""
    if direction > 0:
        return (left <= 0) & (right > 0)
    if direction < 0:
        return (left > 0) & (right <= 0)
    return jnp.sign(left) != jnp.sign(right)


def watch_step(
    event: StepEvent,
    watch: Watch,
    coeffs: jax.Array,
    t: jax.Array,
    t_low: jax.Array,
    tau: jax.Array,
    args: Any,
    ok: jax.Array,
) -> Watch:
    """The watch after the step (t, t_low, signed length tau, polynomial coeffs):
    the conditions sampled along it, and the first crossing of each."""
    fractions = jnp.arange(1, SAMPLES + 1, dtype=tau.dtype) / SAMPLES

    def sample(fraction):
        point = fraction * tau
        return event.values((t + point) + t_low, horner(coeffs, point), args)

    samples = jax.vmap(sample, out_axes=1)(fractions)  # (K, SAMPLES)
    values = jnp.concatenate([watch.start_values[:, None], samples], axis=1)
    crossed = jnp.stack(
        [
            _crossed(row[:-1], row[1:], d)
            for row, d in zip(values, event.directions, strict=True)
        ]
    )
    interval = jnp.argmax(crossed, axis=1).astype(jnp.int32)
    left = jnp.take_along_axis(values, interval[:, None], axis=1)[:, 0]
    return Watch(
        start_values=jnp.where(ok, samples[:, -1], watch.start_values),
        fired=ok & jnp.any(crossed, axis=1),
        interval=interval,
        positive_left=left > 0,
        coeffs=coeffs,
        t=t,
        t_low=t_low,
        tau=tau,
    )


def _locate(
    condition: Callable, watch: Watch, k: int, args: Any
) -> jax.Array:  # fmt: skip
    """The signed offset τ of condition k's crossing in the watched step."""

    def gamma(tau):
        return jnp.asarray(
            condition((watch.t + tau) + watch.t_low, horner(watch.coeffs, tau), args),
            watch.coeffs.dtype,
        )

    width = watch.tau / SAMPLES
    low = jax.lax.stop_gradient(watch.interval[k] * width)
    positive_left = watch.positive_left[k]

    def halve(_, bracket):
        low, high = bracket
        middle = low + (high - low) / 2
        left_side = (gamma(middle) > 0) == positive_left
        return jnp.where(left_side, middle, low), jnp.where(left_side, high, middle)

    _, high = jax.lax.fori_loop(
        0, BISECTIONS, halve, (low, jax.lax.stop_gradient(low + width))
    )
    tau = jax.lax.stop_gradient(high)
    value, slope = jax.jvp(gamma, (tau,), (jnp.ones_like(tau),))
    slope = jax.lax.stop_gradient(slope)
    return tau - jnp.where(slope != 0, value / jnp.where(slope != 0, slope, 1), 0)


class Crossing(NamedTuple):
    """The first crossing of a watched step: which condition (`mask`, one True
    at most), its signed offset `tau` in the step, and whether any fired."""

    mask: jax.Array
    tau: jax.Array
    occurred: jax.Array


def first_crossing(
    event: StepEvent, watch: Watch, args: Any, direction: jax.Array
) -> Crossing:
    """Locate every condition that fired in the watched step; the earliest wins."""
    taus = jnp.stack(
        [_locate(g, watch, k, args) for k, g in enumerate(event.conditions)]
    )
    ahead = jnp.where(watch.fired, direction * taus, jnp.inf)
    first = jnp.argmin(ahead)
    mask = watch.fired & (jnp.arange(taus.shape[0]) == first)
    return Crossing(mask=mask, tau=taus[first], occurred=jnp.any(watch.fired))
