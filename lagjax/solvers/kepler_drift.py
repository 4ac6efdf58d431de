r"""The Kepler drift: two-body motion advanced exactly by Gauss's f and g functions.

A body at relative position $\mathbf r_0$ with velocity $\mathbf v_0$ about a
centre of gravitational parameter $\mu$ moves on a conic. Its state after a time
$h$ is linear in the initial one,

$$\mathbf r = f\,\mathbf r_0 + g\,\mathbf v_0,\qquad
\mathbf v = \dot f\,\mathbf r_0 + \dot g\,\mathbf v_0,$$

with Gauss's $f$ and $g$ written in the *universal variable* $s$, $ds = dt/r$
(Stiefel & Scheifele 1971; Danby 1988 §6.9), valid alike for ellipses, parabolas
and hyperbolas. With $\beta = 2\mu/r_0 - v_0^2$ (minus twice the energy),
$\eta_0 = \mathbf r_0\cdot\mathbf v_0$, $\zeta_0 = \mu - \beta r_0$ and the
Stumpff functions $c_k(z)$, the G-functions $G_k(s) = s^k c_k(\beta s^2)$ give

$$r(s) = r_0 G_0 + \eta_0 G_1 + \mu G_2,\qquad
F(s) = r_0 G_1 + \eta_0 G_2 + \mu G_3 - h = 0$$

(the universal Kepler equation; $F' = r > 0$, $F'' = \eta_0 G_0 + \zeta_0 G_1$), and

$$f - 1 = -\mu G_2/r_0,\quad g = h - \mu G_3,\quad
\dot f = -\mu G_1/(r r_0),\quad \dot g - 1 = -\mu G_2/r.$$

**Solving Kepler's equation.** $F$ increases with $s$ (its slope is $r$), so the
root is bracketed: $|s| \le |h|/q$ with $q$ the pericentre distance, and for an
ellipse, with $h$ first reduced modulo the period $P = 2\pi\mu/\beta^{3/2}$ to
$|h| \le P/2$, $|s| < 2\pi/\sqrt\beta$. From a second-order Taylor guess
($s \approx h/r_0 - \eta_0 h^2/2r_0^3$; for a step over a twentieth of the period,
the mean-motion guess $s \approx h\beta/\mu$) the Laguerre–Conway iteration (order
5; Conway 1986) converges in two or three iterations for a planet's step and in
fewer than ten at e = 0.99 over a half period; an iterate that leaves the bracket
is replaced by its midpoint (bisection), so convergence is guaranteed. The loop is
bounded (`MAX_ITERATIONS`); a body that has not converged is reported, not hidden.

**Derivatives.** The iteration runs on values without derivatives; one Newton step
from its root, $s^* = \bar s - F(\bar s)/F'(\bar s)$, carries them: at the root it
is the implicit-function derivative $ds/d\theta = -(\partial F/\partial\theta)/F'$,
so `jax.jvp` and `jax.grad` work through the drift without unrolling the loop.

**Stumpff functions.** $c_k(z) = \sum_j (-z)^j/(2j + k)!$: the series for
$|z| < 1$ (ten terms reach round-off), closed forms beyond —
$c_2 = 2\sin^2(x/2)/z$, $c_3 = (x - \sin x)/(zx)$ with $x = \sqrt z$, and their
hyperbolic twins for $z < 0$ — so that no form loses more than a few bits.

??? cite "References"

    - Stiefel & Scheifele, *Linear and Regular Celestial Mechanics*, Springer
      (1971), §11 (G-functions, universal variables).
    - Danby, *Fundamentals of Celestial Mechanics*, 2nd ed., Willmann-Bell
      (1988), §6.7–6.9 (Stumpff functions, f and g in universal variables).
    - Conway, *An improved algorithm due to Laguerre for the solution of
      Kepler's equation*, Celest. Mech. 39, 199 (1986).
    - Wisdom & Hernandez, *A fast and accurate universal Kepler solver without
      Stumpff series*, MNRAS 453, 3015 (2015) (the bracket on s).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import jax
import jax.lax as lax
import jax.numpy as jnp

MAX_ITERATIONS = 80  # bisection alone halves a bracket of 4π/√β to round-off in ~55
LAGUERRE_DEGREE = 5  # Conway's choice: converges from any start in his tests
SERIES_TERMS = 10  # |z| < 1: the 10th term of c_3 is below 1/21! ≈ 2e-20
_MEAN_MOTION_GUESS_BEYOND = 0.05  # of a period: the Taylor guess is poor past it
_CUBIC_STOP = 0.5  # × eps^(1/3): a Laguerre step this small has converged


class Stumpff(NamedTuple):
    """c_0 … c_3 at z."""

    c0: jax.Array
    c1: jax.Array
    c2: jax.Array
    c3: jax.Array


def stumpff(z: jax.Array) -> Stumpff:
    """Stumpff's c_0(z) … c_3(z) for any real z (module docstring)."""
    small = jnp.abs(z) < 1
    # Each branch sees only arguments it handles, so no branch makes a NaN that a
    # derivative of the selected one would pick up.
    zs = jnp.where(small, z, 0)
    c2_series = jnp.zeros_like(z)
    c3_series = jnp.zeros_like(z)
    for j in reversed(range(SERIES_TERMS)):
        c2_series = 1 / math.factorial(2 * j + 2) - zs * c2_series
        c3_series = 1 / math.factorial(2 * j + 3) - zs * c3_series
    # One sine and cosine of x/2 (and one exponential of y/2) serve both c_2 and
    # c_3: sin x = 2 sin(x/2) cos(x/2), sinh y = 2 sinh(y/2) cosh(y/2).
    ze = jnp.where(~small & (z > 0), z, 1)
    x = jnp.sqrt(ze)
    sine, cosine = jnp.sin(x / 2), jnp.cos(x / 2)
    c2_ellipse = 2 * sine**2 / ze
    c3_ellipse = (x - 2 * sine * cosine) / (ze * x)
    zh = jnp.where(~small & (z < 0), -z, 1)
    y = jnp.sqrt(zh)
    grow = jnp.exp(y / 2)
    sinh, cosh = (grow - 1 / grow) / 2, (grow + 1 / grow) / 2
    c2_hyperbola = 2 * sinh**2 / zh
    c3_hyperbola = (2 * sinh * cosh - y) / (zh * y)
    c2 = jnp.where(small, c2_series, jnp.where(z > 0, c2_ellipse, c2_hyperbola))
    c3 = jnp.where(small, c3_series, jnp.where(z > 0, c3_ellipse, c3_hyperbola))
    # c_k = 1/k! − z c_{k+2}
    return Stumpff(1 - z * c2, 1 - z * c3, c2, c3)


