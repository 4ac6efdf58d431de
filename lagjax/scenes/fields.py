r"""Motion in uniform fields: gravity, and a charge in uniform electric and magnetic fields.

A uniform field exerts a force that does not depend on where the particle is, so the
motion has a closed form. In uniform gravity the acceleration is constant and
$y(t) = y_0 + v_0 t + \tfrac12 a t^2$ — for a falling body $a = g$, for Atwood's
machine $a = (M_1 - M_2)g/(M_1 + M_2)$ (the course text §3.4, eq. 3.77–3.82). A
charge $e$ of mass $m$ in a uniform magnetic field $\mathbf B$ gyrates about the field
at the cyclotron frequency $\omega_c = |e|B/m$ on a circle of Larmor radius
$m v_\perp/|e|B$, while a uniform electric field $\mathbf E$ moves the centre of that
circle (the guiding centre) at the drift velocity $\mathbf E\times\mathbf B/B^2$ and
accelerates it along $\mathbf B$ at $e E_\parallel/m$. The charge enters through the
velocity-dependent potential $U = e(\phi - \mathbf A\cdot\mathbf v)$ of the course
text §3.5 (eq. 3.88–3.99).

References: the course text §3.4–3.5; Goldstein, Poole & Safko, *Classical
Mechanics*, 3rd ed., §1.5 (velocity-dependent potentials) and §1.6 (Atwood's
machine); Jackson, *Classical Electrodynamics*, 3rd ed., §12.2–12.3 (motion in
uniform static fields, E×B drift).
"""

from __future__ import annotations

import abc
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from lagjax.mechanics.hamiltonian import SeparableHamiltonian
from lagjax.mechanics.lagrangian import Lagrangian
from lagjax.scenes.base import AbstractScene, StateKind, concrete, parameter

# --- Uniform gravity ------------------------------------------------------------------


class AbstractUniformAcceleration(AbstractScene):
    r"""One coordinate $y$ (measured downwards) with a constant acceleration $a$.

    The closed form $y(t) = y_0 + v_0 t + \tfrac12 a t^2$ and its checks; subclasses
    give the system and $a$. Runs are assumed to start from `initial_state()` at
    $t = 0$.
    """

    initial_position: eqx.AbstractVar[jax.Array]
    initial_velocity: eqx.AbstractVar[jax.Array]

    state_kind: ClassVar[StateKind] = "momentum"
    coordinate_names: ClassVar[tuple[str, ...]] = ("y",)
    coordinate_units: ClassVar[tuple[str, ...]] = ("m",)

    @abc.abstractmethod
    def acceleration(self) -> jax.Array:
        """The constant ÿ."""

    def position(self, t) -> jax.Array:
        """y(t) = y₀ + v₀t + ½at²: y₀ plus the mean velocity over [0, t] times t."""
        t = jnp.asarray(t)
        mean_velocity = self.initial_velocity + 0.5 * self.acceleration() * t
        return self.initial_position + mean_velocity * t

    def velocity(self, t) -> jax.Array:
        """ẏ(t) = v₀ + at."""
        return self.initial_velocity + self.acceleration() * jnp.asarray(t)

    def checks(self, trajectory) -> dict[str, tuple[jax.Array, jax.Array]]:
        """y and ẏ at every saved time; the acceleration measured as Δẏ/t at the end."""
        ts, velocity = trajectory.ts, trajectory.qdot
        measured_acceleration = (velocity[-1] - self.initial_velocity) / ts[-1]
        return {
            "y(t)": (trajectory.q, self.position(ts)),
            "velocity": (velocity, self.velocity(ts)),
            "acceleration": (measured_acceleration, self.acceleration()),
        }


def _free_fall_kinetic(p, t, scene):
    return 0.5 * p**2 / scene.mass


def _free_fall_potential(y, t, scene):
    return -scene.mass * scene.gravity * y


class FreeFall(AbstractUniformAcceleration):
    r"""A body falling in uniform gravity; y is the distance fallen (downwards).

    $$ L = \tfrac12 m\dot y^2 + m g y, \qquad H = \frac{p^2}{2m} - m g y, $$

    so $\ddot y = g$ and $y(t) = y_0 + v_0 t + \tfrac12 g t^2$. It is Atwood's machine
    with $M_2 = 0$.

    **Parameters** (SI): `mass` m (1 kg), `gravity` g (9.81 m/s²),
    `initial_position` y₀ (0 m), `initial_velocity` v₀ (−5 m/s: thrown upwards).
    """

    mass: jax.Array = parameter(1.0, positive=True)
    gravity: jax.Array = parameter(9.81)
    initial_position: jax.Array = parameter(0.0)
    initial_velocity: jax.Array = parameter(-5.0)

    default_t1: ClassVar[float] = 1.0
    default_dt: ClassVar[float] = 1.0 / 400  # saving at 401 points falls on steps

    def system(self) -> SeparableHamiltonian:
        return SeparableHamiltonian(_free_fall_kinetic, _free_fall_potential)

    def initial_state(self) -> tuple[jax.Array, jax.Array]:
        return self.initial_position, self.mass * self.initial_velocity

    def acceleration(self) -> jax.Array:
        """ÿ = g, whatever the mass."""
        return self.gravity


