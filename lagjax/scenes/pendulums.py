r"""Pendulums: the simple pendulum at any amplitude, and the double pendulum.

The pendulum is the first oscillator whose frequency depends on its amplitude. The
simple pendulum's period is a complete elliptic integral, evaluated here by the
arithmetic–geometric mean (no special-function library needed, differentiable, and
accurate right up to the separatrix $\theta_0 \to \pi$, where the period diverges
logarithmically). The double pendulum has two normal modes at small amplitude (the
course text's secular equation, §5) and is chaotic at large amplitude, where only its
energy is conserved.

Every `checks(trajectory)` assumes a run from `initial_state()` at $t = 0$.

References: Landau & Lifshitz, *Mechanics*, §11 (problem 1) and §23; Abramowitz &
Stegun, *Handbook of Mathematical Functions*, 17.3 and 17.6 (K by the AGM); the
course text §5; Goldstein, Poole & Safko, *Classical Mechanics*, 3rd ed., §6.2–6.4.
"""

from __future__ import annotations

import math
from typing import ClassVar

import jax
import jax.numpy as jnp

from lagjax.mechanics.hamiltonian import SeparableHamiltonian
from lagjax.mechanics.lagrangian import Lagrangian
from lagjax.sampled_signals import zero_crossing_times
from lagjax.scenes.base import BELOW_THE_TOP, AbstractScene, StateKind, parameter
from lagjax.scenes.judging import measured
from lagjax.special_functions import complete_elliptic_k_from_complement

_DEFAULT_AMPLITUDE = math.radians(150)


# --- Simple pendulum at large amplitude -------------------------------------------


def _pendulum_kinetic(p, t, scene):
    return 0.5 * p**2 / (scene.mass * scene.length**2)


def _pendulum_potential(q, t, scene):
    return -scene.mass * scene.gravity * scene.length * jnp.cos(q)


class SimplePendulum(AbstractScene):
    r"""A point mass on a rigid massless rod, swinging at any amplitude below π.

    $H = \dfrac{p^2}{2ml^2} - mgl\cos\theta$, θ from the downward vertical.
    Released from rest at $\theta_0$, it swings with period

    $$ T = \frac{4K(\sin(\theta_0/2))}{\omega_0},\qquad \omega_0 = \sqrt{g/l}, $$

    $K$ the complete elliptic integral of the first kind, computed as
    $\pi/(2\,\mathrm{AGM}(1, \cos(\theta_0/2)))$ — the complementary modulus
    $\cos(\theta_0/2)$ taken directly keeps all digits as $\theta_0 \to \pi$, where
    $T$ grows like $(4/\omega_0)\ln(8/(\pi - \theta_0))$.

    **Parameters:** `mass` (kg, 1), `length` (m, 1), `gravity` g (m/s², 9.81),
    `amplitude` θ₀ (rad, 150°).

    References: Landau & Lifshitz, *Mechanics*, §11, problem 1; Abramowitz & Stegun
    17.3 and 17.6.
    """

    mass: jax.Array = parameter(1.0, positive=True)
    length: jax.Array = parameter(1.0, positive=True)
    gravity: jax.Array = parameter(9.81, positive=True)
    amplitude: jax.Array = parameter(
        _DEFAULT_AMPLITUDE, within=BELOW_THE_TOP, angle=True
    )

    default_t1: ClassVar[float] = 5.0
    default_dt: ClassVar[float] = 0.01
    state_kind: ClassVar[StateKind] = "momentum"
    coordinate_names: ClassVar[tuple[str, ...]] = ("θ",)
    coordinate_units: ClassVar[tuple[str, ...]] = ("rad",)

    def system(self) -> SeparableHamiltonian:
        return SeparableHamiltonian(_pendulum_kinetic, _pendulum_potential)

    def initial_state(self) -> tuple[jax.Array, jax.Array]:
        return self.amplitude, jnp.zeros_like(self.amplitude)

    def small_amplitude_frequency(self) -> jax.Array:
        """ω₀ = √(g/l)."""
        return jnp.sqrt(self.gravity / self.length)

    def period(self) -> jax.Array:
        """T = 4K(sin(θ₀/2))/ω₀ (s)."""
        quarter = complete_elliptic_k_from_complement(jnp.cos(self.amplitude / 2) ** 2)
        return 4 * quarter / self.small_amplitude_frequency()

    def measured_period(self, trajectory) -> jax.Array:
        """2 × the time between the first two passages through θ = 0.

        Needs samples over at least 3/4 of a period (NaN otherwise), spaced finely
        enough for cubic interpolation: 0.03/ω₀ apart gave ~1e-12 relative.
        """
        first, second = zero_crossing_times(
            trajectory.ts, trajectory.q, trajectory.qdot, 2
        )
        return 2 * (second - first)

    def checks(self, trajectory) -> dict[str, tuple[jax.Array, jax.Array]]:
        """The period measured from θ's zero crossings; energy conservation."""
        start_energy = self.system()(*self.initial_state(), 0.0, self)
        energy = trajectory.energy()
        return {
            "period": (
                measured(
                    self.measured_period(trajectory),
                    self,
                    "the period",
                    "saves over at least 3/4 of a period",
                ),
                self.period(),
            ),
            "energy": (energy, start_energy * jnp.ones_like(energy)),
        }


