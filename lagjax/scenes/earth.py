r"""Local Earth frames: the Foucault pendulum, eastward deflection, the plumb line.

The Earth turns at $\omega_E$ about its axis; in local axes at latitude $\varphi$
— the course text's $x$ due south, $y$ due east, $z$ up (§1.4.3, eq. 1.35) —
$\boldsymbol\omega_E = \omega_E(-\cos\varphi, 0, \sin\varphi)$. Each scene writes the
inertial Lagrangian in these rotating coordinates,
$L = \tfrac12 m|\dot{\mathbf r} + \boldsymbol\omega_E\times\mathbf r|^2 - V$, and
lagjax derives the Coriolis and centrifugal forces (see `rotating.py`).

References: the course text §1.3–1.4 ($g_{\rm eff}$, eq. 1.30; Foucault pendulum;
falling bodies); Landau & Lifshitz, *Mechanics* §39; Goldstein, Poole & Safko,
*Classical Mechanics*, 3rd ed., §4.10.
"""

from __future__ import annotations

from typing import ClassVar

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from lagjax.mechanics.lagrangian import Lagrangian
from lagjax.scenes.base import (
    LATITUDE,
    AbstractScene,
    Diagnostic,
    StateKind,
    parameter,
)
from lagjax.scenes.judging import measured
from lagjax.scenes.rotating import rotating_kinetic_energy

EARTH_RATE = 7.2921159e-5  # sidereal angular velocity of the Earth, rad/s


def earth_rotation(latitude: jax.Array, earth_rate: jax.Array) -> jax.Array:
    """ω_E in the local (south, east, up) axes at `latitude` (eq. 1.35)."""
    return earth_rate * jnp.stack(
        [-jnp.cos(latitude), jnp.zeros_like(latitude), jnp.sin(latitude)]
    )


def bob_offset(q: jax.Array, length: jax.Array) -> jax.Array:
    """Bob below its suspension point, from its horizontal offsets q = (x, y)."""
    height = -jnp.sqrt(length**2 - q[0] ** 2 - q[1] ** 2)
    return jnp.stack([q[0], q[1], height])


def _local_earth_lagrangian(position, velocity, t, scene) -> jax.Array:
    r"""$\tfrac12 m|\dot{\mathbf r} + \boldsymbol\omega_E\times\mathbf r|^2 - mgz$.

    `gravity` is the effective $g$ along the local plumb line: the centrifugal
    potential of the frame's origin is part of it (eq. 1.30), so `latitude` is the
    astronomical one (the plumb line's angle to the equatorial plane).
    """
    omega = earth_rotation(scene.latitude, scene.earth_rate)
    kinetic = rotating_kinetic_energy(position, velocity, omega, scene.mass)
    return kinetic - scene.mass * scene.gravity * position[2]


def _foucault_lagrangian(q, qdot, t, scene):
    bob, bob_velocity = jax.jvp(lambda x: bob_offset(x, scene.length), (q,), (qdot,))
    return _local_earth_lagrangian(bob, bob_velocity, t, scene)


def _weighted_slope(ts: jax.Array, values: jax.Array) -> jax.Array:
    """Least-squares slope of `values` against `ts`, with weights sin²(π s), s∈[0,1].

    Why the taper: a fast oscillation of amplitude A and frequency Ω riding on the
    trend tilts a plain fit over a window W by up to ~6A/(ΩW²), depending on where
    the window cuts it; weights that vanish smoothly at both ends remove that edge
    effect (measured: ±2·10⁻⁵ relative scatter of the Foucault rate → ~10⁻⁸).
    """
    weights = jnp.sin(jnp.pi * (ts - ts[0]) / (ts[-1] - ts[0])) ** 2
    weights = weights / jnp.sum(weights)
    t_centred = ts - jnp.sum(weights * ts)
    v_centred = values - jnp.sum(weights * values)
    return jnp.sum(weights * t_centred * v_centred) / jnp.sum(weights * t_centred**2)


