r"""Constrained systems in redundant coordinates: the constraint forces, measured.

The plain Lagrangian method eliminates a constraint by choosing coordinates that
satisfy it, and so never sees the force that maintains it — the course text says so
of Atwood's rope (§3.4, example 2) and of the wire that turns a bead (example 3).
Here each system keeps redundant coordinates and states its constraint next to L
(`Lagrangian(L, constraints=...)`); the Lagrange multipliers are the forces:

- `CartesianPendulum`: (x, y) with $\sqrt{x^2 + y^2} = l$; the rod's tension
  $T = m(g\cos\theta + l\dot\theta^2) = mg(3\cos\theta - 2\cos\theta_0)$ from rest.
- `CartesianAtwoodMachine`: both depths, $y_1 + y_2 = l$; tension
  $2M_1M_2g/(M_1 + M_2)$.
- `CartesianRotatingWireBead`: (x, y) with the rheonomic $x\sin\omega t - y\cos\omega t
  = 0$; the wire's sideways push is the Coriolis force $2m\omega\dot r$.
- `RollingDisk`: a tilted disk rolling without slipping, a nonholonomic constraint
  (the course text §3.1.3, eq. 3.12–3.13) in the standard coordinates.

Every `checks(trajectory)` assumes a run from `initial_state()` at $t = 0$.

References: the course text §3.1 and §3.4; Goldstein, Poole & Safko, *Classical
Mechanics*, 3rd ed., §2.4 (Lagrange multipliers: hoop rolling on an incline);
Bloch, *Nonholonomic Mechanics and Control* (2003), §1.4 (the rolling disk);
O'Reilly, Nonlinear Dynamics 10, 287 (1996) (steady motions of a rolling disk).
"""

from __future__ import annotations

import math
from typing import ClassVar

import jax
import jax.numpy as jnp

from lagjax.mechanics.constraints import Constraints
from lagjax.mechanics.lagrangian import Lagrangian
from lagjax.scenes.base import (
    BELOW_THE_TOP,
    AbstractScene,
    Diagnostic,
    Interval,
    StateKind,
    parameter,
)
from lagjax.scenes.rotating import BeadOnRotatingWire


def _multipliers_along(trajectory, scene) -> jax.Array:
    """λ at every saved state of a (q, q̇) trajectory of `scene`."""
    system = scene.system()
    return jax.vmap(system.multipliers, in_axes=(0, 0, 0, None))(
        trajectory.q, trajectory.qdot, trajectory.ts, scene
    )


# --- Pendulum in Cartesian coordinates ---------------------------------------------


def _free_mass_in_gravity(q, qdot, t, scene):
    return 0.5 * scene.mass * jnp.sum(qdot**2) - scene.mass * scene.gravity * q[1]


def _rod(q, t, scene):
    return jnp.sqrt(q[0] ** 2 + q[1] ** 2) - scene.length


