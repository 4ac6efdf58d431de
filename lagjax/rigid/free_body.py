r"""Closed forms for the torque-free rigid body: precession, Poinsot, its period.

**Symmetric body** ($I_1 = I_2$, course text eq. 4.45–4.52): $\omega_3$ is constant
and $(\omega_1, \omega_2)$ turns about the symmetry axis, in the body, at

$$ \Omega = \frac{I_1 - I_3}{I_1}\,\omega_3 \qquad
   (\dot\omega_1 = \Omega\,\omega_2,\ \dot\omega_2 = -\Omega\,\omega_1), $$

so $\boldsymbol\omega$ sweeps the body cone. Seen from space the symmetry axis and
$\boldsymbol\omega$ turn about the fixed $\mathbf L$ at $|\mathbf L|/I_1$ (the
space cone; Landau & Lifshitz §33).

**Asymmetric body** ($I_1 < I_2 < I_3$): with energy $E$ and $M = |\mathbf L|$,
$\boldsymbol\omega(t)$ is periodic, in Jacobi elliptic functions of
$\tau = \nu t$ with parameter $m = k^2$ (Landau & Lifshitz §37). Writing
$A = (I_3 - I_2)(M^2 - 2EI_1)$ and $B = (I_2 - I_1)(2EI_3 - M^2)$ (both $\ge 0$),

$$ \nu^2 = \frac{\max(A, B)}{I_1 I_2 I_3}, \qquad m = \frac{\min(A, B)}{\max(A, B)},
   \qquad T = \frac{4K(m)}{\nu}, $$

$A > B$ when $M^2 > 2EI_2$ (motion about the $I_3$ axis), $A < B$ about the $I_1$
axis. Near the intermediate axis $m \to 1$ and $K$ grows like
$\tfrac12\ln(16/(1-m))$: the body holds one orientation for long and flips quickly
(Dzhanibekov's effect), the intermediate component of $\boldsymbol\omega$ changing
sign every $T/2$.

$K(m) = \pi / (2\,\mathrm{AGM}(1, \sqrt{1-m}))$ by Gauss's arithmetic–geometric mean,
which converges quadratically.

**Poinsot** (course text §4.8.1): $\boldsymbol\rho = \boldsymbol\omega/\sqrt{2T}$ lies
on the inertia ellipsoid $\boldsymbol\rho^T\mathbf I\boldsymbol\rho = 1$, which rolls
on the invariable plane normal to $\mathbf L$ at distance $\sqrt{2T}/|\mathbf L|$.

References: the course text §4.8; Landau & Lifshitz, *Mechanics*, §33 and §37;
Goldstein, Poole & Safko, *Classical Mechanics*, 3rd ed., §5.6; Abramowitz &
Stegun, *Handbook of Mathematical Functions*, §17.6.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from lagjax.special_functions import complete_elliptic_k_from_complement


def symmetric_precession_rate(moments: jax.Array, omega_3: jax.Array) -> jax.Array:
    r"""$\Omega = (I_1 - I_3)\,\omega_3 / I_1$ (course text eq. 4.47), body frame."""
    return (moments[0] - moments[2]) * omega_3 / moments[0]


def space_precession_rate(moments: jax.Array, angular_momentum: jax.Array) -> jax.Array:
    r"""$|\mathbf L| / I_1$: the symmetry axis and $\boldsymbol\omega$ about
    $\mathbf L$, space frame."""
    return jnp.linalg.norm(angular_momentum) / moments[0]


def free_body_period(
    moments: jax.Array, energy: jax.Array, angular_momentum_squared: jax.Array
) -> jax.Array:
    r"""The period $4K(m)/\nu$ of $\boldsymbol\omega(t)$ in the body frame.

    `moments` are sorted here, so any labelling works. For a symmetric body (two
    equal moments) $m = 0$ and this is $2\pi/|\Omega|$, the precession period; a
    spherical top has no period (0/0). On the separatrix $M^2 = 2EI_2$ the period
    is infinite.
    """
    i1, i2, i3 = jnp.sort(jnp.asarray(moments))
    m2, two_e = angular_momentum_squared, 2 * energy
    about_largest = (i3 - i2) * (m2 - two_e * i1)
    about_smallest = (i2 - i1) * (two_e * i3 - m2)
    larger = jnp.maximum(about_largest, about_smallest)
    nu = jnp.sqrt(larger / (i1 * i2 * i3))
    # 1 − m = |A − B| / max(A, B), with A − B = (I3 − I1)(M² − 2E I2).
    complement = (i3 - i1) * jnp.abs(m2 - two_e * i2) / larger
    return 4 * complete_elliptic_k_from_complement(complement) / nu


def invariable_plane_distance(
    energy: jax.Array, angular_momentum: jax.Array
) -> jax.Array:
    r"""$\sqrt{2T}/|\mathbf L|$: from the fixed point to the invariable plane."""
    return jnp.sqrt(2 * energy) / jnp.linalg.norm(angular_momentum)