class FoucaultPendulum(AbstractScene):
    r"""A spherical pendulum in the Earth's rotating frame, q = (x, y) (south, east).

    $$ L = \tfrac12 m|\dot{\mathbf r} + \boldsymbol\omega_E\times\mathbf r|^2 - mgz,
       \qquad \mathbf r = (x, y, -\sqrt{l^2 - x^2 - y^2}). $$

    Released at rest a distance $a$ due south, the plane of oscillation turns
    clockwise (seen from above, northern hemisphere) at $-\omega_E\sin\varphi$: a full
    turn takes $24\,\mathrm h/\sin\varphi$ (the course text §1.4.3, eq. 1.57; ≈34 h
    at 45°; Landau & Lifshitz §39 prob. 3). A finite amplitude adds Airy's precession
    of the slightly elliptical swing (G. B. Airy, 1851), $-\tfrac38(a/l)^2$ of that
    rate: −3.9·10⁻⁵ with the defaults, resolved by the tests.

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

    latitude: jax.Array = parameter(jnp.pi / 4, within=LATITUDE, angle=True)
    length: jax.Array = parameter(9.81, positive=True)
    gravity: jax.Array = parameter(9.81, positive=True)
    amplitude: jax.Array = parameter(0.1, positive=True)
    earth_rate: jax.Array = parameter(EARTH_RATE)
    mass: jax.Array = parameter(1.0, positive=True)

    default_t1: ClassVar[float] = 300.0
    default_dt: ClassVar[float] = 0.05
    state_kind: ClassVar[StateKind] = "velocity"
    coordinate_names: ClassVar[tuple[str, ...]] = ("x (south)", "y (east)")
    coordinate_units: ClassVar[tuple[str, ...]] = ("m", "m")

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
                measured(
                    self.measured_precession_rate(trajectory),
                    self,
                    "the precession rate",
                    "saves along the run to fit its slope",
                ),
                self.precession_rate(),
            )
        }

    def diagnostic(self, trajectory) -> Diagnostic:
        """The swing plane's turn since the start against −ω_E sin φ · t."""
        angle = self.plane_angle(trajectory.q, trajectory.qdot)
        elapsed = trajectory.ts - trajectory.ts[0]
        return Diagnostic(
            "swing-plane angle θ(t) − θ(0) [rad]",
            trajectory.ts,
            angle - angle[0],
            self.precession_rate() * elapsed,
            "−ω_E sin φ · t",
        )


class EastwardDeflection(AbstractScene):
    r"""A body dropped from rest at height h, in the local Earth frame (south, east, up).

    $$ L = \tfrac12 m|\dot{\mathbf r} + \boldsymbol\omega_E\times\mathbf r|^2 - mgz. $$

    Expanding in $\omega_E$ about free fall $z = h - \tfrac12 g t^2$:

    - east, first order: $y_1 = \tfrac13\omega_E g t^3\cos\varphi$ (Landau &
      Lifshitz §39 prob. 1; Goldstein §4.10). The next term (derived here, and
      confirmed to 10⁻¹² by the tests) is $y_3 = -y_1\,\omega_E^2(h/g + t^2/10)$: at
      the fall time $T = \sqrt{2h/g}$ the first-order formula is off by
      $0.6(\omega_E T)^2 \approx 7\cdot10^{-8}$;
    - south, second order (Coriolis on the eastward drift plus the centrifugal force
      about the origin): $x_2 = \omega_E^2\sin\varphi\cos\varphi\,(h t^2/2 + g t^4/8)$.

    `gravity` is the effective $g$ at the ground (the origin); `latitude` (rad, π/4),
    `drop_height` (100 m), `earth_rate`, `mass`.
    """

    latitude: jax.Array = parameter(jnp.pi / 4, within=LATITUDE, angle=True)
    drop_height: jax.Array = parameter(100.0, positive=True)
    gravity: jax.Array = parameter(9.81, positive=True)
    earth_rate: jax.Array = parameter(EARTH_RATE)
    mass: jax.Array = parameter(1.0, positive=True)

    default_t1: ClassVar[float] = 4.5  # ≈ √(2h/g) for h = 100 m
    default_dt: ClassVar[float] = 0.01
    state_kind: ClassVar[StateKind] = "velocity"
    coordinate_names: ClassVar[tuple[str, ...]] = ("x (south)", "y (east)", "z (up)")
    coordinate_units: ClassVar[tuple[str, ...]] = ("m", "m", "m")

    def system(self) -> Lagrangian:
        return Lagrangian(_local_earth_lagrangian, quadratic_in_velocity=True)

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

    def diagnostic(self, trajectory) -> Diagnostic:
        """The eastward drift y(t) against ⅓ ω_E g t³ cos φ."""
        return Diagnostic(
            "eastward drift y [m]",
            trajectory.ts,
            trajectory.q[:, 1],
            self.eastward_deflection(trajectory.ts),
            "⅓ ω_E g t³ cos φ",
        )