class CartesianPendulum(AbstractScene):
    r"""A simple pendulum in Cartesian coordinates, its rod a constraint.

    $L = \tfrac12 m(\dot x^2 + \dot y^2) - mgy$ with $g(x, y) = \sqrt{x^2 + y^2} - l
    = 0$. The constraint force $G^T\lambda = \lambda\hat r$ is the rod's pull, so the
    tension is $-\lambda$; from rest at $\theta_0$, energy conservation gives
    $l\dot\theta^2 = 2g(\cos\theta - \cos\theta_0)$ and
    $T = mg(3\cos\theta - 2\cos\theta_0)$ (negative near the top of a wide swing:
    the rod pushes).

    **Parameters** (SI): `mass` (1 kg), `length` l (1 m), `gravity` g (9.81 m/s²),
    `amplitude` θ₀ (2 rad).
    """

    mass: jax.Array = parameter(1.0, positive=True)
    length: jax.Array = parameter(1.0, positive=True)
    gravity: jax.Array = parameter(9.81, positive=True)
    amplitude: jax.Array = parameter(2.0, within=BELOW_THE_TOP, angle=True)

    default_t1: ClassVar[float] = 5.0
    default_dt: ClassVar[float] = 0.005
    state_kind: ClassVar[StateKind] = "velocity"
    coordinate_names: ClassVar[tuple[str, ...]] = ("x", "y")
    coordinate_units: ClassVar[tuple[str, ...]] = ("m", "m")

    def system(self) -> Lagrangian:
        return Lagrangian(_free_mass_in_gravity, constraints=_rod)

    def initial_state(self) -> tuple[jax.Array, jax.Array]:
        """At rest at θ₀ from the downward vertical."""
        angle = self.amplitude
        q = self.length * jnp.stack([jnp.sin(angle), -jnp.cos(angle)])
        return q, jnp.zeros_like(q)

    def tension(self, q: jax.Array) -> jax.Array:
        """T = mg(3 cos θ − 2 cos θ₀) at position(s) q (..., 2)."""
        cos_theta = -q[..., 1] / self.length
        return self.mass * self.gravity * (3 * cos_theta - 2 * jnp.cos(self.amplitude))

    def checks(self, trajectory) -> dict[str, tuple[jax.Array, jax.Array]]:
        """The multiplier against the closed-form tension; the rod's length."""
        tension = -_multipliers_along(trajectory, self)[..., 0]
        length = jnp.sqrt(jnp.sum(trajectory.q**2, axis=-1))
        return {
            "tension": (tension, self.tension(trajectory.q)),
            "rod length": (length, self.length * jnp.ones_like(length)),
        }

    def diagnostic(self, trajectory) -> Diagnostic:
        """The rod's tension, −λ, against mg(3 cos θ − 2 cos θ₀)."""
        return Diagnostic(
            "rod tension T = −λ [N]",
            trajectory.ts,
            -_multipliers_along(trajectory, self)[..., 0],
            self.tension(trajectory.q),
            "mg(3 cos θ − 2 cos θ₀)",
        )


# --- Atwood's machine with both heights ----------------------------------------------


def _two_hanging_masses(q, qdot, t, scene):
    kinetic = 0.5 * (scene.mass_1 * qdot[0] ** 2 + scene.mass_2 * qdot[1] ** 2)
    return kinetic + scene.gravity * (scene.mass_1 * q[0] + scene.mass_2 * q[1])


def _rope(q, t, scene):
    return q[0] + q[1] - scene.rope_length


class CartesianAtwoodMachine(AbstractScene):
    r"""Atwood's machine with both depths as coordinates and the rope as a constraint.

    $L = \tfrac12(M_1\dot y_1^2 + M_2\dot y_2^2) + g(M_1y_1 + M_2y_2)$, depths below
    the pulley, $y_1 + y_2 = l$. The multiplier is the rope's pull on each mass,
    $\lambda = -T$ with $T = 2M_1M_2g/(M_1 + M_2)$, and
    $\ddot y_1 = (M_1 - M_2)g/(M_1 + M_2)$ (the course text §3.4, eq. 3.77–3.82,
    which cannot give T).

    **Parameters** (SI): `mass_1` (3 kg), `mass_2` (1 kg), `rope_length` (2 m),
    `gravity` (9.81 m/s²), `initial_depth` y₁(0) (1 m), `initial_velocity` (0 m/s).
    """

    mass_1: jax.Array = parameter(3.0, positive=True)
    mass_2: jax.Array = parameter(1.0, nonnegative=True)  # 0: free fall
    rope_length: jax.Array = parameter(2.0, positive=True)
    gravity: jax.Array = parameter(9.81)
    initial_depth: jax.Array = parameter(1.0)
    initial_velocity: jax.Array = parameter(0.0)

    default_t1: ClassVar[float] = 0.5
    default_dt: ClassVar[float] = 0.5 / 400
    state_kind: ClassVar[StateKind] = "velocity"
    coordinate_names: ClassVar[tuple[str, ...]] = ("y₁", "y₂")
    coordinate_units: ClassVar[tuple[str, ...]] = ("m", "m")

    def system(self) -> Lagrangian:
        return Lagrangian(_two_hanging_masses, constraints=_rope)

    def initial_state(self) -> tuple[jax.Array, jax.Array]:
        depth, speed = self.initial_depth, self.initial_velocity
        q = jnp.stack([depth, self.rope_length - depth])
        return q, jnp.stack([speed, -speed])

    def acceleration(self) -> jax.Array:
        """ÿ₁ = (M₁ − M₂)g/(M₁ + M₂)."""
        total = self.mass_1 + self.mass_2
        return (self.mass_1 - self.mass_2) * self.gravity / total

    def tension(self) -> jax.Array:
        """T = 2M₁M₂g/(M₁ + M₂)."""
        return (
            2 * self.mass_1 * self.mass_2 * self.gravity / (self.mass_1 + self.mass_2)
        )

    def checks(self, trajectory) -> dict[str, tuple[jax.Array, jax.Array]]:
        """Depth y₁(t) against the parabola; the multiplier against −T."""
        t = trajectory.ts
        depth = (
            self.initial_depth
            + (self.initial_velocity + 0.5 * self.acceleration() * t) * t
        )
        pull = _multipliers_along(trajectory, self)[..., 0]
        return {
            "depth": (trajectory.q[..., 0], depth),
            "tension": (-pull, self.tension() * jnp.ones_like(t)),
        }


