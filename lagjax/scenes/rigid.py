r"""Rigid-body scenes: the torque-free body and the heavy symmetric top.

Each scene gives its physics two ways that must agree:

- `system()`: a `Lagrangian` in the course text's z-x-z Euler angles
  $(\phi, \theta, \psi)$, the scene convention (state `(angles, rates)`); singular
  at $\sin\theta = 0$ (gimbal lock), so the defaults start well away from it;
- `rigid_body()` with `initial_body_state()`: the same body as a `RigidBody` on
  `(quaternion, body angular momentum)`, for the Lie–Poisson solvers of
  `lagjax.solvers.rigid`; integrate it with `args=scene`.

Known answers: the symmetric body's precession rate (course text eq. 4.47), the
asymmetric body's period (elliptic K), the top's nutation bounds (roots of the
cubic $f(u)$), and the constants of motion.

References: the course text §4.3, §4.7–4.8; Goldstein, Poole & Safko, *Classical
Mechanics*, 3rd ed., §5.6–5.7; Landau & Lifshitz, *Mechanics*, §35–37.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp

from lagjax.mechanics.lagrangian import Lagrangian
from lagjax.rigid.body import RigidBody
from lagjax.rigid.euler_angles import (
    euler_zxz_body_angular_velocity,
    euler_zxz_to_quaternion,
    euler_zxz_to_rotation,
)
from lagjax.rigid.free_body import free_body_period, symmetric_precession_rate
from lagjax.rigid.heavy_top import nutation_bounds
from lagjax.rigid.quaternion import quaternion_to_matrix

from .base import AbstractScene


def euler_rates_from_body_omega(angles: jax.Array, omega_body: jax.Array) -> jax.Array:
    r"""$(\dot\phi, \dot\theta, \dot\psi)$ giving the body angular velocity
    $\boldsymbol\omega$; the inverse of Goldstein eq. 4.87, singular at
    $\sin\theta = 0$."""
    theta, psi = angles[1], angles[2]
    w1, w2, w3 = omega_body[0], omega_body[1], omega_body[2]
    phi_dot = (w1 * jnp.sin(psi) + w2 * jnp.cos(psi)) / jnp.sin(theta)
    theta_dot = w1 * jnp.cos(psi) - w2 * jnp.sin(psi)
    return jnp.stack([phi_dot, theta_dot, w3 - phi_dot * jnp.cos(theta)])


def _free_body_lagrangian(q, qdot, t, scene):
    omega = euler_zxz_body_angular_velocity(q, qdot)
    return 0.5 * jnp.sum(scene.moments * omega**2)


def _body_motion(trajectory: Any, moments: jax.Array) -> tuple[jax.Array, jax.Array]:
    """(rotation matrices, body angular velocities) along either kind of run."""
    if trajectory.q.shape[-1] == 4:  # (quaternion, body momentum)
        return quaternion_to_matrix(trajectory.q), trajectory.p / moments
    omega = jax.vmap(euler_zxz_body_angular_velocity)(trajectory.q, trajectory.qdot)
    return jax.vmap(euler_zxz_to_rotation)(trajectory.q), omega


class TorqueFreeBody(AbstractScene):
    """A free rigid body: principal moments, a start orientation and spin.

    `checks` compares the conserved energy and space angular momentum, and the
    period (asymmetric) or precession rate (symmetric, `moments[0] == moments[1]`)
    measured by the caller, with closed forms via `period()` / `precession_rate()`.
    """

    moments: jax.Array
    omega0: jax.Array
    angles0: jax.Array

    default_t1 = 20.0
    default_dt = 1e-3

    def __init__(
        self,
        moments: Any = (1.0, 2.0, 3.0),
        omega0: Any = (0.3, 1.0, 0.2),
        angles0: Any = (0.3, 1.1, -0.4),
    ):
        self.moments = jnp.asarray(moments, dtype=float)
        self.omega0 = jnp.asarray(omega0, dtype=float)
        self.angles0 = jnp.asarray(angles0, dtype=float)

    def system(self) -> Lagrangian:
        return Lagrangian(_free_body_lagrangian, quadratic_in_velocity=True)

    def initial_state(self) -> tuple[jax.Array, jax.Array]:
        return self.angles0, euler_rates_from_body_omega(self.angles0, self.omega0)

    def rigid_body(self) -> RigidBody:
        return RigidBody(self.moments)

    def initial_body_state(self) -> tuple[jax.Array, jax.Array]:
        return euler_zxz_to_quaternion(self.angles0), self.moments * self.omega0

    def energy(self) -> jax.Array:
        return 0.5 * jnp.sum(self.moments * self.omega0**2)

    def angular_momentum_space(self) -> jax.Array:
        return euler_zxz_to_rotation(self.angles0) @ (self.moments * self.omega0)

    def period(self) -> jax.Array:
        """Period of ω(t) in the body (asymmetric body)."""
        momentum_squared = jnp.sum((self.moments * self.omega0) ** 2)
        return free_body_period(self.moments, self.energy(), momentum_squared)

    def precession_rate(self) -> jax.Array:
        """Ω = (I1 − I3) ω3 / I1 (symmetric body, I1 = I2)."""
        return symmetric_precession_rate(self.moments, self.omega0[2])

    def checks(self, trajectory: Any) -> dict[str, tuple[jax.Array, jax.Array]]:
        rotation, omega = _body_motion(trajectory, self.moments)
        space_momentum = jnp.einsum("tij,tj->ti", rotation, self.moments * omega)
        energy = 0.5 * jnp.sum(self.moments * omega**2, axis=-1)
        return {
            "energy(t1)": (energy[-1], self.energy()),
            "L_space(t1)": (space_momentum[-1], self.angular_momentum_space()),
        }


def _heavy_top_lagrangian(q, qdot, t, scene):
    theta = q[1]
    phi_dot, theta_dot, psi_dot = qdot[0], qdot[1], qdot[2]
    transverse = 0.5 * scene.i1 * (theta_dot**2 + (phi_dot * jnp.sin(theta)) ** 2)
    axial = 0.5 * scene.i3 * (psi_dot + phi_dot * jnp.cos(theta)) ** 2
    return transverse + axial - scene.mgl * jnp.cos(theta)


def _gravity_potential(rotation, t, scene):
    # The centre of mass sits at l·e3 in the body; its height is l·(R e3)_z.
    return scene.mgl * rotation[2, 2]


class HeavySymmetricTop(AbstractScene):
    r"""A symmetric top on a fixed tip in gravity (Goldstein §5.7).

    **Arguments:** `i1`, `i3` (moments about the tip), `mgl` ($M g l$), the start
    tilt `theta0`, the spin `spin` ($\omega_3$), and the start rates `phi_dot0`,
    `theta_dot0` (default 0: a top released from rest in $\phi$ and $\theta$).
    The defaults are a fast top, $\epsilon = I_1 Mgl\cos\theta/(I_3\omega_3)^2
    \approx 2\cdot10^{-3}$.
    """

    i1: jax.Array
    i3: jax.Array
    mgl: jax.Array
    theta0: jax.Array
    spin: jax.Array
    phi_dot0: jax.Array
    theta_dot0: jax.Array

    default_t1 = 5.0
    default_dt = 1e-3

    def __init__(
        self,
        i1: Any = 1.0,
        i3: Any = 0.5,
        mgl: Any = 1.0,
        theta0: Any = 0.5,
        spin: Any = 40.0,
        phi_dot0: Any = 0.0,
        theta_dot0: Any = 0.0,
    ):
        self.i1, self.i3, self.mgl = (
            jnp.asarray(x, dtype=float) for x in (i1, i3, mgl)
        )
        self.theta0 = jnp.asarray(theta0, dtype=float)
        self.spin = jnp.asarray(spin, dtype=float)
        self.phi_dot0 = jnp.asarray(phi_dot0, dtype=float)
        self.theta_dot0 = jnp.asarray(theta_dot0, dtype=float)

    def system(self) -> Lagrangian:
        return Lagrangian(_heavy_top_lagrangian, quadratic_in_velocity=True)

    def initial_state(self) -> tuple[jax.Array, jax.Array]:
        angles = jnp.stack([0.0 * self.theta0, self.theta0, 0.0 * self.theta0])
        psi_dot = self.spin - self.phi_dot0 * jnp.cos(self.theta0)
        return angles, jnp.stack([self.phi_dot0, self.theta_dot0, psi_dot])

    def rigid_body(self) -> RigidBody:
        return RigidBody(jnp.stack([self.i1, self.i1, self.i3]), _gravity_potential)

    def initial_body_state(self) -> tuple[jax.Array, jax.Array]:
        angles, rates = self.initial_state()
        omega = euler_zxz_body_angular_velocity(angles, rates)
        return euler_zxz_to_quaternion(angles), self.rigid_body().moments * omega

    def nutation_bounds(self) -> tuple[jax.Array, jax.Array]:
        """(θ_min, θ_max) from the roots of the turning-point cubic."""
        return nutation_bounds(self.i1, self.i3, self.mgl, *self.initial_state())

    def checks(self, trajectory: Any) -> dict[str, tuple[jax.Array, jax.Array]]:
        rotation, omega = _body_motion(trajectory, self.rigid_body().moments)
        theta = jnp.arccos(jnp.clip(rotation[:, 2, 2], -1.0, 1.0))
        theta_min, theta_max = self.nutation_bounds()
        spin = omega[:, 2]
        return {
            "theta_min": (jnp.min(theta), theta_min),
            "theta_max": (jnp.max(theta), theta_max),
            "spin(t1)": (spin[-1], self.spin),
        }