class _Orbit(NamedTuple):
    """What Kepler's equation needs of one body's start (arrays of one shape)."""

    r0: jax.Array
    eta0: jax.Array  # r0 · v0
    beta: jax.Array  # 2μ/r0 − v0²
    mu: jax.Array
    h: jax.Array  # the time to advance, reduced modulo the period for ellipses


def _g_functions(orbit: _Orbit, s: jax.Array) -> tuple[jax.Array, ...]:
    """G_0 … G_3 at s."""
    c = stumpff(orbit.beta * s * s)
    return c.c0, s * c.c1, s * s * c.c2, s * s * s * c.c3


def _kepler_equation(orbit: _Orbit, s: jax.Array) -> tuple[Any, ...]:
    """F(s), F'(s) = r(s), F''(s), and (G_0, …, G_3) at s."""
    g = _g_functions(orbit, s)
    g0, g1, g2, g3 = g
    zeta0 = orbit.mu - orbit.beta * orbit.r0
    residual = orbit.r0 * g1 + orbit.eta0 * g2 + orbit.mu * g3 - orbit.h
    radius = orbit.r0 * g0 + orbit.eta0 * g1 + orbit.mu * g2
    curvature = orbit.eta0 * g0 + zeta0 * g1
    return residual, radius, curvature, g


def _guess(orbit: _Orbit) -> jax.Array:
    """The start of the iteration: the second-order Taylor guess h/r0 −
    η0 h²/2r0³, or for a step beyond a twentieth of an ellipse's period the
    mean-motion guess hβ/μ."""
    h, r0, beta, mu = orbit.h, orbit.r0, orbit.beta, orbit.mu
    ellipse = beta > 0
    period = 2 * jnp.pi * mu / jnp.where(ellipse, beta, 1) ** 1.5
    long_step = ellipse & (jnp.abs(h) > _MEAN_MOTION_GUESS_BEYOND * period)
    return jnp.where(
        long_step, h * beta / mu, h / r0 * (1 - h * orbit.eta0 / (2 * r0**2))
    )


def _bracket(orbit: _Orbit, angular2: jax.Array) -> jax.Array:
    """B with the root in [−B, B] (module docstring: *Solving Kepler's equation*)."""
    h, beta, mu = orbit.h, orbit.beta, orbit.mu
    huge = jnp.asarray(jnp.finfo(h.dtype).max / 4, h.dtype)
    # q = L²/(μ(1 + e)), e = √(1 − βL²/μ²); a radial orbit (L = 0) has no bound.
    e = jnp.sqrt(jnp.maximum(1 - beta * angular2 / mu**2, 0))
    pericentre = angular2 / (mu * (1 + e))
    positive = pericentre > 0
    by_pericentre = jnp.where(
        positive, jnp.abs(h) / jnp.where(positive, pericentre, 1), huge
    )
    ellipse = beta > 0
    by_period = jnp.where(
        ellipse, 2 * jnp.pi / jnp.sqrt(jnp.where(ellipse, beta, 1)), huge
    )
    return jnp.minimum(by_pericentre, by_period)


