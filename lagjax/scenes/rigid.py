r"""Rigid-body scenes: the torque-free body, the heavy top, the Earth's free wobble.

Each scene gives its physics two ways that must agree:

- `system()`: a `Lagrangian` in the course text's z-x-z Euler angles
  $(\phi, \theta, \psi)$, the scene convention (state `(angles, rates)`); singular
  at $\sin\theta = 0$ (gimbal lock), so the defaults start well away from it;
- `rigid_body()` with `initial_body_state()`: the same body as a `RigidBody` on
  `(quaternion, body angular momentum)`, for the Lie–Poisson solvers of
  `lagjax.solvers.lie_poisson`; integrate it with `args=scene`.

Known answers: the symmetric body's precession rate (course text eq. 4.47), the
asymmetric body's period (elliptic K), the top's nutation bounds (roots of the
cubic $f(u)$), and the constants of motion.

References: the course text §4.3, §4.7–4.8; Goldstein, Poole & Safko, *Classical
Mechanics*, 3rd ed., §5.6–5.7; Landau & Lifshitz, *Mechanics*, §35–37.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

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
from lagjax.sampled_signals import zero_crossing_times
from lagjax.scenes.base import AbstractScene, StateKind, parameter
from lagjax.scenes.judging import measured


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
    """(rotation matrices, body angular velocities) along either kind of run:
    Euler angles and their rates, or quaternions and body angular momenta."""
    if trajectory.q.shape[-1] == 4:
        return quaternion_to_matrix(trajectory.q), trajectory.p / moments
    omega = jax.vmap(euler_zxz_body_angular_velocity)(trajectory.q, trajectory.qdot)
    return jax.vmap(euler_zxz_to_rotation)(trajectory.q), omega


def _intermediate_axis_half_period(trajectory: Any, moments: jax.Array) -> jax.Array:
    """Time between the first two sign changes of ω₂ (NaN if fewer than two)."""
    _, omega = _body_motion(trajectory, moments)
    # ω̇₂ from Euler's equations, for the cubic Hermite refinement of each crossing.
    omega_2_rate = (moments[2] - moments[0]) * omega[:, 2] * omega[:, 0] / moments[1]
    first, second = zero_crossing_times(trajectory.ts, omega[:, 1], omega_2_rate, 2)
    return second - first


class TorqueFreeBody(AbstractScene):
    r"""A torque-free rigid body: the Dzhanibekov flip about its intermediate axis.

    $L = \tfrac12\sum_i I_i\,\omega_i^2$, with $\boldsymbol\omega$ the body
    angular velocity of the z-x-z Euler angles (Goldstein eq. 4.87). Spun about the
    intermediate axis ($I_1 < I_2 < I_3$) with a small wobble, it holds still for
    long, then turns over quickly, again and again: $\omega_2$ changes sign every
    half period $T/2 = 2K(m)/\nu$ (Landau & Lifshitz §37; `free_body_period`).
    Energy and the space angular momentum are conserved; for a symmetric body the
    same formula gives $T = 2\pi/|\Omega|$, $\Omega = (I_1 - I_3)\omega_3/I_1$
    (course text eq. 4.47).

    The default start has the intermediate axis vertical, $\theta = \pi/2$, so
    that $\mathbf L$ stays near the space z axis; then θ, the angle between the
    body's $e_3$ and $\mathbf L$, stays above π/6 (its value mid-flip for these
    moments), clear of the Euler angles' gimbal lock at $\sin\theta = 0$.
    `rigid_body()` and `initial_body_state()` give the same motion on quaternions.

    **Parameters:** `moments` $(I_1, I_2, I_3)$ (kg m², (1, 2, 3)), `omega0` body
    angular velocity (rad/s, (10⁻³, 1, 10⁻³)), `angles0` Euler angles
    (φ, θ, ψ) (rad, (0.3, π/2, 0)).

    References: the course text §4.8; Landau & Lifshitz, *Mechanics*, §37;
    Goldstein, Poole & Safko, *Classical Mechanics*, 3rd ed., §5.6.
    """

    moments: jax.Array = parameter((1.0, 2.0, 3.0), positive=True)
    omega0: jax.Array = parameter((1e-3, 1.0, 1e-3))
    angles0: jax.Array = parameter((0.3, math.pi / 2, 0.0), angle=True)

    default_t1: ClassVar[float] = 60.0
    default_dt: ClassVar[float] = 0.01
    state_kind: ClassVar[StateKind] = "velocity"
    coordinate_names: ClassVar[tuple[str, ...]] = ("φ", "θ", "ψ")
    coordinate_units: ClassVar[tuple[str, ...]] = ("rad", "rad", "rad")

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
        """Period T of ω(t) in the body frame (s)."""
        momentum_squared = jnp.sum((self.moments * self.omega0) ** 2)
        return free_body_period(self.moments, self.energy(), momentum_squared)

    def precession_rate(self) -> jax.Array:
        """Ω = (I1 − I3) ω3 / I1 (rad/s; symmetric body, I1 = I2)."""
        return symmetric_precession_rate(self.moments, self.omega0[2])

    def checks(self, trajectory: Any) -> dict[str, tuple[jax.Array, jax.Array]]:
        """The half period from ω₂'s sign changes (needs two in the run), energy and
        the space angular momentum along the run."""
        rotation, omega = _body_motion(trajectory, self.moments)
        space_momentum = jnp.einsum("tij,tj->ti", rotation, self.moments * omega)
        energy = 0.5 * jnp.sum(self.moments * omega**2, axis=-1)
        half_period = _intermediate_axis_half_period(trajectory, self.moments)
        return {
            "half period": (
                measured(
                    half_period,
                    self,
                    "the half period",
                    "two sign changes of ω₂ among the saves (save over a period)",
                ),
                0.5 * self.period(),
            ),
            "energy": (energy, jnp.full_like(energy, self.energy())),
            "angular momentum": (
                space_momentum,
                jnp.broadcast_to(self.angular_momentum_space(), space_momentum.shape),
            ),
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
    r"""A heavy symmetric top on a fixed tip: it precesses and nods between two angles.

    $L = \tfrac12 I_1(\dot\theta^2 + \dot\phi^2\sin^2\theta)
    + \tfrac12 I_3(\dot\psi + \dot\phi\cos\theta)^2 - Mgl\cos\theta$ in the
    course text's Euler angles. θ stays between the roots of the cubic
    $f(u) = \dot u^2$, $u = \cos\theta$ (`nutation_bounds`); a fast top precesses
    at about $Mgl/I_3\omega_3$ and nods at about $I_3\omega_3/I_1$
    (`lagjax.rigid.heavy_top`). At $\sin\theta = 0$ the Euler-angle Lagrangian is
    singular (gimbal lock); `rigid_body()` with `initial_body_state()` is the same
    top on quaternions, which has no such point.

    **Parameters:** `i1`, `i3` moments about the tip (kg m², 1 and 0.5), `mgl`
    $Mgl$ (J, 1), start tilt `theta0` (rad, 0.5), spin `spin` $\omega_3$ (rad/s,
    40), start rates `phi_dot0`, `theta_dot0` (rad/s, 0: released from rest in φ
    and θ). The defaults are a fast top, $\epsilon = I_1 Mgl\cos\theta/(I_3
    \omega_3)^2 \approx 2\cdot10^{-3}$.

    References: Goldstein, Poole & Safko, *Classical Mechanics*, 3rd ed., §5.7;
    Landau & Lifshitz, *Mechanics*, §35.
    """

    i1: jax.Array = parameter(1.0, positive=True)
    i3: jax.Array = parameter(0.5, positive=True)
    mgl: jax.Array = parameter(1.0)
    theta0: jax.Array = parameter(0.5, angle=True)
    spin: jax.Array = parameter(40.0)
    phi_dot0: jax.Array = parameter(0.0)
    theta_dot0: jax.Array = parameter(0.0)

    default_t1: ClassVar[float] = 5.0
    default_dt: ClassVar[float] = 1e-3
    state_kind: ClassVar[StateKind] = "velocity"
    coordinate_names: ClassVar[tuple[str, ...]] = ("φ", "θ", "ψ")
    coordinate_units: ClassVar[tuple[str, ...]] = ("rad", "rad", "rad")

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
        """Extremes of θ over the *saved* times against the nutation bounds (so only
        as close as the sampling resolves the turning points), and the spin ω3."""
        rotation, omega = _body_motion(trajectory, self.rigid_body().moments)
        theta = jnp.arccos(jnp.clip(rotation[:, 2, 2], -1.0, 1.0))
        theta_min, theta_max = self.nutation_bounds()
        spin = omega[:, 2]
        return {
            "theta min": (jnp.min(theta), theta_min),
            "theta max": (jnp.max(theta), theta_max),
            "spin": (spin, jnp.full_like(spin, self.spin)),
        }


SIDEREAL_DAY = 86164.0905  # s
DAY = 86400.0  # s


class EarthFreePrecession(AbstractScene):
    r"""The Earth as a rigid oblate body: its spin axis wobbles about the figure axis.

    The torque-free symmetric body of the course text §4.7 with Earth's numbers:
    $I_1 = I_2 = A$, $I_3 = C$, $(C - A)/A \approx 1/305$, spin $\omega_3 =
    2\pi/$sidereal day. If the rotation axis is off the figure axis by a small
    angle α, $\boldsymbol\omega$ circles the figure axis in the body frame at

    $$ \Omega = \frac{C - A}{A}\,\omega_3, \qquad
       T = \frac{2\pi}{\Omega} = \frac{A}{C - A}\ \text{sidereal days}
       \approx 305\ \text{days} $$

    (eq. 4.47 with $I_1 > I_3$ reversed: an oblate body precesses *with* the spin),
    keeping α constant. This is Euler's free nutation. The wobble the Earth shows —
    Chandler's, about 0.2″ wide — has a period of ≈ 433 days instead: the real Earth
    yields elastically and has oceans (Newcomb 1891), which a rigid body cannot
    show. The run measures the rigid body's 305 days.

    Moments are in units of A (the motion depends on ratios only); time is in
    seconds. `system()` is the Euler-angle Lagrangian, started with the figure axis
    horizontal (θ = π/2) so it is far from gimbal lock; `rigid_body()` with
    `initial_body_state()` is the same motion on quaternions.

    **Parameters:** `ellipticity` $(C - A)/A$ (1/305), `spin` ω (rad/s,
    2π/86164.09 s), `wobble` α, the angle between ω and the figure axis (rad,
    10⁻⁶ ≈ 0.2″, about 6 m at the pole).

    References: the course text §4.7 (eqs. 4.47–4.52); Goldstein, Poole & Safko,
    *Classical Mechanics*, 3rd ed., §5.6 (the Earth's free precession, ~10 months);
    Lambeck, *The Earth's Variable Rotation*, Cambridge (1980), ch. 3 (Chandler
    wobble); Newcomb, Mon. Not. R. Astron. Soc. 52, 336 (1892).
    """

    ellipticity: jax.Array = parameter(1 / 305)
    spin: jax.Array = parameter(2 * math.pi / SIDEREAL_DAY)
    wobble: jax.Array = parameter(1e-6, nonnegative=True, angle=True)

    default_t1: ClassVar[float] = 400 * DAY
    default_dt: ClassVar[float] = 1200.0
    state_kind: ClassVar[StateKind] = "velocity"
    coordinate_names: ClassVar[tuple[str, ...]] = ("φ", "θ", "ψ")
    coordinate_units: ClassVar[tuple[str, ...]] = ("rad", "rad", "rad")

    def body(self) -> TorqueFreeBody:
        """The same motion as a `TorqueFreeBody` (moments in units of A)."""
        omega = self.spin * jnp.stack(
            [jnp.sin(self.wobble), 0 * self.wobble, jnp.cos(self.wobble)]
        )
        return TorqueFreeBody(
            moments=jnp.stack([1 + 0 * self.ellipticity, 1 + 0 * self.ellipticity,
                               1 + self.ellipticity]),
            omega0=omega,
            angles0=jnp.stack([0 * self.spin, math.pi / 2 + 0 * self.spin, 0 * self.spin]),
        )  # fmt: skip

    def system(self) -> Lagrangian:
        return Lagrangian(_earth_lagrangian, quadratic_in_velocity=True)

    def initial_state(self) -> tuple[jax.Array, jax.Array]:
        return self.body().initial_state()

    def rigid_body(self) -> RigidBody:
        return RigidBody(self.body().moments)

    def initial_body_state(self) -> tuple[jax.Array, jax.Array]:
        return self.body().initial_body_state()

    def euler_period(self) -> jax.Array:
        """T = 2π/Ω, Ω = (C − A)/A · ω₃ (s)."""
        omega_3 = self.spin * jnp.cos(self.wobble)
        return 2 * math.pi / (self.ellipticity * omega_3)

    def checks(self, trajectory: Any) -> dict[str, tuple[jax.Array, jax.Array]]:
        """The wobble period (days) from ω₁'s sign changes in the body frame, the
        constant wobble angle and the space angular momentum."""
        moments = self.body().moments
        rotation, omega = _body_motion(trajectory, moments)
        # ω₁ starts at its maximum: it crosses zero at T/4 and 3T/4.
        omega_1_rate = (
            (moments[1] - moments[2]) * omega[:, 1] * omega[:, 2] / moments[0]
        )
        first, second = zero_crossing_times(trajectory.ts, omega[:, 0], omega_1_rate, 2)
        transverse = jnp.hypot(omega[:, 0], omega[:, 1])
        wobble = jnp.arctan2(transverse, omega[:, 2])
        space_momentum = jnp.einsum("tij,tj->ti", rotation, moments * omega)
        expected_momentum = self.body().angular_momentum_space()
        return {
            "wobble period (days)": (
                measured(
                    2 * (second - first) / DAY,
                    self,
                    "the wobble period",
                    "saves over at least 3/4 of the wobble period",
                ),
                self.euler_period() / DAY,
            ),
            "wobble angle": (wobble, jnp.full_like(wobble, self.wobble)),
            "angular momentum": (
                space_momentum,
                jnp.broadcast_to(expected_momentum, space_momentum.shape),
            ),
        }


def _earth_lagrangian(q, qdot, t, scene):
    return _free_body_lagrangian(q, qdot, t, scene.body())


SCENES = (TorqueFreeBody, HeavySymmetricTop, EarthFreePrecession)
