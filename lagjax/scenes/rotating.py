r"""Moving frames: fictitious forces derived from the inertial Lagrangian.

In a frame $S'$ whose origin moves on $\mathbf R(t)$ and whose axes turn with angular
velocity $\boldsymbol\omega(t)$, Newton's law acquires fictitious forces (the course
text §1.2, eq. 1.6, and §1.3, eq. 1.27):

$$ m\ddot{\mathbf r}' = \mathbf F - m\ddot{\mathbf R}
   - 2m\,\boldsymbol\omega\times\dot{\mathbf r}'
   - m\,\boldsymbol\omega\times(\boldsymbol\omega\times\mathbf r')
   - m\,\dot{\boldsymbol\omega}\times\mathbf r'. $$

None of these is typed in here. Every scene writes the *inertial* Lagrangian
$L = \tfrac12 m|\dot{\mathbf x}|^2 - V(\mathbf x)$ with the inertial position
$\mathbf x(\mathbf r', t)$ expressed through the frame coordinates — either as
$\dot{\mathbf x} = \dot{\mathbf r}' + \boldsymbol\omega\times\mathbf r'$ for a frame
turning uniformly, or by pushing $(\mathbf r', \dot{\mathbf r}')$ through the frame
map with `jax.jvp` — and lagjax's Euler–Lagrange derivation produces the
Coriolis force (from the term linear in $\dot{\mathbf r}'$), the centrifugal force
(from the term quadratic in $\boldsymbol\omega$), the Euler force (from
$\partial^2 L/\partial\dot q\,\partial t$) and $-m\ddot{\mathbf R}$.

Local Earth frames use the course text's axes (§1.4.3, eq. 1.35): $x$ due south,
$y$ due east, $z$ up, so that $\boldsymbol\omega_E = \omega_E(-\cos\varphi, 0,
\sin\varphi)$ at latitude $\varphi$.

References: the course text §1.2–1.4 (rectilinear and rotating frames, $g_{\rm eff}$,
Foucault pendulum) and §3 (bead on a rotating wire, eq. 3.83–3.87); Landau &
Lifshitz, *Mechanics* §39 (motion in a non-inertial frame); Goldstein, Poole &
Safko, *Classical Mechanics*, 3rd ed., §4.10 (Coriolis effect, eastward deflection,
Foucault pendulum).
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from lagjax.mechanics.lagrangian import Lagrangian
from lagjax.scenes.base import AbstractScene

EARTH_RATE = 7.2921159e-5  # sidereal angular velocity of the Earth, rad/s


def _parameter(default):
    """A physical parameter: an array field (vmappable, differentiable)."""
    return eqx.field(default=default, converter=jnp.asarray)


# ---------------------------------------------------------------------------------
# Kinematics shared by the scenes.


def rotate(axis: jax.Array, angle: ArrayLike, vector: jax.Array) -> jax.Array:
    r"""Rodrigues' formula: `vector` (..., 3) turned by `angle` (...) about unit `axis`.

    $R\mathbf v = \mathbf v\cos\theta + (\hat n\times\mathbf v)\sin\theta
    + \hat n(\hat n\cdot\mathbf v)(1 - \cos\theta)$ — on vectors, not as a matrix
    (`jnp.eye` would stop lagjax from scalarizing the Lagrangian).
    """
    angle = jnp.asarray(angle)[..., None]
    along = jnp.sum(axis * vector, axis=-1, keepdims=True)
    return (
        vector * jnp.cos(angle)
        + jnp.cross(axis, vector) * jnp.sin(angle)
        + axis * along * (1 - jnp.cos(angle))
    )


def inertial_motion(frame_map, position, velocity, t):
    r"""$(\mathbf x, \dot{\mathbf x})$ for the point with frame coordinates
    $(\mathbf r', \dot{\mathbf r}')$: the frame map $\mathbf x(\mathbf r', t)$ and
    its total time derivative, one forward-mode pass."""
    t = jnp.asarray(t, dtype=jnp.result_type(position))
    return jax.jvp(frame_map, (position, t), (velocity, jnp.ones_like(t)))


def rotating_kinetic_energy(position, velocity, omega, mass) -> jax.Array:
    r"""$\tfrac12 m|\dot{\mathbf r}' + \boldsymbol\omega\times\mathbf r'|^2$: the
    inertial kinetic energy in a frame turning at constant $\boldsymbol\omega$."""
    inertial = velocity + jnp.cross(omega, position)
    return 0.5 * mass * jnp.sum(inertial**2)


def earth_rotation(latitude: jax.Array, earth_rate: jax.Array) -> jax.Array:
    """ω_E in the local (south, east, up) axes at `latitude` (eq. 1.35)."""
    return earth_rate * jnp.stack(
        [-jnp.cos(latitude), jnp.zeros_like(latitude), jnp.sin(latitude)]
    )


def bob_offset(q: jax.Array, length: jax.Array) -> jax.Array:
    """Bob below its suspension point, from its horizontal offsets q = (x, y)."""
    height = -jnp.sqrt(length**2 - q[0] ** 2 - q[1] ** 2)
    return jnp.stack([q[0], q[1], height])


def _local_earth_lagrangian(position, velocity, scene) -> jax.Array:
    r"""$\tfrac12 m|\dot{\mathbf r} + \boldsymbol\omega_E\times\mathbf r|^2 - mgz$.

    `gravity` is the effective $g$ along the local plumb line: the centrifugal
    potential of the frame's origin is part of it (eq. 1.30), so `latitude` is the
    astronomical one (the plumb line's angle to the equatorial plane).
    """
    omega = earth_rotation(scene.latitude, scene.earth_rate)
    kinetic = rotating_kinetic_energy(position, velocity, omega, scene.mass)
    return kinetic - scene.mass * scene.gravity * position[2]


# ---------------------------------------------------------------------------------
# Foucault pendulum.


def _foucault_lagrangian(q, qdot, t, scene):
    bob, bob_velocity = jax.jvp(lambda x: bob_offset(x, scene.length), (q,), (qdot,))
    return _local_earth_lagrangian(bob, bob_velocity, scene)


def _weighted_slope(ts: jax.Array, values: jax.Array) -> jax.Array:
    """Least-squares slope of `values` against `ts`, with weights sin²(π s), s∈[0,1].

    The taper suppresses the end effects of the fast residual oscillation, leaving
    the slow trend (a bias ~1/(ΩW)³ instead of ~1/(ΩW) for an oscillation Ω, window W).
    """
    weights = jnp.sin(jnp.pi * (ts - ts[0]) / (ts[-1] - ts[0])) ** 2
    weights = weights / jnp.sum(weights)
    t_centred = ts - jnp.sum(weights * ts)
    v_centred = values - jnp.sum(weights * values)
    return jnp.sum(weights * t_centred * v_centred) / jnp.sum(weights * t_centred**2)


class FoucaultPendulum(AbstractScene):
    r"""A spherical pendulum in the Earth's rotating frame, $q = (x, y)$ (south, east).

    $$ L = \tfrac12 m|\dot{\mathbf r} + \boldsymbol\omega_E\times\mathbf r|^2 - mgz,
       \qquad \mathbf r = (x, y, -\sqrt{l^2 - x^2 - y^2}). $$

    Released at rest a distance $a$ due south, the plane of oscillation turns
    clockwise (seen from above, northern hemisphere) at $-\omega_E\sin\varphi$: a full
    turn takes $24\,\mathrm h/\sin\varphi$ (the course text §1.4.3, eq. 1.57; ≈34 h
    at 45°). A finite amplitude adds Airy's precession, $-\tfrac38(a/l)^2$ of that
    rate (4·10⁻⁵ with the defaults; Goldstein §4.10, Landau & Lifshitz §39 prob. 1).

    **Measuring the plane** (`plane_angle`): for an isotropic oscillator the
    tensor $\dot{\mathbf r}\dot{\mathbf r}^T + (g/l)\,\mathbf r\mathbf r^T$ (Fradkin's
    tensor) is constant and its major axis is the plane of oscillation; in complex
    form $C = \dot w^2 + (g/l)w^2$, $w = x + iy$, the plane's angle is $\tfrac12\arg C$.
    It is defined at every saved state, needs no turning-point search, and has no
    branch cut in time ($|C| \approx (g/l)a^2$); in the Earth's frame it carries a
    residual oscillation of amplitude $\tfrac12\omega_E\sin\varphi/\sqrt{g/l}$ at
    twice the swing frequency, which the tapered fit of `measured_precession_rate`
    averages out. Save ≳ 5 states per swing.

    Parameters (SI): `latitude` (rad, π/4), `length` (9.81 m: $g/l = 1$ s⁻²),
    `gravity` (9.81), `amplitude` (0.1 m), `earth_rate` (7.292·10⁻⁵ rad/s), `mass`.
    """

    latitude: jax.Array = _parameter(jnp.pi / 4)
    length: jax.Array = _parameter(9.81)
    gravity: jax.Array = _parameter(9.81)
    amplitude: jax.Array = _parameter(0.1)
    earth_rate: jax.Array = _parameter(EARTH_RATE)
    mass: jax.Array = _parameter(1.0)

    default_t1: ClassVar[float] = 300.0
    default_dt: ClassVar[float] = 0.05
    state_kind: ClassVar[str] = "velocity"

    def system(self) -> Lagrangian:
        return Lagrangian(_foucault_lagrangian, quadratic_in_velocity=True)

    def initial_state(self) -> tuple[jax.Array, jax.Array]:
        """Drawn a distance `amplitude` due south, released at rest (eq. 1.47)."""
        start = jnp.stack([self.amplitude, jnp.zeros_like(self.amplitude)])
        return start, jnp.zeros_like(start)

    def precession_rate(self) -> jax.Array:
        """dθ/dt = −ω_E sin φ (negative: clockwise seen from above)."""
        return -self.earth_rate * jnp.sin(self.latitude)

    def precession_period(self) -> jax.Array:
        """Time for the plane to turn through 2π: 2π/(ω_E |sin φ|) (eq. 1.57)."""
        return 2 * jnp.pi / jnp.abs(self.precession_rate())

    def airy_correction(self) -> jax.Array:
        """Relative change of the precession rate at amplitude a: −(3/8)(a/l)²."""
        return -0.375 * (self.amplitude / self.length) ** 2

    def plane_angle(self, q: jax.Array, qdot: jax.Array) -> jax.Array:
        """Angle of the plane of oscillation from south towards east, unwrapped in time.

        `q`, `qdot` have a leading time axis; see the class docstring for the method.
        """
        stiffness = self.gravity / self.length
        x, y, vx, vy = q[..., 0], q[..., 1], qdot[..., 0], qdot[..., 1]
        real = vx**2 - vy**2 + stiffness * (x**2 - y**2)
        imaginary = 2 * vx * vy + 2 * stiffness * x * y
        return 0.5 * jnp.unwrap(jnp.arctan2(imaginary, real))

    def measured_precession_rate(self, trajectory) -> jax.Array:
        """Slope of `plane_angle` over the saved times (tapered least squares)."""
        angle = self.plane_angle(trajectory.q, trajectory.qdot)
        return _weighted_slope(trajectory.ts, angle)

    def checks(self, trajectory) -> dict[str, tuple[jax.Array, jax.Array]]:
        """Measured precession rate against −ω_E sin φ (to ~(a/l)², see the docstring)."""
        return {
            "precession rate": (
                self.measured_precession_rate(trajectory),
                self.precession_rate(),
            )
        }


# ---------------------------------------------------------------------------------
# Eastward deflection of a falling body.


def _falling_body_lagrangian(q, qdot, t, scene):
    return _local_earth_lagrangian(q, qdot, scene)


class EastwardDeflection(AbstractScene):
    r"""A body dropped from rest at height $h$, in the local Earth frame (south, east, up).

    $$ L = \tfrac12 m|\dot{\mathbf r} + \boldsymbol\omega_E\times\mathbf r|^2 - mgz. $$

    Expanding in $\omega_E$ about free fall $z = h - \tfrac12 g t^2$ (Goldstein §4.10;
    Landau & Lifshitz §39 prob. 1):

    - east, first order: $y_1 = \tfrac13\omega_E g t^3\cos\varphi$; the next term is
      $y_3 = -y_1\,\omega_E^2(h/g + t^2/10)$, so at the fall time $T = \sqrt{2h/g}$
      the first-order formula is off by $0.6(\omega_E T)^2 \approx 7\cdot10^{-8}$;
    - south, second order (Coriolis on the eastward drift plus the centrifugal force
      about the origin): $x_2 = \omega_E^2\sin\varphi\cos\varphi\,(h t^2/2 + g t^4/8)$.

    `gravity` is the effective $g$ at the ground (the origin); `latitude` (rad, π/4),
    `drop_height` (100 m), `earth_rate`, `mass`.
    """

    latitude: jax.Array = _parameter(jnp.pi / 4)
    drop_height: jax.Array = _parameter(100.0)
    gravity: jax.Array = _parameter(9.81)
    earth_rate: jax.Array = _parameter(EARTH_RATE)
    mass: jax.Array = _parameter(1.0)

    default_t1: ClassVar[float] = 4.5  # ≈ √(2h/g) for h = 100 m
    default_dt: ClassVar[float] = 0.01
    state_kind: ClassVar[str] = "velocity"

    def system(self) -> Lagrangian:
        return Lagrangian(_falling_body_lagrangian, quadratic_in_velocity=True)

    def initial_state(self) -> tuple[jax.Array, jax.Array]:
        zero = jnp.zeros_like(self.drop_height)
        return jnp.stack([zero, zero, self.drop_height]), jnp.zeros(3)

    def fall_time(self) -> jax.Array:
        """T = √(2h/g), the fall time without rotation."""
        return jnp.sqrt(2 * self.drop_height / self.gravity)

    def eastward_deflection(self, t: ArrayLike) -> jax.Array:
        """First order in ω_E: y = (1/3) ω_E g t³ cos φ."""
        return self.earth_rate * self.gravity * t**3 * jnp.cos(self.latitude) / 3

    def eastward_relative_correction(self, t: ArrayLike) -> jax.Array:
        """y₃/y₁ = −ω_E² (h/g + t²/10): the O(ω²) remainder of the first-order formula."""
        return -(self.earth_rate**2) * (self.drop_height / self.gravity + t**2 / 10)

    def southward_deflection(self, t: ArrayLike) -> jax.Array:
        """Second order: x = ω_E² sin φ cos φ (h t²/2 + g t⁴/8)."""
        h, g, phi = self.drop_height, self.gravity, self.latitude
        spread = h * t**2 / 2 + g * t**4 / 8
        return self.earth_rate**2 * jnp.sin(phi) * jnp.cos(phi) * spread

    def checks(self, trajectory) -> dict[str, tuple[jax.Array, jax.Array]]:
        """Eastward drift at the last saved time; agrees to (ω_E t)² ≈ 10⁻⁷."""
        t = trajectory.ts[-1]
        return {
            "eastward deflection": (trajectory.q[-1, 1], self.eastward_deflection(t))
        }


# ---------------------------------------------------------------------------------
# Plumb line on the rotating Earth.


def _plumb_lagrangian(q, qdot, t, scene):
    bob, bob_velocity = jax.jvp(lambda x: bob_offset(x, scene.length), (q,), (qdot,))
    from_centre = scene.site() + bob
    omega = earth_rotation(scene.latitude, scene.earth_rate)
    kinetic = rotating_kinetic_energy(from_centre, bob_velocity, omega, scene.mass)
    distance = jnp.sqrt(jnp.sum(from_centre**2))
    return kinetic + scene.mass * scene.gravitational_parameter / distance


class PlumbLine(AbstractScene):
    r"""A plumb bob hung at geocentric latitude $\varphi$ on a spherical rotating Earth.

    $q = (x, y)$: the bob's offsets south and east of the suspension point, in the
    local axes whose $z$ is the geocentric vertical; $\boldsymbol\rho = R\hat z +
    \mathbf r$ is the bob's position from the Earth's centre.

    $$ L = \tfrac12 m|\dot{\mathbf r} + \boldsymbol\omega_E\times\boldsymbol\rho|^2
       + \frac{GMm}{|\boldsymbol\rho|}. $$

    At equilibrium the string lies along $\mathbf g_{\rm eff} = \mathbf g -
    \boldsymbol\omega\times(\boldsymbol\omega\times\boldsymbol\rho)$ at the bob (the
    course text eq. 1.30), deflected towards the equator from the geocentric vertical
    by $\tan\delta = \omega^2R\sin\varphi\cos\varphi/(g_0 - \omega^2R\cos^2\varphi)$,
    $g_0 = GM/R^2$ — about 0.1° at 45°. The bob hangs a length $l$ below the point
    where that formula holds, which shifts $\delta$ by a relative $O(l/R) \approx
    2\cdot10^{-7}$.

    Parameters (SI): `latitude` (rad, π/4), `length` (1 m), `earth_radius`,
    `gravitational_parameter` (GM), `earth_rate`, `mass`.
    """

    latitude: jax.Array = _parameter(jnp.pi / 4)
    length: jax.Array = _parameter(1.0)
    earth_radius: jax.Array = _parameter(6.371e6)
    gravitational_parameter: jax.Array = _parameter(3.986004418e14)
    earth_rate: jax.Array = _parameter(EARTH_RATE)
    mass: jax.Array = _parameter(1.0)

    default_t1: ClassVar[float] = 10.0
    default_dt: ClassVar[float] = 0.01
    state_kind: ClassVar[str] = "velocity"

    def system(self) -> Lagrangian:
        return Lagrangian(_plumb_lagrangian, quadratic_in_velocity=True)

    def site(self) -> jax.Array:
        """The suspension point from the Earth's centre, local axes."""
        zero = jnp.zeros_like(self.earth_radius)
        return jnp.stack([zero, zero, self.earth_radius])

    def effective_gravity(self, from_centre: jax.Array) -> jax.Array:
        """g_eff = −GM ρ/|ρ|³ − ω × (ω × ρ) (eq. 1.30)."""
        omega = earth_rotation(self.latitude, self.earth_rate)
        distance = jnp.sqrt(jnp.sum(from_centre**2))
        attraction = -self.gravitational_parameter * from_centre / distance**3
        return attraction - jnp.cross(omega, jnp.cross(omega, from_centre))

    def hanging_offset(self) -> jax.Array:
        """The bob's equilibrium offset r = l ĝ_eff(R ẑ + r), by fixed-point iteration.

        The map contracts by ~l/R per step, so three steps reach round-off.
        """
        offset = jnp.zeros(3)
        for _ in range(3):
            pull = self.effective_gravity(self.site() + offset)
            offset = self.length * pull / jnp.sqrt(jnp.sum(pull**2))
        return offset

    def deflection(self) -> jax.Array:
        """δ from the geocentric vertical at the site, closed form (see docstring)."""
        centrifugal = self.earth_rate**2 * self.earth_radius
        surface_gravity = self.gravitational_parameter / self.earth_radius**2
        phi = self.latitude
        return jnp.arctan2(
            centrifugal * jnp.sin(phi) * jnp.cos(phi),
            surface_gravity - centrifugal * jnp.cos(phi) ** 2,
        )

    def string_deflection(self, q: jax.Array) -> jax.Array:
        """Angle between the string to the bob at q and the geocentric vertical."""
        bob = bob_offset(q, self.length)
        return jnp.arctan2(jnp.sqrt(bob[0] ** 2 + bob[1] ** 2), -bob[2])

    def initial_state(self) -> tuple[jax.Array, jax.Array]:
        """At rest on the plumb line (`hanging_offset`)."""
        return self.hanging_offset()[:2], jnp.zeros(2)

    def checks(self, trajectory) -> dict[str, tuple[jax.Array, jax.Array]]:
        """The bob stays put; its string's deflection matches δ to O(l/R)."""
        final = trajectory.q[-1]
        return {
            "bob at rest on the plumb line": (final, self.hanging_offset()[:2]),
            "plumb-line deflection": (self.string_deflection(final), self.deflection()),
        }


# ---------------------------------------------------------------------------------
# A frame turning with angular acceleration about a fixed axis.


def _spinning_frame_lagrangian(q, qdot, t, scene):
    inertial, inertial_velocity = inertial_motion(scene.to_inertial, q, qdot, t)
    kinetic = 0.5 * scene.mass * jnp.sum(inertial_velocity**2)
    return kinetic + scene.mass * jnp.dot(scene.gravity, inertial)


class SpinningFrameParticle(AbstractScene):
    r"""A particle under uniform gravity seen from a frame turning about a tilted axis.

    The frame turns by $\theta(t) = \omega_0 t + \tfrac12\alpha t^2$ about the fixed
    unit axis $\hat n$, so $\boldsymbol\omega = (\omega_0 + \alpha t)\hat n$ and
    $\dot{\boldsymbol\omega} = \alpha\hat n$ (the same components in both frames).
    With $\mathbf x = R_{\hat n}(\theta(t))\,\mathbf r'$ the inertial position,

    $$ L(\mathbf r', \dot{\mathbf r}', t) = \tfrac12 m|\dot{\mathbf x}|^2
       + m\,\mathbf g\cdot\mathbf x, $$

    composed with `jax.jvp` of the frame map: Coriolis, centrifugal and Euler forces
    all come from the derivation. Closed forms: the inertial parabola
    $\mathbf x(t) = \mathbf x_0 + \mathbf v_0 t + \tfrac12\mathbf g t^2$ turned back
    into the frame, and the frame acceleration of eq. 1.27 (the course text §1.3).

    Parameters (SI): `spin_rate` $\omega_0$ (1 rad/s), `spin_acceleration` $\alpha$
    (0.5 rad/s²), `axis` (tilted 30° from vertical; normalised), `gravity`
    (inertial vector, (0, 0, −9.81)), `mass`.
    """

    spin_rate: jax.Array = _parameter(1.0)
    spin_acceleration: jax.Array = _parameter(0.5)
    axis: jax.Array = _parameter((0.0, 0.5, 0.75**0.5))
    gravity: jax.Array = _parameter((0.0, 0.0, -9.81))
    mass: jax.Array = _parameter(1.0)

    default_t1: ClassVar[float] = 3.0
    default_dt: ClassVar[float] = 1e-3
    state_kind: ClassVar[str] = "velocity"

    def system(self) -> Lagrangian:
        return Lagrangian(_spinning_frame_lagrangian, quadratic_in_velocity=True)

    def initial_state(self) -> tuple[jax.Array, jax.Array]:
        """At (1, 0, 2) m moving at (0, 1, 3) m/s relative to the frame."""
        return jnp.array([1.0, 0.0, 2.0]), jnp.array([0.0, 1.0, 3.0])

    def unit_axis(self) -> jax.Array:
        return self.axis / jnp.sqrt(jnp.sum(self.axis**2))

    def frame_angle(self, t: ArrayLike) -> jax.Array:
        """θ(t) = ω₀ t + α t²/2."""
        return self.spin_rate * t + 0.5 * self.spin_acceleration * t**2

    def angular_velocity(self, t: ArrayLike) -> jax.Array:
        """ω(t) = (ω₀ + α t) n̂."""
        return (self.spin_rate + self.spin_acceleration * t) * self.unit_axis()

    def to_inertial(self, position: jax.Array, t: ArrayLike) -> jax.Array:
        """x = R(θ(t)) r' (the frame map)."""
        return rotate(self.unit_axis(), self.frame_angle(t), position)

    def to_frame(self, position: jax.Array, t: ArrayLike) -> jax.Array:
        """r' = R(θ(t))ᵀ x."""
        return rotate(self.unit_axis(), -self.frame_angle(t), position)

    def frame_acceleration(self, r, v, t) -> jax.Array:
        """a' = Rᵀg − 2ω×v' − ω×(ω×r') − ω̇×r' (eq. 1.27)."""
        omega = self.angular_velocity(t)
        return (
            self.to_frame(self.gravity, t)
            - 2 * jnp.cross(omega, v)
            - jnp.cross(omega, jnp.cross(omega, r))
            - jnp.cross(self.spin_acceleration * self.unit_axis(), r)
        )

    def frame_position(self, t: ArrayLike) -> jax.Array:
        """r'(t) of the run from `initial_state()` at t = 0: the inertial parabola."""
        r0, v0 = self.initial_state()
        x0, inertial_v0 = r0, v0 + jnp.cross(self.angular_velocity(0.0), r0)

        t_column = jnp.asarray(t)[..., None]
        parabola = x0 + inertial_v0 * t_column + 0.5 * self.gravity * t_column**2
        return self.to_frame(parabola, t)

    def checks(self, trajectory) -> dict[str, tuple[jax.Array, jax.Array]]:
        """Saved positions against the inertial parabola seen from the frame."""
        return {"position": (trajectory.q, self.frame_position(trajectory.ts))}


# ---------------------------------------------------------------------------------
# A rectilinearly accelerated frame.


def _accelerated_frame_lagrangian(q, qdot, t, scene):
    inertial, inertial_velocity = inertial_motion(scene.to_inertial, q, qdot, t)
    kinetic = 0.5 * scene.mass * jnp.sum(inertial_velocity**2)
    return kinetic + scene.mass * jnp.dot(scene.gravity, inertial)


class AcceleratedFrameParticle(AbstractScene):
    r"""A particle under uniform gravity seen from a frame translated along $\mathbf R(t)$.

    The frame's axes stay parallel to the inertial ones while its origin moves on
    $\mathbf R(t) = \tfrac12\mathbf a t^2 + \mathbf b\sin\nu t$; with $\mathbf x =
    \mathbf r' + \mathbf R(t)$,

    $$ L(\mathbf r', \dot{\mathbf r}', t) = \tfrac12 m|\dot{\mathbf r}' +
       \dot{\mathbf R}(t)|^2 + m\,\mathbf g\cdot(\mathbf r' + \mathbf R(t)), $$

    so that $\ddot{\mathbf r}' = \mathbf g - \ddot{\mathbf R}(t)$: the fictitious
    force $-m\ddot{\mathbf R}$ (the course text §1.2, eq. 1.6; Landau & Lifshitz §39).

    Parameters (SI): `frame_acceleration` $\mathbf a$ ((2, 0, 0) m/s²),
    `shake_amplitude` $\mathbf b$ ((0, 0.5, 0) m), `shake_frequency` $\nu$ (3 rad/s),
    `gravity` ((0, 0, −9.81)), `mass`.
    """

    frame_acceleration: jax.Array = _parameter((2.0, 0.0, 0.0))
    shake_amplitude: jax.Array = _parameter((0.0, 0.5, 0.0))
    shake_frequency: jax.Array = _parameter(3.0)
    gravity: jax.Array = _parameter((0.0, 0.0, -9.81))
    mass: jax.Array = _parameter(1.0)

    default_t1: ClassVar[float] = 3.0
    default_dt: ClassVar[float] = 1e-3
    state_kind: ClassVar[str] = "velocity"

    def system(self) -> Lagrangian:
        return Lagrangian(_accelerated_frame_lagrangian, quadratic_in_velocity=True)

    def initial_state(self) -> tuple[jax.Array, jax.Array]:
        """At (0, 0, 1) m moving at (1, 0, 5) m/s relative to the frame."""
        return jnp.array([0.0, 0.0, 1.0]), jnp.array([1.0, 0.0, 5.0])

    def origin(self, t: ArrayLike) -> jax.Array:
        """R(t) = a t²/2 + b sin νt."""
        t = jnp.asarray(t)[..., None]
        shake = self.shake_amplitude * jnp.sin(self.shake_frequency * t)
        return 0.5 * self.frame_acceleration * t**2 + shake

    def origin_acceleration(self, t: ArrayLike) -> jax.Array:
        """R̈(t) = a − ν² b sin νt."""
        t = jnp.asarray(t)[..., None]
        nu = self.shake_frequency
        return self.frame_acceleration - nu**2 * self.shake_amplitude * jnp.sin(nu * t)

    def to_inertial(self, position: jax.Array, t: ArrayLike) -> jax.Array:
        return position + self.origin(t)

    def fictitious_force(self, t: ArrayLike) -> jax.Array:
        """−m R̈(t)."""
        return -self.mass * self.origin_acceleration(t)

    def frame_position(self, t: ArrayLike) -> jax.Array:
        """r'(t) = x(t) − R(t) for the run from `initial_state()` at t = 0."""
        r0, v0 = self.initial_state()
        x0 = r0 + self.origin(0.0)
        inertial_v0 = v0 + self.shake_frequency * self.shake_amplitude  # Ṙ(0) = ν b
        t_column = jnp.asarray(t)[..., None]
        parabola = x0 + inertial_v0 * t_column + 0.5 * self.gravity * t_column**2
        return parabola - self.origin(t)

    def checks(self, trajectory) -> dict[str, tuple[jax.Array, jax.Array]]:
        """Saved positions against the inertial parabola less R(t)."""
        return {"position": (trajectory.q, self.frame_position(trajectory.ts))}


# ---------------------------------------------------------------------------------
# Bead on a uniformly rotating wire: a rheonomic constraint.


def _wire_lagrangian(q, qdot, t, scene):
    def on_wire(r, time):
        angle = scene.angular_velocity * time
        return jnp.stack([r * jnp.cos(angle), r * jnp.sin(angle)])

    _, velocity = inertial_motion(on_wire, q, qdot, t)
    return 0.5 * scene.mass * jnp.sum(velocity**2)


class BeadOnRotatingWire(AbstractScene):
    r"""A bead sliding freely on a straight wire turning at $\omega$ in a plane.

    The constraint $x = r\cos\omega t$, $y = r\sin\omega t$ depends on time
    (rheonomic); composing $T = \tfrac12 m(\dot x^2 + \dot y^2)$ with it gives

    $$ L(r, \dot r, t) = \tfrac12 m(\dot r^2 + \omega^2 r^2), \qquad \ddot r = \omega^2 r, $$

    $r(t) = A e^{\omega t} + B e^{-\omega t}$, $A, B = \tfrac12(r_0 \pm \dot r_0/\omega)$
    (the course text §3, eq. 3.83–3.87). The energy is not conserved (the wire does
    work) but Jacobi's integral $h = \tfrac12 m(\dot r^2 - \omega^2 r^2)$ is.

    Parameters (SI): `angular_velocity` (2 rad/s), `mass`.
    """

    angular_velocity: jax.Array = _parameter(2.0)
    mass: jax.Array = _parameter(1.0)

    default_t1: ClassVar[float] = 2.0
    default_dt: ClassVar[float] = 1e-3
    state_kind: ClassVar[str] = "velocity"

    def system(self) -> Lagrangian:
        return Lagrangian(_wire_lagrangian, quadratic_in_velocity=True)

    def initial_state(self) -> tuple[jax.Array, jax.Array]:
        """r = 0.1 m moving inwards at 0.15 m/s: it turns round, then flies out."""
        return jnp.asarray(0.1), jnp.asarray(-0.15)

    def radius(self, t: ArrayLike) -> jax.Array:
        """r(t) = A e^{ωt} + B e^{−ωt} for the run from `initial_state()`."""
        r0, v0 = self.initial_state()
        omega = self.angular_velocity
        outward, inward = 0.5 * (r0 + v0 / omega), 0.5 * (r0 - v0 / omega)
        return outward * jnp.exp(omega * t) + inward * jnp.exp(-omega * t)

    def jacobi_integral(self) -> jax.Array:
        """h = ½ m (ṙ² − ω² r²), constant along the motion."""
        r0, v0 = self.initial_state()
        return 0.5 * self.mass * (v0**2 - self.angular_velocity**2 * r0**2)

    def checks(self, trajectory) -> dict[str, tuple[jax.Array, jax.Array]]:
        """Radius against the closed form; Jacobi's integral constant."""
        return {
            "radius": (trajectory.q, self.radius(trajectory.ts)),
            "Jacobi integral": (
                trajectory.energy(),
                self.jacobi_integral() * jnp.ones_like(trajectory.ts),
            ),
        }


SCENES = (
    FoucaultPendulum,
    EastwardDeflection,
    PlumbLine,
    SpinningFrameParticle,
    AcceleratedFrameParticle,
    BeadOnRotatingWire,
)
