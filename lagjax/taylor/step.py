"""One Taylor step: the order and step size from the tolerance, and the step
polynomial evaluated by Horner's rule.

With the coefficients y₀..y_p of the solution through (t, y(t)) in hand, the
step polynomial Σₖ yₖ τᵏ is the solution to within its remainder, which Jorba
& Zou bound by the last terms: for a series with radius of convergence ρ,
‖yⱼ‖ ≈ ρ⁻ʲ, so

    ρ ≈ min_{j ∈ {p−1, p}} ‖yⱼ‖∞^{−1/j}

and a step h keeps the remainder below ε when (h/ρ)^{p+1} ≲ ε. They choose

    p = ⌈−ln(ε)/2 + 1⌉,    h = ε^{1/(p−1)} e^{−0.7/(p−1)} · ρ,
    ρ = min_{j ∈ {p−1, p}} (s / ‖yⱼ‖∞)^{1/j},

the order that minimises the cost per unit time, with the safety factor
e^{−0.7/(p−1)}. At that order ε^{1/(p−1)} ≈ e^{−2}: this is heyoka's
h = ρ e^{−2} e^{−0.7/(p−1)}, and it stays meaningful at a user's order. With
ε = min(rtol, atol), the scale s = max(atol, rtol‖y₀‖∞)/ε is 1 in absolute
control and ‖y₀‖∞ in relative control (rtol = atol: heyoka's switch at
‖y₀‖∞ = 1). Since the coefficients of the whole
step are at hand, dense output is the same polynomial at any τ ∈ [0, h].

References:
    Jorba & Zou, "A software package for the numerical integration of ODEs by
    means of high-order Taylor methods", Experimental Mathematics 14 (2005),
    §3.2–3.3; Biscani & Izzo, "Revisiting high-order Taylor methods for
    astrodynamics and celestial mechanics", MNRAS 504 (2021), §3.
"""

from __future__ import annotations

import math
from typing import Any

import jax
import jax.numpy as jnp

# e^{-0.7/(p-1)}: Jorba & Zou's safety factor against an underestimated remainder.
SAFETY_EXPONENT = 0.7


def order_from_tolerance(tolerance: float) -> int:
    """p = ⌈−ln(ε)/2 + 1⌉ (Jorba & Zou 2005; heyoka's rule), at least 2."""
    return max(2, math.ceil(-math.log(tolerance) / 2 + 1))


def step_size(coeffs: jax.Array, rtol: Any, atol: Any) -> jax.Array:
    """The step length (positive, possibly inf) from the last two coefficients
    of `coeffs`, shape (p + 1, n), or one per member for a batch (p + 1, n, B)."""
    order = coeffs.shape[0] - 1
    tolerance = jnp.minimum(rtol, atol)
    # max(atol, rtol‖y₀‖)/tol: 1 in absolute mode, the state's size in relative mode.
    scale = jnp.maximum(atol, rtol * jnp.max(jnp.abs(coeffs[0]), axis=0)) / tolerance
    # The last two orders' norms in one reduction (one kernel, not two).
    norms = jnp.max(jnp.abs(coeffs[order - 1 :]), axis=1)
    powers = jnp.asarray([1.0 / (order - 1), 1.0 / order], coeffs.dtype)
    powers = powers.reshape((2,) + (1,) * (norms.ndim - 1))
    # A zero coefficient bounds nothing: it allows any step (a polynomial solution).
    safe = jnp.where(norms > 0, norms, 1.0)
    radii = jnp.where(norms > 0, (scale / safe) ** powers, jnp.inf)
    factor = tolerance ** (1.0 / (order - 1)) * math.exp(-SAFETY_EXPONENT / (order - 1))
    return factor * jnp.min(radii, axis=0)


def horner(coeffs: jax.Array, tau: jax.Array) -> jax.Array:
    """Σₖ coeffs[k] τᵏ by Horner's rule; τ scalar (or broadcastable to the
    leading axes of `coeffs[0]`'s batch)."""
    result = coeffs[-1]
    for k in range(coeffs.shape[0] - 2, -1, -1):
        result = result * tau + coeffs[k]
    return result


def two_sum(a: jax.Array, b: jax.Array) -> tuple[jax.Array, jax.Array]:
    """s + e = a + b exactly, s = fl(a + b) (Knuth's TwoSum)."""
    s = a + b
    b_virtual = s - a
    return s, (a - (s - b_virtual)) + (b - b_virtual)


def compensated_advance(
    coeffs: jax.Array, tau: jax.Array, y_low: jax.Array
) -> tuple[jax.Array, jax.Array]:
    """The state after a step of τ as y_high + y_low (compensated summation).

    The increment Σ_{k≥1} yₖ τᵏ is small beside y₀ = y_high, so the sum rounded
    to double loses ε|y| every step, and over n steps the state random-walks by
    ε|y|√n — the floor of a long run at tight tolerance (the double pendulum to
    t = 100 at tol 1e-15: 1–2e-14 against heyoka in long double). Carried apart,
    the part below y_high's last bit is added back at the next step, so what is
    lost per step is the rounding of the increment, ε|Δy| (Kahan 1965; heyoka's
    `high_accuracy` mode compensates the same way). The coefficients are still
    computed at y_high: the y_low they miss moves the step by h‖∂f/∂y‖ε|y|."""
    increment = tau * horner(coeffs[1:], tau)
    return two_sum(coeffs[0], increment + y_low)


def horner_many(coeffs: jax.Array, taus: jax.Array) -> jax.Array:
    """The step polynomial at several times: shape (len(taus), n)."""
    return jax.vmap(lambda tau: horner(coeffs, tau))(taus)
