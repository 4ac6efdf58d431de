r"""Central forces: the Kepler (attractive inverse-square, or Coulomb) problem.

A particle of mass $m$ in the potential $V(r) = -m\mu/r$ moves in a plane on a
conic section. For negative energy the orbit is an ellipse of semi-major axis $a$ and
eccentricity $e$, traced in the period $T = 2\pi\sqrt{a^3/\mu}$; the energy
$E = -m\mu/2a$, the angular momentum $\ell = m\sqrt{\mu a(1 - e^2)}$ and the
Laplace–Runge–Lenz vector $\mathbf A = \mathbf p\times\boldsymbol\ell - m^2\mu\,\hat{\mathbf r}$
(length $m^2\mu e$, pointing at periapsis) are conserved, and the position at time
$t$ follows from Kepler's equation $\mathcal E - e\sin\mathcal E = 2\pi t/T$.

The same physics is given twice — in Cartesian coordinates as a separable Hamiltonian
(so the explicit splitting solvers apply) and in polar coordinates as a Lagrangian
whose angle is cyclic (the course text §6.2: $p_\theta = mr^2\dot\theta$ is
constant) — so that the two derivations can be checked against each other and
against the closed forms. Both start at periapsis on the $+x$ axis, moving
counter-clockwise.

References: Goldstein, Poole & Safko, *Classical Mechanics*, 3rd ed., §3.7 (the
Kepler orbit), §3.8 (Kepler's equation, motion in time) and §3.9 (the
Laplace–Runge–Lenz vector); the course text §6.2 and §6.5 (cyclic θ, conserved
angular momentum in a central field).
"""

from __future__ import annotations

import abc
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp

from lagjax._core.gravitation import Gravitation
from lagjax.mechanics.hamiltonian import SeparableHamiltonian
from lagjax.mechanics.lagrangian import Lagrangian
from lagjax.scenes.base import (
    AbstractScene,
    Diagnostic,
    Interval,
    StateKind,
    parameter,
)

# Newton's method on Kepler's equation started at 𝓔 = π converges monotonically for
# mean anomalies in [0, π] (the equation is increasing and convex there); 50
# iterations reach round-off even for e = 0.99 near periapsis, where it is slowest.
_KEPLER_NEWTON_ITERATIONS = 50


def eccentric_anomaly(mean_anomaly: jax.Array, eccentricity: jax.Array) -> jax.Array:
    r"""Solve Kepler's equation $\mathcal E - e\sin\mathcal E = M$ for $\mathcal E$.

    Any real $M$; the result lies in $[0, 2\pi)$. Uses the symmetry
    $\mathcal E(2\pi - M) = 2\pi - \mathcal E(M)$ to solve on $[0, \pi]$ only.
    """
    reduced = jnp.mod(mean_anomaly, 2 * jnp.pi)
    upper_half = reduced > jnp.pi
    half_turn = jnp.where(upper_half, 2 * jnp.pi - reduced, reduced)

    def newton_step(_, anomaly):
        residual = anomaly - eccentricity * jnp.sin(anomaly) - half_turn
        return anomaly - residual / (1 - eccentricity * jnp.cos(anomaly))

    start = jnp.full_like(half_turn, jnp.pi)
    anomaly = jax.lax.fori_loop(0, _KEPLER_NEWTON_ITERATIONS, newton_step, start)
    # The root for M in [0, π] lies in [0, π]; Newton's last step can overshoot
    # M = 0 by round-off (−1e-306 was seen), which would leave [0, 2π).
    anomaly = jnp.clip(anomaly, 0.0, jnp.pi)
    return jnp.where(upper_half, 2 * jnp.pi - anomaly, anomaly)


BOUND_ORBIT = Interval(0.0, 1.0, include_high=False)  # 0 ≤ e < 1: an ellipse


