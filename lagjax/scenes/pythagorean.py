r"""The Pythagorean three-body problem: close encounters, then an escape.

Three point masses $m_1 = 3$, $m_2 = 4$, $m_3 = 5$ start at rest at the corners of
a right triangle with sides 3, 4, 5, each mass opposite the side of its own length
($G = 1$; Burrau 1913):

$$ \mathbf r_1 = (1, 3),\quad \mathbf r_2 = (-2, -1),\quad \mathbf r_3 = (1, -1),
   \qquad H = \sum_i \frac{|\mathbf p_i|^2}{2m_i}
   - \sum_{i<j} \frac{G m_i m_j}{|\mathbf r_i - \mathbf r_j|}. $$

The centre of mass is at the origin and stays there; the total momentum and the
angular momentum are zero and stay zero (pair forces, the course text §2.1), and the
energy is $E = -G(m_1m_2/5 + m_1m_3/4 + m_2m_3/3) = -769/60$ for the standard
masses. Szebehely & Peters (1967) integrated it to its end: after a sequence of
close two-body encounters (the closest, of bodies 2 and 3 near t ≈ 29.8, within
about 3e-3 of each other, with speeds up to about 40, against separations of order
1 at the start, at rest) the lightest body escapes and the other two
leave as an eccentric binary, recoiling the other way; from t ≈ 59.5 on, the
lightest body's energy relative to the binary,
$E_{\rm rel} = \tfrac12\mu|\dot{\mathbf r}|^2 - Gm_1(m_2 + m_3)/|\mathbf r|$ with
$\mathbf r$ from the binary's centre of mass to it and $\mu = m_1(m_2 + m_3)/M$,
stays positive (a hyperbolic escape), while the binary's own energy is negative
(figures from a `TimeTransformed(BlanesMoan4())` run at ds = 0.01, saved every
5e-4).

The run is chaotic: an error at round-off grows by orders of magnitude through each
encounter, so two methods agree on the state late in the run only when both follow
every encounter closely (issue 30 asks for the energy kept to 1e-12 to t = 70).

References: C. Burrau, Astron. Nachr. 195, 113 (1913); V. Szebehely & C. F.
Peters, *Complete solution of a general problem of three bodies*, Astron. J. 72,
876 (1967); S. J. Aarseth, *Gravitational N-Body Simulations*, CUP (2003), §5.
"""

from __future__ import annotations

from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from lagjax.mechanics.hamiltonian import SeparableHamiltonian
from lagjax.mechanics.particles import (
    pair_energy,
    total_angular_momentum,
    total_momentum,
)
from lagjax.scenes.base import AbstractScene, Diagnostic, StateKind, parameter

# Burrau's corners: each body opposite the side whose length is its mass.
PYTHAGOREAN_POSITIONS = np.array([[1.0, 3.0], [-2.0, -1.0], [1.0, -1.0]])


def _kinetic(p, t, scene):
    return 0.5 * jnp.sum(p**2 / scene.masses[:, None])


def _potential(q, t, scene):
    strengths = -scene.gravitational_constant * jnp.outer(scene.masses, scene.masses)
    return pair_energy(q, lambda r: 1 / r, strengths)


