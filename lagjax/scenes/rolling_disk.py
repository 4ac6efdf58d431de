r"""A thin disk rolling without slipping on a plane: nonholonomic constraints.

The scene `RollingDisk` of the constrained systems (`lagjax.scenes.constrained`):
the rolling condition — the disk's material point at contact is at rest — is linear
in the velocities and not integrable (the course text §3.1.3, eq. 3.12–3.13), so it
is stated as a velocity constraint next to L (`Constraints(velocity=...)`) in the
standard coordinates: contact point, tilt, heading and spin. The disk's frame,
centre and angular velocity are the helpers below.

`checks(trajectory)` assumes a run from `initial_state()` at $t = 0$.

References: the course text §3.1; Bloch, *Nonholonomic Mechanics and Control*
(2003), §1.4 (the rolling disk); O'Reilly, Nonlinear Dynamics 10, 287 (1996)
(steady motions of a rolling disk).
"""

from __future__ import annotations

import math
from typing import ClassVar

import jax
import jax.numpy as jnp

from lagjax.mechanics.constraints import Constraints
from lagjax.mechanics.lagrangian import Lagrangian
from lagjax.scenes.base import AbstractScene, Interval, StateKind, parameter


def _disk_frame(q):
    """Unit vectors (e_t rolling direction, a disk axis, u contact → centre)."""
    _, _, tilt, heading, _ = q
    along = jnp.stack([jnp.cos(heading), jnp.sin(heading), 0.0])
    across = jnp.stack([-jnp.sin(heading), jnp.cos(heading), 0.0])
    # in q's precision: a float64 constant would lift a float32 run to float64
    vertical = jnp.array([0.0, 0.0, 1.0], dtype=jnp.result_type(tilt))
    axis = jnp.cos(tilt) * across + jnp.sin(tilt) * vertical
    up = -jnp.sin(tilt) * across + jnp.cos(tilt) * vertical
    return along, axis, up


def _disk_centre(q, scene):
    contact = jnp.stack([q[0], q[1], 0.0])
    return contact + scene.radius * _disk_frame(q)[2]


def _disk_motion(q, qdot, scene):
    """Centre velocity and angular velocity ω = φ̇ ẑ + θ̇ e_t + ψ̇ a."""
    centre_velocity = jax.jvp(lambda c: _disk_centre(c, scene), (q,), (qdot,))[1]
    along, axis, _ = _disk_frame(q)
    tilt_rate, heading_rate, spin_rate = qdot[2], qdot[3], qdot[4]
    vertical = jnp.array([0.0, 0.0, 1.0], dtype=qdot.dtype)
    omega = heading_rate * vertical + tilt_rate * along + spin_rate * axis
    return centre_velocity, omega


def _disk_lagrangian(q, qdot, t, scene):
    centre_velocity, omega = _disk_motion(q, qdot, scene)
    _, axis, _ = _disk_frame(q)
    spin = jnp.dot(omega, axis)
    diameter_moment, axis_moment = scene.moments()
    kinetic = 0.5 * scene.mass * jnp.sum(centre_velocity**2) + 0.5 * (
        diameter_moment * (jnp.sum(omega**2) - spin**2) + axis_moment * spin**2
    )
    return kinetic - scene.mass * scene.gravity * _disk_centre(q, scene)[2]


def _contact_point_velocity(q, qdot, scene):
    """v_P = ċ + ω × (P − c), the velocity of the disk's material point at contact."""
    centre_velocity, omega = _disk_motion(q, qdot, scene)
    return centre_velocity + jnp.cross(omega, -scene.radius * _disk_frame(q)[2])


def _no_slip(q, qdot, t, scene):
    # Its vertical part vanishes identically (the contact stays on the plane), so
    # only the two horizontal rows are independent constraints.
    return _contact_point_velocity(q, qdot, scene)[:2]


# Tilt from the vertical: at ±π/2 the disk lies flat on the floor.
_OFF_THE_GROUND = Interval(
    -math.pi / 2, math.pi / 2, include_low=False, include_high=False
)


