r"""Special functions the closed forms need: the AGM and the complete elliptic integral.

$K(m) = \int_0^{\pi/2} (1 - m\sin^2\phi)^{-1/2}\,d\phi = \pi / (2\,\mathrm{AGM}(1,
\sqrt{1 - m}))$ (Gauss; Abramowitz & Stegun §17.6) gives the pendulum's period
$4K(\sin^2(\theta_0/2))/\sqrt{g/l}$ and the free rigid body's flip period. The
parameter convention $m = k^2$ is scipy's (`scipy.special.ellipk`). Near $m = 1$,
where K diverges logarithmically, pass the complement $m_1 = 1 - m$ directly: it
carries digits that $m$ has lost to rounding.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

# Enough for float64 from any start: the ratio of the two means falls doubly
# exponentially once it is O(1), and reaches O(1) within ~10 steps even from 1e300.
_AGM_ITERATIONS = 24


def arithmetic_geometric_mean(a: jax.Array, b: jax.Array) -> jax.Array:
    r"""Gauss's $\mathrm{AGM}(a, b)$: iterate $a, b \to (a + b)/2, \sqrt{ab}$ (a, b > 0)."""

    def iterate(_, means):
        a, b = means
        return 0.5 * (a + b), jnp.sqrt(a * b)

    a, b = jnp.broadcast_arrays(
        jnp.asarray(a, dtype=float), jnp.asarray(b, dtype=float)
    )
    a, b = jax.lax.fori_loop(0, _AGM_ITERATIONS, iterate, (a, b))
    return 0.5 * (a + b)


def complete_elliptic_k(parameter: jax.Array) -> jax.Array:
    r"""$K(m)$ for $0 \le m < 1$ (parameter $m = k^2$)."""
    m = jnp.asarray(parameter, dtype=float)
    return complete_elliptic_k_from_complement(1 - m)


def complete_elliptic_k_from_complement(complement: jax.Array) -> jax.Array:
    r"""$K$ as a function of the complementary parameter $m_1 = 1 - m$."""
    m1 = jnp.asarray(complement, dtype=float)
    return 0.5 * jnp.pi / arithmetic_geometric_mean(jnp.ones_like(m1), jnp.sqrt(m1))