def _plumb_lagrangian(q, qdot, t, scene):
    bob, bob_velocity = jax.jvp(lambda x: bob_offset(x, scene.length), (q,), (qdot,))
    from_centre = scene.site() + bob
    omega = earth_rotation(scene.latitude, scene.earth_rate)
    kinetic = rotating_kinetic_energy(from_centre, bob_velocity, omega, scene.mass)
    distance = jnp.sqrt(jnp.sum(from_centre**2))
    return kinetic + scene.mass * scene.gravitational_parameter / distance


class PlumbLine(AbstractScene):
    r"""A plumb bob hung at geocentric latitude φ on a spherical rotating Earth.

    $q = (x, y)$: the bob's offsets south and east of the suspension point, in the
    local axes whose $z$ is the geocentric vertical; $\boldsymbol\rho = R\hat z +
    \mathbf r$ is the bob's position from the Earth's centre.

    $$ L = \tfrac12 m|\dot{\mathbf r} + \boldsymbol\omega_E\times\boldsymbol\rho|^2
       + \frac{GMm}{|\boldsymbol\rho|}. $$

    At equilibrium the string lies along $\mathbf g_{\rm eff} = \mathbf g -
    \boldsymbol\omega\times(\boldsymbol\omega\times\boldsymbol\rho)$ at the bob (the
    course text eq. 1.30), deflected towards the equator from the geocentric vertical
    by $\tan\delta = \omega^2R\sin\varphi\cos\varphi/(g_0 - \omega^2R\cos^2\varphi)$,
    $g_0 = GM/R^2$ — about 0.1° at 45°. That formula holds at the site; the bob
    hangs $l$ lower, which changes $\delta$ by $-4l/R \approx -6\cdot10^{-7}$
    relative ($-3l/R$ as centrifugal over gravitational pull scales as $\rho^3$, $-l/R$
    as the bob's own vertical is turned by its offset).

    Parameters (SI): `latitude` (rad, π/4), `length` (1 m), `earth_radius`,
    `gravitational_parameter` (GM), `earth_rate`, `mass`.
    """

    latitude: jax.Array = parameter(jnp.pi / 4, within=LATITUDE, angle=True)
    length: jax.Array = parameter(1.0, positive=True)
    earth_radius: jax.Array = parameter(6.371e6, positive=True)
    gravitational_parameter: jax.Array = parameter(3.986004418e14, positive=True)
    earth_rate: jax.Array = parameter(EARTH_RATE)
    mass: jax.Array = parameter(1.0, positive=True)

    default_t1: ClassVar[float] = 10.0
    default_dt: ClassVar[float] = 0.01
    state_kind: ClassVar[StateKind] = "velocity"
    coordinate_names: ClassVar[tuple[str, ...]] = ("x (south)", "y (east)")
    coordinate_units: ClassVar[tuple[str, ...]] = ("m", "m")

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
        """The bob stays put; its string's deflection matches δ to 4l/R."""
        final = trajectory.q[-1]
        return {
            "bob at rest on the plumb line": (final, self.hanging_offset()[:2]),
            "plumb-line deflection": (self.string_deflection(final), self.deflection()),
        }


SCENES = (FoucaultPendulum, EastwardDeflection, PlumbLine)
