r"""Euler angles in the z-x-z convention of the course text (eq. 4.12–4.20).

The angles $(\phi, \theta, \psi)$ are three successive turns of the axes: by $\phi$
about z, by $\theta$ about the new x (the line of nodes), by $\psi$ about the new z.
Space components $\mathbf x$ become body components $\mathbf x' = A\,\mathbf x$ with

$$ A = A_\psi A_\theta A_\phi = \begin{pmatrix}
   c_\psi c_\phi - c_\theta s_\phi s_\psi & c_\psi s_\phi + c_\theta c_\phi s_\psi
     & s_\psi s_\theta \\
   -s_\psi c_\phi - c_\theta s_\phi c_\psi & -s_\psi s_\phi + c_\theta c_\phi c_\psi
     & c_\psi s_\theta \\
   s_\theta s_\phi & -s_\theta c_\phi & c_\theta \end{pmatrix}
   \qquad \text{(eq. 4.20)}, $$

orthogonal ($A^T = A^{-1}$). (Eq. 4.18 writes the product in the opposite order;
the explicit matrix 4.20 is $A_\psi A_\theta A_\phi$, the first turn acting first.)
The body-to-space rotation used with quaternions is $R = A^T$.

The body-frame angular velocity from the angle rates (Goldstein eq. 4.87) is

$$ \boldsymbol\omega' = \begin{pmatrix}
   \dot\phi\, s_\theta s_\psi + \dot\theta\, c_\psi \\
   \dot\phi\, s_\theta c_\psi - \dot\theta\, s_\psi \\
   \dot\phi\, c_\theta + \dot\psi \end{pmatrix}. $$

At $\sin\theta = 0$ the map from rates to $\boldsymbol\omega$ loses rank — only
$\dot\phi + \dot\psi$ (or $\dot\phi - \dot\psi$) is seen — which is the gimbal lock
that makes a Lagrangian in Euler angles singular there.

References: the course text §4.3; Goldstein, Poole & Safko, *Classical Mechanics*,
3rd ed., §4.4 and §4.9.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from lagjax.rigid.quaternion import axis_angle_quaternion, quaternion_multiply


def _unpack(angles: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
    angles = jnp.asarray(angles)
    if angles.shape[-1:] != (3,):
        raise ValueError(
            f"Euler angles (phi, theta, psi) have shape (3,), got {angles.shape}"
        )
    return angles[..., 0], angles[..., 1], angles[..., 2]


def euler_zxz_matrix(angles: jax.Array) -> jax.Array:
    r"""The course text's $A$ (eq. 4.20): space components → body components."""
    phi, theta, psi = _unpack(angles)
    cf, sf = jnp.cos(phi), jnp.sin(phi)
    ct, st = jnp.cos(theta), jnp.sin(theta)
    cp, sp = jnp.cos(psi), jnp.sin(psi)
    rows = [
        [cp * cf - ct * sf * sp, cp * sf + ct * cf * sp, sp * st],
        [-sp * cf - ct * sf * cp, -sp * sf + ct * cf * cp, cp * st],
        [st * sf, -st * cf, ct],
    ]
    return jnp.stack([jnp.stack(row, axis=-1) for row in rows], axis=-2)


def euler_zxz_to_rotation(angles: jax.Array) -> jax.Array:
    """$R = A^T$: body components → space components."""
    return jnp.swapaxes(euler_zxz_matrix(angles), -1, -2)


def euler_zxz_to_quaternion(angles: jax.Array) -> jax.Array:
    r"""$q = q_z(\phi) \otimes q_x(\theta) \otimes q_z(\psi)$, the quaternion of
    $R = A^T$."""
    phi, theta, psi = _unpack(angles)
    dtype = jnp.result_type(phi)
    z_axis = jnp.array([0.0, 0.0, 1.0], dtype=dtype)
    x_axis = jnp.array([1.0, 0.0, 0.0], dtype=dtype)
    first = axis_angle_quaternion(z_axis, phi)
    nodes = axis_angle_quaternion(x_axis, theta)
    last = axis_angle_quaternion(z_axis, psi)
    return quaternion_multiply(quaternion_multiply(first, nodes), last)


def rotation_to_euler_zxz(rotation: jax.Array) -> jax.Array:
    r"""$(\phi, \theta, \psi)$ with $\theta \in [0, \pi]$ from $R = A^T$.

    At gimbal lock ($\sin\theta = 0$) only $\phi \pm \psi$ is defined; there
    $\psi = 0$ is chosen.
    """
    r = jnp.asarray(rotation)
    sin_theta = jnp.hypot(r[..., 0, 2], r[..., 1, 2])
    theta = jnp.arctan2(sin_theta, r[..., 2, 2])
    locked = sin_theta < 1e-12
    phi = jnp.where(
        locked,
        jnp.arctan2(r[..., 1, 0], r[..., 0, 0]),
        jnp.arctan2(r[..., 0, 2], -r[..., 1, 2]),
    )
    psi = jnp.where(locked, 0.0, jnp.arctan2(r[..., 2, 0], r[..., 2, 1]))
    return jnp.stack([phi, theta, psi], axis=-1)


def euler_zxz_body_angular_velocity(angles: jax.Array, rates: jax.Array) -> jax.Array:
    r"""$\boldsymbol\omega$ in body components from $(\dot\phi, \dot\theta,
    \dot\psi)$."""
    _, theta, psi = _unpack(angles)
    phi_dot, theta_dot, psi_dot = _unpack(rates)
    st, ct = jnp.sin(theta), jnp.cos(theta)
    sp, cp = jnp.sin(psi), jnp.cos(psi)
    return jnp.stack(
        [
            phi_dot * st * sp + theta_dot * cp,
            phi_dot * st * cp - theta_dot * sp,
            phi_dot * ct + psi_dot,
        ],
        axis=-1,
    )


def euler_zxz_space_angular_velocity(angles: jax.Array, rates: jax.Array) -> jax.Array:
    r"""$\boldsymbol\omega$ in space components:
    $\dot\phi\,\hat z + \dot\theta\,\hat n_{\text{nodes}} + \dot\psi\,\hat z'$."""
    phi, theta, _ = _unpack(angles)
    phi_dot, theta_dot, psi_dot = _unpack(rates)
    sf, cf = jnp.sin(phi), jnp.cos(phi)
    st, ct = jnp.sin(theta), jnp.cos(theta)
    return jnp.stack(
        [
            theta_dot * cf + psi_dot * st * sf,
            theta_dot * sf - psi_dot * st * cf,
            phi_dot + psi_dot * ct,
        ],
        axis=-1,
    )