def _atwood_kinetic(p, t, scene):
    return 0.5 * p**2 / (scene.mass_1 + scene.mass_2)


def _atwood_potential(y, t, scene):
    # Eq. 3.78: M₁ hangs y below the pulley, M₂ the rest of the rope, l − y.
    return -scene.gravity * (scene.mass_1 * y + scene.mass_2 * (scene.rope_length - y))


class AtwoodMachine(AbstractUniformAcceleration):
    r"""Atwood's machine: two masses on a rope over a massless, frictionless pulley.

    The course text §3.4, example 2: $y$ is the depth of $M_1$ below the pulley,
    $l - y$ that of $M_2$ (eq. 3.78–3.80),

    $$ L = \tfrac12(M_1 + M_2)\dot y^2 + M_1 g y + M_2 g(l - y), \qquad
       H = \frac{p^2}{2(M_1 + M_2)} - M_1 g y - M_2 g (l - y), $$

    so $\ddot y = (M_1 - M_2)g/(M_1 + M_2)$; the rope's tension never appears.

    **Parameters** (SI): `mass_1` M₁ (3 kg), `mass_2` M₂ (1 kg), `rope_length` l
    (2 m), `gravity` g (9.81 m/s²), `initial_position` y₀ (1 m), `initial_velocity`
    v₀ (0 m/s). The closed form holds while both masses hang, 0 < y < l.
    """

    mass_1: jax.Array = parameter(3.0, positive=True)
    mass_2: jax.Array = parameter(1.0, nonnegative=True)  # 0: free fall
    rope_length: jax.Array = parameter(2.0, positive=True)
    gravity: jax.Array = parameter(9.81)
    initial_position: jax.Array = parameter(1.0)
    initial_velocity: jax.Array = parameter(0.0)

    default_t1: ClassVar[float] = 0.5
    default_dt: ClassVar[float] = 0.5 / 400  # saving at 401 points falls on steps

    def system(self) -> SeparableHamiltonian:
        return SeparableHamiltonian(_atwood_kinetic, _atwood_potential)

    def initial_state(self) -> tuple[jax.Array, jax.Array]:
        total_mass = self.mass_1 + self.mass_2
        return self.initial_position, total_mass * self.initial_velocity

    def acceleration(self) -> jax.Array:
        """ÿ = (M₁ − M₂) g / (M₁ + M₂)."""
        return (self.mass_1 - self.mass_2) * self.gravity / (self.mass_1 + self.mass_2)


# --- A charge in uniform electric and magnetic fields ---------------------------------


def _charge_lagrangian(r, v, t, scene):
    # Gauge: φ = −E·r and the symmetric A = ½ B × r (∇×A = B, ∂A/∂t = 0).
    vector_potential = 0.5 * jnp.cross(scene.magnetic_field, r)
    scalar_potential = -jnp.dot(scene.electric_field, r)
    kinetic = 0.5 * scene.mass * jnp.dot(v, v)
    return kinetic - scene.charge * (scalar_potential - jnp.dot(vector_potential, v))


def _perpendicular(vectors, direction):
    """The components of `vectors` (..., 3) perpendicular to the unit `direction`."""
    along = jnp.sum(vectors * direction, axis=-1, keepdims=True)
    return vectors - along * direction


def _plane_basis(direction):
    """Rows e₁, e₂: orthonormal, ⊥ the unit `direction`, with e₁ × e₂ = direction."""
    # Any axis not nearly parallel to the direction gives a well-conditioned e₁.
    axis = jnp.where(jnp.abs(direction[0]) < 0.9, jnp.eye(3)[0], jnp.eye(3)[1])
    first = jnp.cross(direction, axis)
    first = first / jnp.linalg.norm(first)
    return jnp.stack([first, jnp.cross(direction, first)])


def _fit_circle(points):
    """(centre, radius) of the circle through 2-D `points` (N, 2), least squares.

    |p|² = 2 c·p + k is linear in (c, k) (Kåsa's fit), exact for points on a circle;
    then ρ² = k + |c|².
    """
    design = jnp.concatenate([2 * points, jnp.ones_like(points[:, :1])], axis=1)
    solution = jnp.linalg.lstsq(design, jnp.sum(points**2, axis=1))[0]
    centre = solution[:2]
    return centre, jnp.sqrt(solution[2] + jnp.sum(centre**2))


