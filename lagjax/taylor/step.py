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


def horner_many(coeffs: jax.Array, taus: jax.Array) -> jax.Array:
    """The step polynomial at several times: shape (len(taus), n)."""
    return jax.vmap(lambda tau: horner(coeffs, tau))(taus)
