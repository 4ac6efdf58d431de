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
  (the course text §3.1.3, eq. 3.12–3.13) in the standard coordinates; its own
  module, `lagjax.scenes.rolling_disk`.

Every `checks(trajectory)` assumes a run from `initial_state()` at $t = 0$.

References: the course text §3.1 and §3.4; Goldstein, Poole & Safko, *Classical
Mechanics*, 3rd ed., §2.4 (Lagrange multipliers: hoop rolling on an incline);
Bloch, *Nonholonomic Mechanics and Control* (2003), §1.4 (the rolling disk);
O'Reilly, Nonlinear Dynamics 10, 287 (1996) (steady motions of a rolling disk).
"""

from __future__ import annotations

from typing import ClassVar

import jax
import jax.numpy as jnp

from lagjax.mechanics.lagrangian import Lagrangian
from lagjax.scenes.base import (
    BELOW_THE_TOP,
    AbstractScene,
    Diagnostic,
    StateKind,
    parameter,
)
from lagjax.scenes.rolling_disk import RollingDisk as RollingDisk
from lagjax.scenes.rolling_disk import (
    _contact_point_velocity as _contact_point_velocity,  # tests import it from here
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


SCENES = (
    CartesianPendulum,
    CartesianAtwoodMachine,
    CartesianRotatingWireBead,
    RollingDisk,
)
