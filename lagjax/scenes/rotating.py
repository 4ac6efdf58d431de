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

Scenes on the turning Earth (Foucault pendulum, eastward deflection, plumb line)
live in `earth.py` and reuse the helpers here.

References: the course text §1.2–1.4 (rectilinear and rotating frames, $g_{\rm eff}$,
Foucault pendulum) and §3 (bead on a rotating wire, eq. 3.83–3.87); Landau &
Lifshitz, *Mechanics* §39 (motion in a non-inertial frame); Goldstein, Poole &
Safko, *Classical Mechanics*, 3rd ed., §4.10 (Coriolis effect, eastward deflection,
Foucault pendulum).
"""

from __future__ import annotations

import abc
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from lagjax.mechanics.lagrangian import Lagrangian
from lagjax.scenes.base import AbstractScene, StateKind, parameter


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


def _moving_frame_lagrangian(q, qdot, t, scene):
    inertial, inertial_velocity = inertial_motion(scene.to_inertial, q, qdot, t)
    kinetic = 0.5 * scene.mass * jnp.sum(inertial_velocity**2)
    return kinetic + scene.mass * jnp.dot(scene.gravity, inertial)


class AbstractMovingFrameParticle(AbstractScene):
    r"""A particle under uniform gravity $\mathbf g$, seen from a moving frame.

    A subclass gives the frame map $\mathbf x(\mathbf r', t)$ (`to_inertial`) and
    its inverse (`to_frame`). The inertial Lagrangian, with $(\mathbf x,
    \dot{\mathbf x})$ pushed through the frame map by `jax.jvp`,

    $$ L(\mathbf r', \dot{\mathbf r}', t) = \tfrac12 m|\dot{\mathbf x}|^2
       + m\,\mathbf g\cdot\mathbf x, $$

    is the whole model; the closed form is the inertial parabola
    $\mathbf x_0 + \mathbf v_0 t + \tfrac12\mathbf g t^2$ mapped into the frame.
    """

    gravity: eqx.AbstractVar[jax.Array]
    mass: eqx.AbstractVar[jax.Array]

    default_t1: ClassVar[float] = 3.0
    default_dt: ClassVar[float] = 1e-3
    state_kind: ClassVar[StateKind] = "velocity"
    coordinate_names: ClassVar[tuple[str, ...]] = ("x′", "y′", "z′")
    coordinate_units: ClassVar[tuple[str, ...]] = ("m", "m", "m")

    @abc.abstractmethod
    def to_inertial(self, position: jax.Array, t: ArrayLike) -> jax.Array:
        """x(r', t), for one point."""

    @abc.abstractmethod
    def to_frame(self, position: jax.Array, t: ArrayLike) -> jax.Array:
        """r'(x, t); `position` (..., 3) and `t` (...) may carry time axes."""

    def system(self) -> Lagrangian:
        return Lagrangian(_moving_frame_lagrangian, quadratic_in_velocity=True)

    def initial_state(self) -> tuple[jax.Array, jax.Array]:
        """At (1, 0, 2) m moving at (0, 1, 3) m/s relative to the frame, at t = 0."""
        return jnp.array([1.0, 0.0, 2.0]), jnp.array([0.0, 1.0, 3.0])

    def frame_position(self, t: ArrayLike) -> jax.Array:
        """r'(t) of the run from `initial_state()` at t = 0: the parabola, mapped."""
        x0, v0 = inertial_motion(self.to_inertial, *self.initial_state(), 0.0)
        t_column = jnp.asarray(t)[..., None]
        parabola = x0 + v0 * t_column + 0.5 * self.gravity * t_column**2
        return self.to_frame(parabola, t)

    def checks(self, trajectory) -> dict[str, tuple[jax.Array, jax.Array]]:
        """Saved positions against the inertial parabola seen from the frame."""
        return {"position": (trajectory.q, self.frame_position(trajectory.ts))}


class SpinningFrameParticle(AbstractMovingFrameParticle):
    r"""A particle under gravity, seen from a frame spinning up about a fixed axis.

    The frame turns by $\theta(t) = \omega_0 t + \tfrac12\alpha t^2$:
    $\mathbf x = R_{\hat n}(\theta(t))\,\mathbf r'$, so $\boldsymbol\omega =
    (\omega_0 + \alpha t)\hat n$ and $\dot{\boldsymbol\omega} = \alpha\hat n$ (the
    same components in both frames). Coriolis, centrifugal and Euler forces all come
    from the derivation of $L$ (`AbstractMovingFrameParticle`); `frame_acceleration`
    is their closed form, eq. 1.27 (the course text §1.3; Landau & Lifshitz §39).

    Parameters (SI): `spin_rate` $\omega_0$ (1 rad/s), `spin_acceleration` $\alpha$
    (0.5 rad/s²), `axis` (30° from vertical; normalised), `gravity` (inertial,
    (0, 0, −9.81)), `mass`.
    """

    spin_rate: jax.Array = parameter(1.0)
    spin_acceleration: jax.Array = parameter(0.5)
    axis: jax.Array = parameter((0.0, 0.5, 0.75**0.5))
    gravity: jax.Array = parameter((0.0, 0.0, -9.81))
    mass: jax.Array = parameter(1.0, positive=True)

    def unit_axis(self) -> jax.Array:
        return self.axis / jnp.sqrt(jnp.sum(self.axis**2))

    def frame_angle(self, t: ArrayLike) -> jax.Array:
        """θ(t) = ω₀ t + α t²/2."""
        return self.spin_rate * t + 0.5 * self.spin_acceleration * t**2

    def angular_velocity(self, t: ArrayLike) -> jax.Array:
        """ω(t) = (ω₀ + α t) n̂."""
        return (self.spin_rate + self.spin_acceleration * t) * self.unit_axis()

    def to_inertial(self, position: jax.Array, t: ArrayLike) -> jax.Array:
        return rotate(self.unit_axis(), self.frame_angle(t), position)

    def to_frame(self, position: jax.Array, t: ArrayLike) -> jax.Array:
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


class AcceleratedFrameParticle(AbstractMovingFrameParticle):
    r"""A particle under gravity, seen from a frame that accelerates and shakes.

    The frame's origin moves on
    $\mathbf R(t) = \tfrac12\mathbf a t^2 + \mathbf b\sin\nu t$; its axes stay parallel to the inertial ones: $\mathbf x = \mathbf r' +
    \mathbf R(t)$, so $L = \tfrac12 m|\dot{\mathbf r}' + \dot{\mathbf R}|^2 +
    m\,\mathbf g\cdot(\mathbf r' + \mathbf R)$ and $\ddot{\mathbf r}' = \mathbf g -
    \ddot{\mathbf R}(t)$: the fictitious force $-m\ddot{\mathbf R}$ (the course text
    §1.2, eq. 1.6; Landau & Lifshitz §39).

    Parameters (SI): `frame_acceleration` $\mathbf a$ ((2, 0, 0) m/s²),
    `shake_amplitude` $\mathbf b$ ((0, 0.5, 0) m), `shake_frequency` $\nu$ (3 rad/s),
    `gravity` ((0, 0, −9.81)), `mass`.
    """

    frame_acceleration: jax.Array = parameter((2.0, 0.0, 0.0))
    shake_amplitude: jax.Array = parameter((0.0, 0.5, 0.0))
    shake_frequency: jax.Array = parameter(3.0)
    gravity: jax.Array = parameter((0.0, 0.0, -9.81))
    mass: jax.Array = parameter(1.0, positive=True)

    def origin(self, t: ArrayLike) -> jax.Array:
        """R(t) = a t²/2 + b sin νt."""
        t = jnp.asarray(t)[..., None]
        shake = self.shake_amplitude * jnp.sin(self.shake_frequency * t)
        return 0.5 * self.frame_acceleration * t**2 + shake

    def fictitious_force(self, t: ArrayLike) -> jax.Array:
        """−m R̈(t) = −m (a − ν² b sin νt)."""
        t = jnp.asarray(t)[..., None]
        nu = self.shake_frequency
        shake = nu**2 * self.shake_amplitude * jnp.sin(nu * t)
        return -self.mass * (self.frame_acceleration - shake)

    def to_inertial(self, position: jax.Array, t: ArrayLike) -> jax.Array:
        return position + self.origin(t)

    def to_frame(self, position: jax.Array, t: ArrayLike) -> jax.Array:
        return position - self.origin(t)


def _wire_lagrangian(q, qdot, t, scene):
    def on_wire(r, time):
        angle = scene.angular_velocity * time
        return jnp.stack([r * jnp.cos(angle), r * jnp.sin(angle)])

    _, velocity = inertial_motion(on_wire, q, qdot, t)
    return 0.5 * scene.mass * jnp.sum(velocity**2)


class BeadOnRotatingWire(AbstractScene):
    r"""A bead sliding freely on a straight wire turning at rate ω in a plane.

    The constraint $x = r\cos\omega t$, $y = r\sin\omega t$ depends on time
    (rheonomic); composing $T = \tfrac12 m(\dot x^2 + \dot y^2)$ with it gives

    $$ L(r, \dot r, t) = \tfrac12 m(\dot r^2 + \omega^2 r^2), \qquad \ddot r = \omega^2 r, $$

    $r(t) = A e^{\omega t} + B e^{-\omega t}$, $A, B = \tfrac12(r_0 \pm \dot r_0/\omega)$
    (the course text §3, eq. 3.83–3.87). The energy is not conserved (the wire does
    work) but Jacobi's integral $h = \tfrac12 m(\dot r^2 - \omega^2 r^2)$ is.

    Parameters (SI): `angular_velocity` (2 rad/s), `mass`.
    """

    angular_velocity: jax.Array = parameter(2.0)
    mass: jax.Array = parameter(1.0, positive=True)

    default_t1: ClassVar[float] = 2.0
    default_dt: ClassVar[float] = 1e-3
    state_kind: ClassVar[StateKind] = "velocity"
    coordinate_names: ClassVar[tuple[str, ...]] = ("r",)
    coordinate_units: ClassVar[tuple[str, ...]] = ("m",)

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


SCENES = (SpinningFrameParticle, AcceleratedFrameParticle, BeadOnRotatingWire)