class AbstractKeplerProblem(AbstractScene):
    r"""Orbit elements, closed forms and checks shared by the two coordinate forms.

    Natural units by default: $\mu = a = m = 1$, so $T = 2\pi$ and $E = -\tfrac12$.
    Subclasses say how their coordinates map to the Cartesian plane.
    """

    eccentricity: eqx.AbstractVar[jax.Array]
    semi_major_axis: eqx.AbstractVar[jax.Array]
    gravitational_parameter: eqx.AbstractVar[jax.Array]
    mass: eqx.AbstractVar[jax.Array]

    default_t1: ClassVar[float] = 2 * jnp.pi
    default_dt: ClassVar[float] = 2 * jnp.pi / 2000

    @abc.abstractmethod
    def cartesian_state(self, q, qdot) -> tuple[jax.Array, jax.Array]:
        """(position, velocity), each of shape (..., 2), from coordinates q, q̇."""

    def period(self) -> jax.Array:
        """T = 2π √(a³/μ) (Kepler's third law)."""
        return (
            2
            * jnp.pi
            * jnp.sqrt(self.semi_major_axis**3 / self.gravitational_parameter)
        )

    def energy(self) -> jax.Array:
        """E = −mμ/2a, fixed by the semi-major axis alone."""
        return -self.mass * self.gravitational_parameter / (2 * self.semi_major_axis)

    def angular_momentum(self) -> jax.Array:
        """ℓ_z = m √(μ a (1 − e²)) (counter-clockwise orbit)."""
        latus = self.semi_major_axis * (1 - self.eccentricity**2)
        return self.mass * jnp.sqrt(self.gravitational_parameter * latus)

    def laplace_runge_lenz(self) -> jax.Array:
        """A = (m²μe, 0): towards periapsis, which lies on the +x axis."""
        length = self.mass**2 * self.gravitational_parameter * self.eccentricity
        return jnp.stack([length, jnp.zeros_like(length)])

    def periapsis_distance(self) -> jax.Array:
        """r_p = a (1 − e)."""
        return self.semi_major_axis * (1 - self.eccentricity)

    def periapsis_speed(self) -> jax.Array:
        """v_p = √(μ (1 + e) / (a (1 − e))) (vis-viva at r_p)."""
        return jnp.sqrt(
            self.gravitational_parameter
            * (1 + self.eccentricity)
            / self.periapsis_distance()
        )

    def orbit_state(self, t: jax.Array) -> tuple[jax.Array, jax.Array]:
        r"""Exact Cartesian (position, velocity) at times `t` (shape (..., 2)).

        From the eccentric anomaly $\mathcal E(t)$:
        $x = a(\cos\mathcal E - e)$, $y = b\sin\mathcal E$, $b = a\sqrt{1-e^2}$,
        and $\dot{\mathcal E} = n/(1 - e\cos\mathcal E)$ with $n = 2\pi/T$.
        """
        a, e = self.semi_major_axis, self.eccentricity
        mean_motion = 2 * jnp.pi / self.period()
        anomaly = eccentric_anomaly(mean_motion * jnp.asarray(t), e)
        minor = a * jnp.sqrt(1 - e**2)
        anomaly_rate = mean_motion / (1 - e * jnp.cos(anomaly))
        position = jnp.stack([a * (jnp.cos(anomaly) - e), minor * jnp.sin(anomaly)], -1)
        velocity = (
            jnp.stack([-a * jnp.sin(anomaly), minor * jnp.cos(anomaly)], -1)
            * anomaly_rate[..., None]
        )
        return position, velocity

    def checks(self, trajectory) -> dict[str, tuple[jax.Array, jax.Array]]:
        """Position against Kepler's equation, and the three conserved quantities.

        Every saved time is compared; the run must start from `initial_state()` at
        t = 0. Energy comes from lagjax (H, or the Jacobi integral of L); angular
        momentum and the Laplace–Runge–Lenz vector from the Cartesian state.
        """
        position, velocity = self.cartesian_state(trajectory.q, trajectory.qdot)
        expected_position, _ = self.orbit_state(trajectory.ts)
        momentum = self.mass * velocity
        angular = (
            position[..., 0] * momentum[..., 1] - position[..., 1] * momentum[..., 0]
        )
        radius = jnp.linalg.norm(position, axis=-1, keepdims=True)
        p_cross_l = (
            jnp.stack([momentum[..., 1], -momentum[..., 0]], -1) * angular[..., None]
        )
        pull = self.mass**2 * self.gravitational_parameter
        lenz = p_cross_l - pull * position / radius
        ones = jnp.ones_like(angular)
        return {
            "position": (position, expected_position),
            "energy": (trajectory.energy(), self.energy() * ones),
            "angular momentum": (angular, self.angular_momentum() * ones),
            "Laplace-Runge-Lenz vector": (
                lenz,
                self.laplace_runge_lenz() * ones[..., None],
            ),
        }

    def diagnostic(self, trajectory) -> Diagnostic:
        """The distance from the centre along the run against Kepler's equation."""
        position, _ = self.cartesian_state(trajectory.q, trajectory.qdot)
        expected, _ = self.orbit_state(trajectory.ts)
        return Diagnostic(
            "distance from the centre r [m]",
            trajectory.ts,
            jnp.linalg.norm(position, axis=-1),
            jnp.linalg.norm(expected, axis=-1),
            "a(1 − e cos E), E from Kepler's equation",
        )


def _cartesian_kinetic(p, t, scene):
    return 0.5 * jnp.sum(p**2) / scene.mass


def _cartesian_potential(q, t, scene):
    return -scene.mass * scene.gravitational_parameter / jnp.sqrt(jnp.sum(q**2))


