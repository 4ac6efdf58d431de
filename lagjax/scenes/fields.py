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

import lagjax as lj
from lagjax.scenes.base import AbstractScene

# --- Uniform gravity ------------------------------------------------------------------


class AbstractUniformAcceleration(AbstractScene):
    r"""One coordinate $y$ (measured downwards) with a constant acceleration $a$.

    The closed form $y(t) = y_0 + v_0 t + \tfrac12 a t^2$ and its checks; subclasses
    give the system and $a$. Runs are assumed to start from `initial_state()` at
    $t = 0$.
    """

    initial_position: eqx.AbstractVar[jax.Array]
    initial_velocity: eqx.AbstractVar[jax.Array]

    state_kind: ClassVar[str] = "momentum"

    @abc.abstractmethod
    def acceleration(self) -> jax.Array:
        """The constant ÿ."""

    def position(self, t) -> jax.Array:
        """y(t) = y₀ + v₀t + ½at²."""
        t = jnp.asarray(t)
        return (
            self.initial_position
            + self.initial_velocity * t
            + 0.5 * self.acceleration() * t**2
        )

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
    r"""A body falling in uniform gravity; $y$ is the distance fallen (downwards).

    $$ L = \tfrac12 m\dot y^2 + m g y, \qquad H = \frac{p^2}{2m} - m g y, $$

    so $\ddot y = g$ and $y(t) = y_0 + v_0 t + \tfrac12 g t^2$. It is Atwood's machine
    with $M_2 = 0$.

    **Parameters** (SI): `mass` m (1 kg), `gravity` g (9.81 m/s²),
    `initial_position` y₀ (0 m), `initial_velocity` v₀ (−5 m/s: thrown upwards).
    """

    mass: jax.Array
    gravity: jax.Array
    initial_position: jax.Array
    initial_velocity: jax.Array

    default_t1: ClassVar[float] = 1.0
    default_dt: ClassVar[float] = 0.01

    def __init__(
        self, mass=1.0, gravity=9.81, initial_position=0.0, initial_velocity=-5.0
    ):
        self.mass = jnp.asarray(mass, dtype=float)
        self.gravity = jnp.asarray(gravity, dtype=float)
        self.initial_position = jnp.asarray(initial_position, dtype=float)
        self.initial_velocity = jnp.asarray(initial_velocity, dtype=float)

    def system(self) -> lj.SeparableHamiltonian:
        return lj.SeparableHamiltonian(_free_fall_kinetic, _free_fall_potential)

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
    r"""Two masses on a rope over a massless, frictionless pulley (the course text §3.4).

    $y$ is the depth of $M_1$ below the pulley, $l - y$ that of $M_2$ (eq. 3.78–3.80):

    $$ L = \tfrac12(M_1 + M_2)\dot y^2 + M_1 g y + M_2 g(l - y), \qquad
       H = \frac{p^2}{2(M_1 + M_2)} - M_1 g y - M_2 g (l - y), $$

    so $\ddot y = (M_1 - M_2)g/(M_1 + M_2)$; the rope's tension never appears.

    **Parameters** (SI): `mass_1` M₁ (3 kg), `mass_2` M₂ (1 kg), `rope_length` l
    (2 m), `gravity` g (9.81 m/s²), `initial_position` y₀ (1 m), `initial_velocity`
    v₀ (0 m/s). The closed form holds while both masses hang, 0 < y < l.
    """

    mass_1: jax.Array
    mass_2: jax.Array
    rope_length: jax.Array
    gravity: jax.Array
    initial_position: jax.Array
    initial_velocity: jax.Array

    default_t1: ClassVar[float] = 0.5
    default_dt: ClassVar[float] = 0.01

    def __init__(
        self,
        mass_1=3.0,
        mass_2=1.0,
        rope_length=2.0,
        gravity=9.81,
        initial_position=1.0,
        initial_velocity=0.0,
    ):
        self.mass_1 = jnp.asarray(mass_1, dtype=float)
        self.mass_2 = jnp.asarray(mass_2, dtype=float)
        self.rope_length = jnp.asarray(rope_length, dtype=float)
        self.gravity = jnp.asarray(gravity, dtype=float)
        self.initial_position = jnp.asarray(initial_position, dtype=float)
        self.initial_velocity = jnp.asarray(initial_velocity, dtype=float)

    def system(self) -> lj.SeparableHamiltonian:
        return lj.SeparableHamiltonian(_atwood_kinetic, _atwood_potential)

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


def _rotation_angle_about(direction, before, after):
    """Signed angle (right-handed about `direction`) from `before` to `after`."""
    sine = jnp.sum(jnp.cross(before, after) * direction, axis=-1)
    return jnp.arctan2(sine, jnp.sum(before * after, axis=-1))