def _accumulated_turn(vectors):
    """Total signed angle swept by the 2-D `vectors` (N, 2), counter-clockwise positive.

    Each step must turn by less than π for its angle to be unambiguous.
    """
    before, after = vectors[:-1], vectors[1:]
    cross = before[:, 0] * after[:, 1] - before[:, 1] * after[:, 0]
    return jnp.sum(jnp.arctan2(cross, jnp.sum(before * after, axis=1)))


class ChargeInUniformFields(AbstractScene):
    r"""A point charge in uniform static electric and magnetic fields, in 3-D.

    $q = \mathbf r$. The Lagrangian of the course text §3.5 (eq. 3.99), in the gauge
    $\phi = -\mathbf E\cdot\mathbf r$, $\mathbf A = \tfrac12\mathbf B\times\mathbf r$:

    $$ L = \tfrac12 m\dot{\mathbf r}^2 - e(\phi - \mathbf A\cdot\dot{\mathbf r})
         = \tfrac12 m\dot{\mathbf r}^2 + e\,\mathbf E\cdot\mathbf r
           + \tfrac e2 (\mathbf B\times\mathbf r)\cdot\dot{\mathbf r}. $$

    Another gauge (e.g. Landau's $\mathbf A = B x\,\hat{\mathbf y}$) changes $L$ by a
    total time derivative and the canonical momentum, not the motion.

    The exact motion (Jackson §12.2–12.3): with $\Omega = eB/m$ (signed by the
    charge), $\hat{\mathbf b} = \mathbf B/B$, drift $\mathbf v_E = \mathbf E\times
    \mathbf B/B^2$ and gyration velocity $\mathbf u_0 = \mathbf v_{0\perp} -
    \mathbf v_E$,

    $$ \mathbf r(t) = \mathbf v_E t + (v_{0\parallel}t + \tfrac12 a_\parallel t^2)
       \hat{\mathbf b} + \frac{\mathbf u_0\sin\Omega t + (\mathbf u_0\times\hat{\mathbf b})
       (1 - \cos\Omega t)}{\Omega}, \qquad a_\parallel = eE_\parallel/m. $$

    A positive charge turns clockwise seen looking along $\mathbf B$.

    **Parameters** (natural units, $m = e = B = 1$ by default, so $T_c = 2\pi$):
    `mass`, `charge` (signed), `magnetic_field` (3-vector, non-zero; (0, 0, 1)),
    `electric_field` (3-vector; (0.2, 0, 0): crossed fields, drift along −y),
    `initial_velocity` ((1, 0, 0.1)). Starts at the origin at t = 0.
    """

    mass: jax.Array = parameter(1.0, positive=True)
    charge: jax.Array = parameter(1.0)
    magnetic_field: jax.Array = parameter((0.0, 0.0, 1.0))
    electric_field: jax.Array = parameter((0.2, 0.0, 0.0))
    initial_velocity: jax.Array = parameter((1.0, 0.0, 0.1))

    default_t1: ClassVar[float] = 3 * 2 * jnp.pi
    default_dt: ClassVar[float] = 3 * 2 * jnp.pi / 400  # 401 saved points on steps
    state_kind: ClassVar[StateKind] = "velocity"
    coordinate_names: ClassVar[tuple[str, ...]] = ("x", "y", "z")
    coordinate_units: ClassVar[tuple[str, ...]] = ("m", "m", "m")

    def __check_init__(self):
        values = concrete(self.charge, self.magnetic_field)
        if values is None:
            return  # traced (vmap, jit): not checked, see lagjax.scenes.base
        charge, field = values
        if np.any(charge == 0) or np.any(np.linalg.norm(field, axis=-1) == 0):
            raise ValueError(
                "ChargeInUniformFields needs a non-zero charge and magnetic_field: "
                "its closed forms turn on the cyclotron frequency eB/m"
            )

    def system(self) -> Lagrangian:
        return Lagrangian(_charge_lagrangian, quadratic_in_velocity=True)

    def initial_state(self) -> tuple[jax.Array, jax.Array]:
        return jnp.zeros_like(self.initial_velocity), self.initial_velocity

    def field_direction(self) -> jax.Array:
        """b̂ = B/|B|."""
        return self.magnetic_field / jnp.linalg.norm(self.magnetic_field)

    def signed_gyrofrequency(self) -> jax.Array:
        """Ω = eB/m: the velocity turns by −Ωt about b̂ (clockwise for e > 0)."""
        return self.charge * jnp.linalg.norm(self.magnetic_field) / self.mass

    def cyclotron_frequency(self) -> jax.Array:
        """ω_c = |e|B/m."""
        return jnp.abs(self.signed_gyrofrequency())

    def cyclotron_period(self) -> jax.Array:
        """T_c = 2π/ω_c."""
        return 2 * jnp.pi / self.cyclotron_frequency()

    def drift_velocity(self) -> jax.Array:
        """v_E = E × B / B², the same for every charge and mass."""
        field = self.magnetic_field
        return jnp.cross(self.electric_field, field) / jnp.dot(field, field)

    def parallel_acceleration(self) -> jax.Array:
        """a_∥ = e (E·b̂)/m along b̂."""
        electric_along_field = jnp.dot(self.electric_field, self.field_direction())
        return self.charge * electric_along_field / self.mass

    def gyration_velocity(self) -> jax.Array:
        """u₀ = v₀⊥ − v_E: the initial velocity in the frame of the guiding centre."""
        return (
            _perpendicular(self.initial_velocity, self.field_direction())
            - self.drift_velocity()
        )

    def larmor_radius(self) -> jax.Array:
        """ρ = m|u₀|/(|e|B), with u₀ the velocity ⊥ B relative to the drift."""
        return jnp.linalg.norm(self.gyration_velocity()) / self.cyclotron_frequency()

    def orbit_state(self, t) -> tuple[jax.Array, jax.Array]:
        """Exact (position, velocity) at times `t`, each of shape t.shape + (3,)."""
        t = jnp.asarray(t)[..., None]
        direction, gyration = self.field_direction(), self.gyration_velocity()
        turned = jnp.cross(gyration, direction)
        omega = self.signed_gyrofrequency()
        cos, sin = jnp.cos(omega * t), jnp.sin(omega * t)
        initial_parallel = jnp.dot(self.initial_velocity, direction)
        accel = self.parallel_acceleration()
        along_field = (initial_parallel * t + 0.5 * accel * t**2) * direction
        position = (
            self.drift_velocity() * t
            + along_field
            + (gyration * sin + turned * (1 - cos)) / omega
        )
        velocity = (
            self.drift_velocity()
            + (initial_parallel + accel * t) * direction
            + gyration * cos
            + turned * sin
        )
        return position, velocity

    def checks(self, trajectory) -> dict[str, tuple[jax.Array, jax.Array]]:
        """The exact position and energy; v_E, Ω and ρ measured from the samples.

        Needs a run from `initial_state()` saved at three or more times less than
        half a cyclotron period apart (and a non-zero gyration, u₀ ≠ 0). In the plane
        ⊥ B the velocity runs on a circle (the hodograph) about v_E: its fitted
        centre is the measured drift, and its turn about that centre over the elapsed
        time is minus the measured Ω. In the frame moving with the measured drift the
        positions run on a circle, whose fitted radius is the measured Larmor radius.
        """
        ts = self._require_dense_samples(trajectory.ts)
        plane = _plane_basis(self.field_direction())
        velocities = trajectory.qdot @ plane.T
        drift, _ = _fit_circle(velocities)
        turn = _accumulated_turn(velocities - drift)
        elapsed = ts[-1] - ts[0]
        _, radius = _fit_circle(trajectory.q @ plane.T - ts[:, None] * drift)
        initial_energy = 0.5 * self.mass * jnp.sum(self.initial_velocity**2)
        return {
            "position": (trajectory.q, self.orbit_state(ts)[0]),
            "drift velocity": (drift @ plane, self.drift_velocity()),
            "signed gyrofrequency": (-turn / elapsed, self.signed_gyrofrequency()),
            "Larmor radius": (radius, self.larmor_radius()),
            "energy": (trajectory.energy(), initial_energy * jnp.ones_like(ts)),
        }

    def _require_dense_samples(self, ts: jax.Array) -> jax.Array:
        """`ts`, with a run-time error if samples are half a period or more apart."""
        if ts.shape[-1] < 3:
            raise ValueError(
                "ChargeInUniformFields.checks measures circles: save the trajectory "
                f"at three or more times (ts=...), got {ts.shape[-1]}"
            )
        widest = jnp.max(jnp.abs(jnp.diff(ts)))
        return eqx.error_if(
            ts,
            widest >= 0.5 * self.cyclotron_period(),
            "ChargeInUniformFields.checks needs samples less than half a cyclotron "
            "period apart, or the gyration phase is ambiguous",
        )


SCENES = (ChargeInUniformFields, AtwoodMachine, FreeFall)