class KeplerCartesian(AbstractKeplerProblem):
    r"""Kepler problem in Cartesian coordinates (x, y), as a separable Hamiltonian.

    $$ H = \frac{p_x^2 + p_y^2}{2m} - \frac{m\mu}{\sqrt{x^2 + y^2}}. $$

    **Parameters** (natural units): `eccentricity` $0 \le e < 1$ (default 0.6),
    `semi_major_axis` $a$ (1), `gravitational_parameter` $\mu = GM$, or $k/m$ for an
    attractive Coulomb force $-k/r^2$ (1), `mass` $m$ (1). Starts at periapsis
    $(a(1-e), 0)$ with momentum $(0, m v_p)$.

    Closed forms: see the module docstring (Goldstein §3.7–3.9).
    """

    eccentricity: jax.Array = parameter(0.6, within=BOUND_ORBIT)
    semi_major_axis: jax.Array = parameter(1.0, positive=True)
    gravitational_parameter: jax.Array = parameter(1.0, positive=True)
    mass: jax.Array = parameter(1.0, positive=True)

    state_kind: ClassVar[StateKind] = "momentum"
    coordinate_names: ClassVar[tuple[str, ...]] = ("x", "y")
    coordinate_units: ClassVar[tuple[str, ...]] = ("m", "m")

    def system(self) -> SeparableHamiltonian:
        return SeparableHamiltonian(_cartesian_kinetic, _cartesian_potential)

    def gravitation(self, args: Any) -> Gravitation:
        """Two bodies (the centre and the particle); τ = √(a³/μ)."""
        scene = self if args is None else args
        axis, pull = scene.semi_major_axis, scene.gravitational_parameter
        return Gravitation(bodies=2, dynamical_time=jnp.sqrt(axis**3 / pull))

    def initial_state(self) -> tuple[jax.Array, jax.Array]:
        zero = jnp.zeros_like(self.eccentricity)
        position = jnp.stack([self.periapsis_distance(), zero])
        momentum = jnp.stack([zero, self.mass * self.periapsis_speed()])
        return position, momentum

    def cartesian_state(self, q, qdot) -> tuple[jax.Array, jax.Array]:
        return q, qdot


def _polar_lagrangian(q, qdot, t, scene):
    radius, radial_speed, angular_speed = q[0], qdot[0], qdot[1]
    kinetic = 0.5 * scene.mass * (radial_speed**2 + (radius * angular_speed) ** 2)
    return kinetic + scene.mass * scene.gravitational_parameter / radius


class KeplerPolar(AbstractKeplerProblem):
    r"""Kepler problem in polar coordinates (r, θ), as a Lagrangian.

    $$ L = \tfrac12 m(\dot r^2 + r^2\dot\theta^2) + \frac{m\mu}{r}. $$

    θ is cyclic, so $p_\theta = m r^2\dot\theta = \ell$ is conserved (the course text
    §6.2). Parameters and closed forms as `KeplerCartesian`; starts at
    $(r, \theta) = (a(1-e), 0)$ with $(\dot r, \dot\theta) = (0, v_p/r_p)$. θ is not
    wrapped: it grows by 2π per orbit.
    """

    eccentricity: jax.Array = parameter(0.6, within=BOUND_ORBIT)
    semi_major_axis: jax.Array = parameter(1.0, positive=True)
    gravitational_parameter: jax.Array = parameter(1.0, positive=True)
    mass: jax.Array = parameter(1.0, positive=True)

    state_kind: ClassVar[StateKind] = "velocity"
    coordinate_names: ClassVar[tuple[str, ...]] = ("r", "θ")
    coordinate_units: ClassVar[tuple[str, ...]] = ("m", "rad")

    def system(self) -> Lagrangian:
        return Lagrangian(_polar_lagrangian, quadratic_in_velocity=True)

    def initial_state(self) -> tuple[jax.Array, jax.Array]:
        periapsis = self.periapsis_distance()
        zero = jnp.zeros_like(periapsis)
        return (
            jnp.stack([periapsis, zero]),
            jnp.stack([zero, self.periapsis_speed() / periapsis]),
        )

    def cartesian_state(self, q, qdot) -> tuple[jax.Array, jax.Array]:
        radius, angle = q[..., 0], q[..., 1]
        radial, tangential = qdot[..., 0], radius * qdot[..., 1]
        cos, sin = jnp.cos(angle), jnp.sin(angle)
        position = jnp.stack([radius * cos, radius * sin], -1)
        velocity = jnp.stack(
            [radial * cos - tangential * sin, radial * sin + tangential * cos], -1
        )
        return position, velocity


SCENES = (KeplerCartesian, KeplerPolar)