def _laguerre_step(orbit: _Orbit, s: jax.Array) -> tuple[jax.Array, jax.Array]:
    """(Laguerre–Conway step from s, F(s))."""
    residual, slope, curvature, _ = _kepler_equation(orbit, s)
    n = LAGUERRE_DEGREE
    discriminant = (n - 1) ** 2 * slope**2 - n * (n - 1) * residual * curvature
    step = -n * residual / (slope + jnp.sqrt(jnp.abs(discriminant)))
    return jnp.where(residual == 0, 0, step), residual


def _universal_anomaly(orbit: _Orbit, angular2: jax.Array):
    """(s̄, converged) with F(s̄) ≈ 0: Laguerre–Conway from the guess, kept inside
    the bracket by bisection, at most `MAX_ITERATIONS` iterations.

    Laguerre's iteration converges cubically, so a step below `_CUBIC_STOP` (relative)
    leaves an error of round-off size; `kepler_drift`'s closing Newton step squares
    it again. A planet's step stops after one iteration. A bisection step stops the
    loop only once the bracket itself has shrunk to round-off.
    """
    bound = _bracket(orbit, angular2)
    s = jnp.clip(_guess(orbit), -bound, bound)
    eps = jnp.finfo(s.dtype).eps
    cubic_stop = jnp.asarray(_CUBIC_STOP * eps ** (1 / 3), s.dtype)

    def iterate(carry):
        s, low, high, iteration, _ = carry
        step, residual = _laguerre_step(orbit, s)
        low = jnp.where(residual < 0, s, low)
        high = jnp.where(residual > 0, s, high)
        new = s + step
        inside = (new >= low) & (new <= high)
        new = jnp.where(inside, new, 0.5 * (low + high))
        stop = jnp.where(inside, cubic_stop, 8 * eps) * jnp.abs(s)
        settled = (jnp.abs(new - s) <= stop) | (residual == 0)
        return new, low, high, iteration + 1, settled & jnp.isfinite(residual)

    def going(carry):
        *_, iteration, converged = carry
        return (iteration < MAX_ITERATIONS) & ~jnp.all(converged)

    carry = (s, -bound, bound, jnp.zeros((), jnp.int32), jnp.zeros(s.shape, bool))
    s, *_, converged = lax.while_loop(going, iterate, carry)
    return s, converged


def kepler_drift(
    position: jax.Array, velocity: jax.Array, mu: jax.Array, h: Any
) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Advance two-body motion by time `h`: `(position, velocity, converged)`.

    `position`, `velocity`: relative to the centre, shape (..., 3) (or (..., d));
    `mu`: the gravitational parameter G(m_centre + m), shape (...); `h`: a scalar
    or shape (...). `converged` (shape (...)) is False for a body whose Kepler
    equation did not converge within `MAX_ITERATIONS` (a non-finite state, say).
    """
    r0 = jnp.sqrt(jnp.sum(position**2, axis=-1))
    v2 = jnp.sum(velocity**2, axis=-1)
    eta0 = jnp.sum(position * velocity, axis=-1)
    beta = 2 * mu / r0 - v2
    h = jnp.broadcast_to(jnp.asarray(h, r0.dtype), r0.shape)
    ellipse = beta > 0
    period = 2 * jnp.pi * mu / jnp.where(ellipse, beta, 1) ** 1.5
    h = jnp.where(ellipse, h - period * jnp.round(h / period), h)
    orbit = _Orbit(r0, eta0, beta, mu, h)
    angular2 = jnp.maximum(r0**2 * v2 - eta0**2, 0)  # |r × v|²
    frozen = jax.tree_util.tree_map(lax.stop_gradient, (orbit, angular2))
    root, converged = _universal_anomaly(*frozen)
    equation = _kepler_equation(orbit, lax.stop_gradient(root))
    residual, radius, curvature, (g0, g1, g2, g3) = equation
    # One Newton step from the root carries the derivatives (module docstring);
    # at s* = s̄ + δ, to first order in δ (round-off at the root): G_k' = G_{k−1}.
    delta = -residual / radius
    g1, g2, g3 = g1 + delta * g0, g2 + delta * g1, g3 + delta * g2
    radius = radius + delta * curvature
    f_minus_1 = -mu * g2 / r0
    g = h - mu * g3
    fdot = -mu * g1 / (radius * r0)
    gdot_minus_1 = -mu * g2 / radius
    new_position = position + (
        f_minus_1[..., None] * position + g[..., None] * velocity
    )
    new_velocity = velocity + (
        fdot[..., None] * position + gdot_minus_1[..., None] * velocity
    )
    return new_position, new_velocity, converged