class RollingDisk(AbstractScene):
    r"""A thin disk rolling without slipping on a plane: nonholonomic constraints.

    Coordinates $q = (x, y, \theta, \varphi, \psi)$: the contact point, the tilt
    from the vertical, the heading and the spin; orientation $R_z(\varphi)
    R_x(\theta)R_y(\psi)$, so $\boldsymbol\omega = \dot\varphi\hat z + \dot\theta\hat
    e_t + \dot\psi\hat a$ ($\hat e_t$ the rolling direction, $\hat a$ the axis). With
    the centre $\mathbf c = \mathbf P + R\hat u$ ($\hat u$ from contact to centre),

    $$ L = \tfrac12 m|\dot{\mathbf c}|^2 + \tfrac12 I_1(|\boldsymbol\omega|^2 -
       \omega_a^2) + \tfrac12 I_3\omega_a^2 - mgR\cos\theta, $$

    $I_1 = mR^2/4$, $I_3 = mR^2/2$. Rolling: the material point at contact is at rest,
    $\dot{\mathbf c} + \boldsymbol\omega\times(-R\hat u) = 0$ (eq. 3.13), two
    independent rows linear in $\dot q$ and not integrable. Friction at the contact
    does no work, so the energy is conserved. Steady motion at constant tilt θ,
    heading rate Ω and $\sigma = \omega_a$ (Newton–Euler about the centre) needs
    $I_1\Omega^2\sin\theta\cos\theta - (I_3 + mR^2)\sigma\Omega\cos\theta =
    mgR\sin\theta$ (`steady_spin_rate`).

    **Parameters** (SI): `mass` (1 kg), `radius` R (0.1 m), `gravity` (9.81 m/s²),
    `tilt` θ₀ (0.3 rad), `heading_rate` φ̇₀ (3 rad/s), `spin_rate` ψ̇₀ (−15 rad/s).
    """

    mass: jax.Array = parameter(1.0, positive=True)
    radius: jax.Array = parameter(0.1, positive=True)
    gravity: jax.Array = parameter(9.81, positive=True)
    tilt: jax.Array = parameter(0.3, within=_OFF_THE_GROUND, angle=True)
    heading_rate: jax.Array = parameter(3.0)
    spin_rate: jax.Array = parameter(-15.0)

    default_t1: ClassVar[float] = 3.0
    default_dt: ClassVar[float] = 1e-3
    state_kind: ClassVar[StateKind] = "velocity"
    coordinate_names: ClassVar[tuple[str, ...]] = ("x", "y", "θ", "φ", "ψ")
    coordinate_units: ClassVar[tuple[str, ...]] = ("m", "m", "rad", "rad", "rad")

    def moments(self) -> tuple[jax.Array, jax.Array]:
        """(I₁ about a diameter, I₃ about the axis) of a thin uniform disk."""
        return 0.25 * self.mass * self.radius**2, 0.5 * self.mass * self.radius**2

    def system(self) -> Lagrangian:
        return Lagrangian(_disk_lagrangian, constraints=Constraints(velocity=_no_slip))

    def initial_state(self) -> tuple[jax.Array, jax.Array]:
        """At the origin heading along x, tilted, with the contact at rest."""
        q = jnp.stack([0.0, 0.0, self.tilt, 0.0, 0.0])
        rates = jnp.stack([0.0, 0.0, 0.0, self.heading_rate, self.spin_rate])
        # v_P is (ẋ, ẏ) plus terms in the angle rates: choose (ẋ, ẏ) to cancel them.
        slip = _no_slip(q, rates, 0.0, self)
        return q, rates.at[:2].set(-slip)

    def steady_spin_rate(self) -> jax.Array:
        """ψ̇ for steady rolling at `tilt` and `heading_rate` (from the condition above)."""
        theta, heading_rate = self.tilt, self.heading_rate
        diameter_moment, axis_moment = self.moments()
        mgr = self.mass * self.gravity * self.radius
        numerator = (
            diameter_moment * heading_rate**2 * jnp.cos(theta) - mgr
        ) * jnp.sin(theta)
        denominator = (axis_moment + self.mass * self.radius**2) * heading_rate
        axial_rate = numerator / (denominator * jnp.cos(theta))
        return axial_rate - heading_rate * jnp.sin(theta)

    def checks(self, trajectory) -> dict[str, tuple[jax.Array, jax.Array]]:
        """Energy conserved; the centre moves as ω × (c − P), i.e. no slip."""
        energy = trajectory.energy()
        q0, qdot0 = self.initial_state()
        energy0 = self.system().energy(q0, qdot0, 0.0, self)

        def velocities(q, qdot):
            centre_velocity, omega = _disk_motion(q, qdot, self)
            return centre_velocity, jnp.cross(omega, self.radius * _disk_frame(q)[2])

        centre, rolling = jax.vmap(velocities)(trajectory.q, trajectory.qdot)
        return {
            "energy": (energy, energy0 * jnp.ones_like(energy)),
            "rolling": (centre, rolling),
        }
