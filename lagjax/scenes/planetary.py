r"""Planetary systems: N bodies under Newtonian gravity, one of them dominant.

$$H = \sum_i \frac{|\mathbf p_i|^2}{2m_i} - \sum_{i<j}\frac{G m_i m_j}{|\mathbf q_i - \mathbf q_j|}$$

in inertial Cartesian coordinates. The total momentum $\mathbf P = \sum_i
\mathbf p_i$ and angular momentum $\mathbf L = \sum_i \mathbf q_i\times\mathbf p_i$
are conserved exactly (translation and rotation invariance), and so is $H$; the
centre of mass moves uniformly. With body 0 much heavier than the rest the
planets follow nearly Keplerian orbits about it, the regime of the Wisdom–Holman
splitting (`lagjax.solvers.wisdom_holman`).

The default is Hairer, Lubich & Wanner's *outer solar system* (HLW §I.2.4): the Sun
with the inner planets' masses added, Jupiter, Saturn, Uranus, Neptune and Pluto
on September 5, 1994, in astronomical units, solar masses and Earth days
($G = 2.95912208286\cdot10^{-4}\,\mathrm{AU^3\,M_\odot^{-1}\,d^{-2}}$), the Sun at
the origin at rest. Any consistent units may be used: $G$ fixes them.

References: Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed.,
Springer (2006), §I.2.4 (the outer solar system, its data) and §I.2.3 (the N-body
problem); Goldstein, Poole & Safko, *Classical Mechanics*, 3rd ed., §1.2
(conservation of total momentum and angular momentum).
"""

from __future__ import annotations

from typing import Any, ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from lagjax._core.gravitation import Gravitation
from lagjax.mechanics.hamiltonian import SeparableHamiltonian
from lagjax.scenes.base import AbstractScene, StateKind, concrete, parameter

# HLW Table I.2.1: the Sun (+ inner planets), Jupiter, Saturn, Uranus, Neptune, Pluto.
OUTER_SOLAR_SYSTEM_MASSES = (
    1.00000597682,
    0.000954786104043,
    0.000285583733151,
    0.0000437273164546,
    0.0000517759138449,
    1 / 1.3e8,
)
OUTER_SOLAR_SYSTEM_POSITIONS = (
    (0.0, 0.0, 0.0),
    (-3.5023653, -3.8169847, -1.5507963),
    (9.0755314, -3.0458353, -1.6483708),
    (8.3101420, -16.2901086, -7.2521278),
    (11.4707666, -25.7294829, -10.8169456),
    (-15.5387357, -25.2225594, -3.1902382),
)
OUTER_SOLAR_SYSTEM_VELOCITIES = (
    (0.0, 0.0, 0.0),
    (0.00565429, -0.00412490, -0.00190589),
    (0.00168318, 0.00483525, 0.00192462),
    (0.00354178, 0.00137102, 0.00055029),
    (0.00288930, 0.00114527, 0.00039677),
    (0.00276725, -0.00170702, -0.00136504),
)
GAUSS_G = 2.95912208286e-4  # AU³ / (M☉ day²), HLW §I.2.4


def _kinetic(p, t, scene):
    return 0.5 * jnp.sum(jnp.sum(p**2, axis=-1) / scene.masses)


def _potential(q, t, scene):
    size = q.shape[-2]
    pairs = np.triu(np.ones((size, size), bool), 1)
    squared = jnp.sum((q[:, None, :] - q[None, :, :]) ** 2, axis=-1)
    squared = jnp.where(pairs, squared, 1)  # no 1/0 on the diagonal
    products = scene.masses[:, None] * scene.masses[None, :]
    pair_sum = jnp.sum(jnp.where(pairs, products / jnp.sqrt(squared), 0))
    return -scene.gravitational_constant * pair_sum