# --- Bead on a rotating wire, in Cartesian coordinates --------------------------------


def _free_mass(q, qdot, t, scene):
    return 0.5 * scene.mass * jnp.sum(qdot**2)


def _turning_wire(q, t, scene):
    angle = scene.angular_velocity * t
    return q[0] * jnp.sin(angle) - q[1] * jnp.cos(angle)


class CartesianRotatingWireBead(AbstractScene):
    r"""The bead on a rotating wire in Cartesian coordinates: a rheonomic constraint.

    $L = \tfrac12 m(\dot x^2 + \dot y^2)$ with $g(x, y, t) = x\sin\omega t -
    y\cos\omega t = 0$ (the bead stays on the line at angle ωt). The radius
    $r = x\cos\omega t + y\sin\omega t$ follows $r = Ae^{\omega t} + Be^{-\omega t}$
    (the course text §3.4, eq. 3.83–3.87), and the wire pushes the bead sideways
    with the Coriolis force $2m\omega\dot r$ along $\hat e_\theta$: since
    $G = -\hat e_\theta$, $\lambda = -2m\omega\dot r$. The energy grows (the wire
    does work) — the run's `energy()` is not conserved.

    **Parameters** (SI): `angular_velocity` ω (2 rad/s), `mass` (1 kg).
    """

    angular_velocity: jax.Array = parameter(2.0)
    mass: jax.Array = parameter(1.0, positive=True)

    default_t1: ClassVar[float] = 2.0
    default_dt: ClassVar[float] = 1e-3
    state_kind: ClassVar[StateKind] = "velocity"
    coordinate_names: ClassVar[tuple[str, ...]] = ("x", "y")
    coordinate_units: ClassVar[tuple[str, ...]] = ("m", "m")

    def generalized(self) -> BeadOnRotatingWire:
        """The same bead in the generalized coordinate r (closed forms)."""
        return BeadOnRotatingWire(
            angular_velocity=self.angular_velocity, mass=self.mass
        )

    def system(self) -> Lagrangian:
        return Lagrangian(_free_mass, constraints=_turning_wire)

    def initial_state(self) -> tuple[jax.Array, jax.Array]:
        """On the wire along x at t = 0, with the r₀, ṙ₀ of `BeadOnRotatingWire`."""
        r0, v0 = self.generalized().initial_state()
        return jnp.stack([r0, 0.0]), jnp.stack([v0, self.angular_velocity * r0])

    def checks(self, trajectory) -> dict[str, tuple[jax.Array, jax.Array]]:
        """Radius and the wire's sideways force against the closed forms."""
        t, q = trajectory.ts, trajectory.q
        angle = self.angular_velocity * t
        radius = q[..., 0] * jnp.cos(angle) + q[..., 1] * jnp.sin(angle)
        radial_speed = jax.vmap(jax.grad(self.generalized().radius))(t)
        push = -_multipliers_along(trajectory, self)[..., 0]
        return {
            "radius": (radius, self.generalized().radius(t)),
            "wire force": (push, 2 * self.mass * self.angular_velocity * radial_speed),
        }


# --- A disk rolling without slipping ---------------------------------------------------


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


SCENES = (
    CartesianPendulum,
    CartesianAtwoodMachine,
    CartesianRotatingWireBead,
    RollingDisk,
)