class ChargeInUniformFields(AbstractScene):
    r"""A point charge in uniform static fields $\mathbf E$ and $\mathbf B$, $q = \mathbf r \in \mathbb R^3$.

    The Lagrangian of the course text §3.5 (eq. 3.99), in the gauge
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

    mass: jax.Array
    charge: jax.Array
    magnetic_field: jax.Array
    electric_field: jax.Array
    initial_velocity: jax.Array

    default_t1: ClassVar[float] = 3 * 2 * jnp.pi
    default_dt: ClassVar[float] = 2 * jnp.pi / 64
    state_kind: ClassVar[str] = "velocity"

    def __init__(
        self,
        mass=1.0,
        charge=1.0,
        magnetic_field=(0.0, 0.0, 1.0),
        electric_field=(0.2, 0.0, 0.0),
        initial_velocity=(1.0, 0.0, 0.1),
    ):
        self.mass = jnp.asarray(mass, dtype=float)
        self.charge = jnp.asarray(charge, dtype=float)
        self.magnetic_field = jnp.asarray(magnetic_field, dtype=float)
        self.electric_field = jnp.asarray(electric_field, dtype=float)
        self.initial_velocity = jnp.asarray(initial_velocity, dtype=float)

    def system(self) -> lj.Lagrangian:
        return lj.Lagrangian(_charge_lagrangian, quadratic_in_velocity=True)

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
        return (
            self.charge
            * jnp.dot(self.electric_field, self.field_direction())
            / self.mass
        )

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

    def sample_times(self, periods: int, samples_per_period: int = 16) -> jax.Array:
        """Uniform times over whole cyclotron periods, 0 to `periods`·T_c: save at these
        for `checks` (at least 3 samples per period)."""
        steps = jnp.arange(periods * samples_per_period + 1)
        return steps * (self.cyclotron_period() / samples_per_period)

    def checks(self, trajectory) -> dict[str, tuple[jax.Array, jax.Array]]:
        """The exact position and energy, and ω_c, ρ and v_E measured from the samples.

        Needs a run from `initial_state()` saved at `sample_times(periods, n)`. The
        drift is the guiding centre's displacement over those whole periods (the
        displacement of the particle, ⊥ B, since its gyration phase is back where it
        started) over the time; the signed gyrofrequency is minus the accumulated turn
        of the velocity about b̂ in the drift frame, over the time; the Larmor radius
        is the distance of each sample, in the drift frame, from the samples' mean
        (the guiding centre, because they cover whole periods uniformly).
        """
        ts = self._require_whole_periods(trajectory.ts)
        positions, velocities = trajectory.q, trajectory.qdot
        direction = self.field_direction()
        elapsed = ts[-1] - ts[0]
        drift = _perpendicular(positions[-1] - positions[0], direction) / elapsed
        gyration = _perpendicular(velocities, direction) - drift
        turn = jnp.sum(_rotation_angle_about(direction, gyration[:-1], gyration[1:]))
        # The last sample repeats the first one's phase; leave it out of the mean.
        in_drift_frame = (
            _perpendicular(positions[:-1], direction) - ts[:-1, None] * drift
        )
        radii = jnp.linalg.norm(
            in_drift_frame - jnp.mean(in_drift_frame, axis=0), axis=-1
        )
        ones = jnp.ones_like(ts)
        initial_energy = 0.5 * self.mass * jnp.sum(self.initial_velocity**2)
        return {
            "position": (positions, self.orbit_state(ts)[0]),
            "drift velocity": (drift, self.drift_velocity()),
            "signed gyrofrequency": (-turn / elapsed, self.signed_gyrofrequency()),
            "Larmor radius": (radii, self.larmor_radius() * ones[:-1]),
            "energy": (trajectory.energy(), initial_energy * ones),
        }

    def _require_whole_periods(self, ts: jax.Array) -> jax.Array:
        """`ts`, with a run-time error unless it is uniform over whole periods."""
        if ts.shape[-1] < 4:
            raise ValueError(
                "ChargeInUniformFields.checks needs the trajectory saved at "
                f"sample_times(periods, n); got {ts.shape[-1]} saved times"
            )
        spacing = jnp.diff(ts)
        periods = (ts[-1] - ts[0]) / self.cyclotron_period()
        uneven = jnp.ptp(spacing) > 1e-9 * spacing[0]
        too_sparse = spacing[0] > self.cyclotron_period() / 3
        not_whole = (periods < 0.5) | (jnp.abs(periods - jnp.round(periods)) > 1e-6)
        return eqx.error_if(
            ts,
            uneven | too_sparse | not_whole,
            "ChargeInUniformFields.checks needs samples uniform over whole cyclotron "
            "periods, at least 3 per period: save at sample_times(periods, n)",
        )


SCENES = (ChargeInUniformFields, AtwoodMachine, FreeFall)