class PythagoreanThreeBody(AbstractScene):
    r"""Burrau's three bodies of masses 3, 4, 5 at rest on a 3-4-5 triangle (G = 1).

    $$ H = \sum_{i=1}^3 \frac{|\mathbf p_i|^2}{2m_i}
       - \sum_{i<j} \frac{G m_i m_j}{|\mathbf r_i - \mathbf r_j|}, $$

    q and p are (3, 2) arrays, one row per body. Close encounters, then the
    lightest body escapes and the other two leave as a binary (Szebehely & Peters
    1967; module docstring).

    **Parameters** (dimensionless, $G = 1$ units): `masses` $(m_1, m_2, m_3)$
    ((3, 4, 5)), `gravitational_constant` $G$ (1). Starts at rest at
    $(1, 3)$, $(-2, -1)$, $(1, -1)$ whatever the masses.

    Closed forms: the energy $-G\sum_{i<j} m_im_j/r_{ij}(0)$, zero total momentum
    and zero angular momentum, all conserved. Integrate it with
    `lj.TimeTransformed` (the logarithmic Hamiltonian steps in proportion to the
    closest separation): `TimeTransformed(Yoshida4())` at ds = 0.005 keeps the
    energy to ~2e-13 to t = 70 in about 390,000 steps;
    `TimeTransformed(GraggBulirschStoer(rtol=1e-13, atol=1e-13))`, the extrapolated
    leapfrog, to ~5e-13 in about 3,400 steps, about 5 times faster
    (`benchmarks/close_encounters.py`). `lj.ChainRegularization(
    GraggBulirschStoer(rtol=3e-14, atol=3e-14))` integrates the separations
    along a chain of the closest pairs instead of the positions: 3.1e-13, and
    as little with the whole configuration shifted by 100, where the positions'
    round-off costs the barycentric run 6.1e-11 (`benchmarks/pythagorean_chain.py`).
    """

    masses: jax.Array = parameter((3.0, 4.0, 5.0), positive=True)
    gravitational_constant: jax.Array = parameter(1.0, positive=True)

    default_t1: ClassVar[float] = 70.0
    default_dt: ClassVar[float] = 1e-4
    state_kind: ClassVar[StateKind] = "momentum"
    coordinate_names: ClassVar[tuple[str, ...]] = ("x₁", "y₁", "x₂", "y₂", "x₃", "y₃")
    coordinate_units: ClassVar[tuple[str, ...]] = ("",) * 6
    time_unit: ClassVar[str] = ""

    def system(self) -> SeparableHamiltonian:
        return SeparableHamiltonian(_kinetic, _potential)

    def initial_state(self) -> tuple[jax.Array, jax.Array]:
        positions = jnp.asarray(PYTHAGOREAN_POSITIONS, dtype=self.masses.dtype)
        return positions, jnp.zeros_like(positions)

    def energy(self) -> jax.Array:
        """$E = -G\\sum_{i<j} m_im_j/r_{ij}$ at the start (at rest): −769/60."""
        return _potential(self.initial_state()[0], 0.0, self)

    def relative_motion(
        self, q: jax.Array, p: jax.Array, body: int = 0
    ) -> tuple[jax.Array, jax.Array]:
        """(r, ṙ): `body` seen from the centre of mass of the other two.
        q, p: (..., 3, 2)."""
        pair = np.array([other for other in range(3) if other != body])
        weights = self.masses[pair][:, None]
        pair_mass = jnp.sum(weights)
        pair_position = jnp.sum(weights * q[..., pair, :], axis=-2) / pair_mass
        pair_velocity = jnp.sum(p[..., pair, :], axis=-2) / pair_mass
        return (
            q[..., body, :] - pair_position,
            p[..., body, :] / self.masses[body] - pair_velocity,
        )

    def escape_energy(self, q: jax.Array, p: jax.Array, body: int = 0) -> jax.Array:
        r"""$E_{\rm rel} = \tfrac12\mu|\dot{\mathbf r}|^2 - Gm_b(M - m_b)/|\mathbf r|$
        of `body` relative to the other two (module docstring): positive once it
        escapes."""
        separation, velocity = self.relative_motion(q, p, body)
        body_mass, total = self.masses[body], jnp.sum(self.masses)
        reduced_mass = body_mass * (total - body_mass) / total
        pull = self.gravitational_constant * body_mass * (total - body_mass)
        kinetic = 0.5 * reduced_mass * jnp.sum(velocity**2, axis=-1)
        return kinetic - pull / jnp.linalg.norm(separation, axis=-1)

    def checks(self, trajectory) -> dict[str, tuple[jax.Array, jax.Array]]:
        """Energy, total momentum and angular momentum against their start values."""
        q, p = trajectory.q, trajectory.p
        angular = total_angular_momentum(q, p)
        momentum = total_momentum(p)
        return {
            "energy": (trajectory.energy(), self.energy() * jnp.ones_like(angular)),
            "total momentum": (momentum, jnp.zeros_like(momentum)),
            "angular momentum": (angular, jnp.zeros_like(angular)),
        }

    def diagnostic(self, trajectory) -> Diagnostic:
        """The lightest body's distance from the other two's centre of mass."""
        lightest = int(np.argmin(np.asarray(self.masses)))
        return Diagnostic(
            "distance of the lightest body from the binary",
            trajectory.ts,
            jnp.linalg.norm(
                self.relative_motion(trajectory.q, trajectory.p, lightest)[0], axis=-1
            ),
        )
