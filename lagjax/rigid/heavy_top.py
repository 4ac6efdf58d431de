r"""Closed forms for the heavy symmetric top: precession and nutation bounds.

A symmetric top ($I_1 = I_2$ about its fixed tip, $I_3$ about its axis) with its
centre of mass a distance $l$ up the axis, in gravity, has

$$ L = \tfrac12 I_1(\dot\theta^2 + \dot\phi^2\sin^2\theta)
     + \tfrac12 I_3(\dot\psi + \dot\phi\cos\theta)^2 - Mgl\cos\theta $$

in the course text's Euler angles. $\phi$ and $\psi$ are cyclic: the spin
$\omega_3 = \dot\psi + \dot\phi\cos\theta$, $p_\psi = I_3\omega_3$ and
$p_\phi = I_1\dot\phi\sin^2\theta + I_3\omega_3\cos\theta$ are constant, as is the
energy. With $u = \cos\theta$, $a = p_\psi/I_1$, $b = p_\phi/I_1$,
$\beta = 2Mgl/I_1$ and $\alpha = 2E'/I_1$, $E' = E - \tfrac12 I_3\omega_3^2$,

$$ \dot u^2 = f(u) = (1 - u^2)(\alpha - \beta u) - (b - a u)^2, $$

a cubic with two roots $u_1 \le u_2$ in $[-1, 1]$ (and one above 1): $\theta$
nods between $\arccos u_2$ and $\arccos u_1$.

**Steady precession** ($\dot\theta = 0$) at angle $\theta$ needs
$I_1\cos\theta\,\dot\phi^2 - I_3\omega_3\dot\phi + Mgl = 0$, a slow and a fast
root, which for a fast top ($I_3^2\omega_3^2 \gg 4 I_1 Mgl\cos\theta$) are the
gyroscopic approximations

$$ \dot\phi_{\text{slow}} \approx \frac{Mgl}{I_3\omega_3}, \qquad
   \dot\phi_{\text{fast}} \approx \frac{I_3\omega_3}{I_1\cos\theta}, $$

with relative errors about $\epsilon = I_1 Mgl\cos\theta / (I_3\omega_3)^2$. A fast
top released with $\dot\theta = \dot\phi = 0$ nods at about $I_3\omega_3/I_1$ and
drifts on average at the slow rate.

References: Goldstein, Poole & Safko, *Classical Mechanics*, 3rd ed., §5.7;
Landau & Lifshitz, *Mechanics*, §35; the course text §4.3 (Euler angles).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def steady_precession_rates(
    i1: jax.Array, i3: jax.Array, mgl: jax.Array, omega_3: jax.Array, theta: jax.Array
) -> tuple[jax.Array, jax.Array]:
    r"""The exact (slow, fast) roots of $I_1\cos\theta\,\dot\phi^2 - I_3\omega_3
    \dot\phi + Mgl = 0$.

    Written as $2Mgl/r$ and $r/(2I_1\cos\theta)$ with $r = I_3\omega_3 +
    \mathrm{sign}(\omega_3)\sqrt{D}$, so neither root cancels. Needs the discriminant
    $D = I_3^2\omega_3^2 - 4 I_1 Mgl\cos\theta \ge 0$ (a fast enough top).
    """
    spin_momentum = i3 * omega_3
    cos_theta = jnp.cos(theta)
    discriminant = spin_momentum**2 - 4 * i1 * mgl * cos_theta
    r = spin_momentum + jnp.sign(omega_3) * jnp.sqrt(discriminant)
    return 2 * mgl / r, r / (2 * i1 * cos_theta)


def gyroscopic_precession_rates(
    i1: jax.Array, i3: jax.Array, mgl: jax.Array, omega_3: jax.Array, theta: jax.Array
) -> tuple[jax.Array, jax.Array]:
    r"""The fast-top approximations $(Mgl/I_3\omega_3,\ I_3\omega_3/I_1\cos\theta)$."""
    return mgl / (i3 * omega_3), i3 * omega_3 / (i1 * jnp.cos(theta))


def turning_point_cubic(
    i1: jax.Array, i3: jax.Array, mgl: jax.Array, angles: jax.Array, rates: jax.Array
) -> jax.Array:
    r"""Coefficients $(c_3, c_2, c_1, c_0)$ of $f(u) = \dot u^2$ from a state.

    $f(u) = \beta u^3 - (\alpha + a^2)u^2 + (2ab - \beta)u + \alpha - b^2$, with the
    constants of motion taken from Euler angles $(\phi, \theta, \psi)$ and their rates.
    """
    theta = angles[1]
    phi_dot, theta_dot, psi_dot = rates[0], rates[1], rates[2]
    cos_theta, sin_theta = jnp.cos(theta), jnp.sin(theta)
    omega_3 = psi_dot + phi_dot * cos_theta
    p_phi = i1 * phi_dot * sin_theta**2 + i3 * omega_3 * cos_theta
    reduced_energy = (
        0.5 * i1 * (theta_dot**2 + (phi_dot * sin_theta) ** 2) + mgl * cos_theta
    )
    alpha, beta = 2 * reduced_energy / i1, 2 * mgl / i1
    a, b = i3 * omega_3 / i1, p_phi / i1
    return jnp.stack([beta, -(alpha + a**2), 2 * a * b - beta, alpha - b**2])


def _three_real_roots(coefficients: jax.Array) -> jax.Array:
    """Ascending roots of a cubic known to have three real roots.

    Viète's trigonometric form, then two Newton steps on the cubic itself to remove
    the round-off of the shift and the arccos.
    """
    c3, c2, c1, c0 = coefficients / coefficients[0]
    shift = c2 / 3
    p = c1 - c2 * shift
    q = 2 * shift**3 - shift * c1 + c0
    radius = 2 * jnp.sqrt(jnp.maximum(-p / 3, 0.0))
    cosine = jnp.clip(3 * q / (p * radius), -1.0, 1.0)
    angle = jnp.arccos(cosine) / 3
    roots = radius * jnp.cos(angle - 2 * jnp.pi * jnp.arange(3) / 3) - shift

    def newton(u):
        value = ((c3 * u + c2) * u + c1) * u + c0
        slope = (3 * c3 * u + 2 * c2) * u + c1
        return jnp.where(slope != 0, u - value / jnp.where(slope != 0, slope, 1.0), u)

    return jnp.sort(newton(newton(roots)))


def nutation_bounds(
    i1: jax.Array, i3: jax.Array, mgl: jax.Array, angles: jax.Array, rates: jax.Array
) -> tuple[jax.Array, jax.Array]:
    r"""$(\theta_{\min}, \theta_{\max})$ from the two roots of $f(u)$ in $[-1, 1]$.

    Needs gravity ($Mgl > 0$: f is then a true cubic with its third root above 1).
    """
    u1, u2, _ = _three_real_roots(turning_point_cubic(i1, i3, mgl, angles, rates))
    return jnp.arccos(jnp.clip(u2, -1.0, 1.0)), jnp.arccos(jnp.clip(u1, -1.0, 1.0))