class PlanetarySystem(AbstractScene):
    r"""N point masses under Newtonian gravity; default HLW's outer solar system.

    $$H = \sum_i \frac{|\mathbf p_i|^2}{2m_i}
        - \sum_{i<j}\frac{G m_i m_j}{|\mathbf q_i - \mathbf q_j|}.$$

    **Parameters:** `masses` (N,), all > 0, body 0 the dominant one for
    `lj.WisdomHolman`; `positions`, `velocities` (N, 3), the start;
    `gravitational_constant` $G$ > 0, which fixes the units (default: AU, solar
    masses, days). The state is (q, p), inertial positions and momenta, each
    (N, 3).

    Closed forms: the total momentum, angular momentum and energy stay at their
    start values (`checks`).
    """

    masses: jax.Array = parameter(OUTER_SOLAR_SYSTEM_MASSES, positive=True)
    positions: jax.Array = parameter(OUTER_SOLAR_SYSTEM_POSITIONS)
    velocities: jax.Array = parameter(OUTER_SOLAR_SYSTEM_VELOCITIES)
    gravitational_constant: jax.Array = parameter(GAUSS_G, positive=True)

    default_t1: ClassVar[float] = 2.0e5  # days: HLW's Figure I.2.4 span
    default_dt: ClassVar[float] = 10.0
    state_kind: ClassVar[StateKind] = "momentum"
    time_unit: ClassVar[str] = ""  # G's units (days for the default)

    def __check_init__(self) -> None:
        super().__check_init__()
        shapes = (self.masses.shape, self.positions.shape, self.velocities.shape)
        size = shapes[0][0] if len(shapes[0]) == 1 else -1
        if size < 2 or shapes[1] != shapes[2] or shapes[1][:1] != (size,):
            raise ValueError(
                f"PlanetarySystem: masses {shapes[0]}, positions {shapes[1]} and "
                f"velocities {shapes[2]} must be (N,), (N, d), (N, d) with N ≥ 2 "
                "bodies (one row of positions and of velocities per mass)"
            )
        values = concrete(self.positions)
        if values is not None and len(np.unique(values[0], axis=0)) < size:
            raise ValueError(
                "PlanetarySystem: two bodies start at the same position (their "
                "potential energy is infinite); give every body its own position"
            )

    def system(self) -> SeparableHamiltonian:
        return SeparableHamiltonian(_kinetic, _potential, quadratic_in_momentum=True)

    def gravitation(self, args: Any) -> Gravitation:
        """N bodies; τ = √(a³/G(m₀ + mᵢ)) of the innermost two-body orbit about
        body 0 (vis-viva: 1/a = 2/r − v²/G(m₀ + mᵢ))."""
        scene = self if args is None else args
        pull = scene.gravitational_constant * (scene.masses[0] + scene.masses[1:])
        distance = jnp.linalg.norm(scene.positions[1:] - scene.positions[0], axis=-1)
        speed = scene.velocities[1:] - scene.velocities[0]
        axis = 1 / (2 / distance - jnp.sum(speed**2, axis=-1) / pull)
        return Gravitation(scene.masses.shape[-1], jnp.min(jnp.sqrt(axis**3 / pull)))

    def initial_state(self) -> tuple[jax.Array, jax.Array]:
        return self.positions, self.masses[:, None] * self.velocities

    def coordinates(self) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """x₀ y₀ z₀ x₁ …, body 0 the dominant one; units those of G ("")."""
        size, dimension = self.positions.shape
        axes = "xyz" if dimension == 3 else "xy" if dimension == 2 else "x"
        subscripts = str.maketrans("0123456789", "₀₁₂₃₄₅₆₇₈₉")
        names = tuple(
            f"{axis}{str(body).translate(subscripts)}"
            for body in range(size)
            for axis in axes
        )
        return names, ("",) * len(names)

    def total_momentum(self, q: Any, p: Any) -> jax.Array:
        """P = Σ p_i (any leading axes)."""
        del q
        return jnp.sum(p, axis=-2)

    def angular_momentum(self, q: Any, p: Any) -> jax.Array:
        """L = Σ q_i × p_i (three dimensions; any leading axes)."""
        return jnp.sum(jnp.cross(q, p), axis=-2)

    def checks(self, trajectory: Any) -> dict[str, tuple[jax.Array, jax.Array]]:
        """Total momentum, angular momentum and energy at every saved time against
        their start values (a run from `initial_state()`)."""
        q0, p0 = self.initial_state()
        q, p = trajectory.q, trajectory.p
        start_energy = self.system()(q0, p0, 0.0, self)
        ones = jnp.ones(q.shape[:-2])
        return {
            "total momentum": (
                self.total_momentum(q, p),
                self.total_momentum(q0, p0) * ones[..., None],
            ),
            "angular momentum": (
                self.angular_momentum(q, p),
                self.angular_momentum(q0, p0) * ones[..., None],
            ),
            "energy": (trajectory.energy(), start_energy * ones),
        }


SCENES = (PlanetarySystem,)