# --- Double pendulum --------------------------------------------------------------


def _double_pendulum_lagrangian(q, qdot, t, scene):
    (m1, m2), (l1, l2), g = scene.masses, scene.lengths, scene.gravity
    total = m1 + m2
    kinetic = (
        0.5 * total * l1**2 * qdot[0] ** 2
        + 0.5 * m2 * l2**2 * qdot[1] ** 2
        + m2 * l1 * l2 * qdot[0] * qdot[1] * jnp.cos(q[0] - q[1])
    )
    potential = -total * g * l1 * jnp.cos(q[0]) - m2 * g * l2 * jnp.cos(q[1])
    return kinetic - potential


class DoublePendulum(AbstractScene):
    r"""Two pendulums, one hung from the other: normal modes if small, chaos if large.

    Angles θ₁, θ₂ from the downward vertical, point masses on massless rods:

    $$ L = \tfrac12(m_1 + m_2)l_1^2\dot\theta_1^2 + \tfrac12 m_2 l_2^2\dot\theta_2^2
       + m_2 l_1 l_2\dot\theta_1\dot\theta_2\cos(\theta_1 - \theta_2)
       + (m_1 + m_2)g l_1\cos\theta_1 + m_2 g l_2\cos\theta_2. $$

    Small oscillations: with $M = m_1 + m_2$, the secular equation
    $m_1 l_1 l_2\,\omega^4 - M g(l_1 + l_2)\,\omega^2 + M g^2 = 0$, which for equal
    masses and lengths gives $\omega^2 = (2 \mp \sqrt2)\,g/l$ with shapes
    $\theta_2/\theta_1 = \pm\sqrt2$. At large amplitude the motion is chaotic and only
    the energy is conserved.

    **Parameters:** `masses` (m₁, m₂) (kg, (1, 1)), `lengths` (l₁, l₂) (m, (1, 1)),
    `gravity` (m/s², 9.81). Starts at rest at θ = (2, 2.5) rad (chaotic).

    References: the course text §5 (secular equation, eq. 5.21); Goldstein, Poole &
    Safko §6.2–6.3; Landau & Lifshitz, *Mechanics*, §23.
    """

    masses: jax.Array = parameter((1.0, 1.0), positive=True)
    lengths: jax.Array = parameter((1.0, 1.0), positive=True)
    gravity: jax.Array = parameter(9.81, positive=True)

    default_t1: ClassVar[float] = 10.0
    default_dt: ClassVar[float] = 0.0025
    state_kind: ClassVar[StateKind] = "velocity"
    coordinate_names: ClassVar[tuple[str, ...]] = ("θ₁", "θ₂")
    coordinate_units: ClassVar[tuple[str, ...]] = ("rad", "rad")

    def system(self) -> Lagrangian:
        return Lagrangian(_double_pendulum_lagrangian, quadratic_in_velocity=True)

    def initial_state(self) -> tuple[jax.Array, jax.Array]:
        return jnp.array([2.0, 2.5]), jnp.zeros(2)

    def normal_mode_frequencies(self) -> jax.Array:
        """The two small-oscillation frequencies ω₋ < ω₊ (rad/s)."""
        (m1, m2), (l1, l2), g = self.masses, self.lengths, self.gravity
        total = m1 + m2
        linear = total * g * (l1 + l2)
        root = jnp.sqrt(linear**2 - 4 * m1 * l1 * l2 * total * g**2)
        fast = (linear + root) / (2 * m1 * l1 * l2)
        # The product of the roots is M g²/(m₁ l₁ l₂): no cancellation for the slow one.
        slow = total * g**2 / (m1 * l1 * l2) / fast
        return jnp.sqrt(jnp.stack([slow, fast]))

    def normal_mode_shapes(self) -> jax.Array:
        """Mode k in column k, θ₂/θ₁ = M(g − ω²l₁)/(m₂ l₂ ω²), normalised Aᵀ T A = 1."""
        (m1, m2), (l1, l2), g = self.masses, self.lengths, self.gravity
        squared = self.normal_mode_frequencies() ** 2
        ratio = (m1 + m2) * (g - squared * l1) / (m2 * l2 * squared)
        shapes = jnp.stack([jnp.ones_like(ratio), ratio])
        kinetic = jnp.array(
            [[(m1 + m2) * l1**2, m2 * l1 * l2], [m2 * l1 * l2, m2 * l2**2]]
        )
        norms = jnp.sqrt(jnp.einsum("ik,ij,jk->k", shapes, kinetic, shapes))
        return shapes / norms

    def checks(self, trajectory) -> dict[str, tuple[jax.Array, jax.Array]]:
        """Energy conservation, the one invariant left when the motion is chaotic."""
        start_energy = self.system().energy(*self.initial_state(), 0.0, self)
        energy = trajectory.energy()
        return {"energy": (energy, start_energy * jnp.ones_like(energy))}


SCENES = (SimplePendulum, DoublePendulum)
