r"""Chains of masses and springs: normal modes, and what nonlinearity does to them.

A chain of masses joined by linear springs is the course text's model of a molecule
and of a crystal (§5): its normal modes are known in closed form, and a motion
started in one of them stays in it for ever. The linear triatomic molecule (CO₂,
§5.3) has a zero-frequency translation and two stretching modes; the uniform chain
with fixed ends has sine-shaped modes. The Fermi–Pasta–Ulam chain of Hairer, Lubich
and Wanner alternates stiff linear springs with soft nonlinear ones: the stiff
springs trade energy among themselves, but their total oscillatory energy is an
adiabatic invariant, nearly conserved over very long times, and a symplectic
splitting method at step sizes $h\omega \approx 1$ keeps it so.

Every `checks(trajectory)` assumes a run from `initial_state()` at $t = 0$.

References: the course text §5.3 (CO₂, eq. 5.34–5.51); Goldstein, Poole & Safko,
*Classical Mechanics*, 3rd ed., §6.4 (CO₂); A. P. French, *Vibrations and Waves*,
ch. 5 (N coupled oscillators, the beaded string); Hairer, Lubich & Wanner,
*Geometric Numerical Integration*, 2nd ed., Springer 2006, §I.5 and Chapter XIII
(the Fermi–Pasta–Ulam problem).
"""

from __future__ import annotations

from typing import ClassVar

import jax
import jax.numpy as jnp

from lagjax.mechanics.hamiltonian import SeparableHamiltonian
from lagjax.scenes.base import AbstractScene, StateKind, count, numbered, parameter
from lagjax.scenes.oscillators import normal_mode_motion

ATOMIC_MASS_UNIT = 1.66053906660e-27  # kg, CODATA 2018


def _kinetic(p, t, scene):
    return 0.5 * jnp.sum(p**2 / scene.masses())


def _mode_leakage(normal_coordinates: jax.Array, excited: int) -> jax.Array:
    """max_t |ξ_j(t)|, j ≠ excited, relative to max_t |ξ_excited(t)|."""
    size = jnp.max(jnp.abs(normal_coordinates), axis=0)
    return jnp.max(size.at[excited].set(0.0)) / size[excited]


# --- Linear triatomic molecule (CO₂) ----------------------------------------------


def _triatomic_potential(q, t, scene):
    return 0.5 * scene.spring_constant * ((q[1] - q[0]) ** 2 + (q[2] - q[1]) ** 2)


class LinearTriatomicMolecule(AbstractScene):
    r"""CO₂ along its axis: masses m, M, m joined by two springs k (course text §5.3).

    $$ H = \frac{p_1^2 + p_3^2}{2m} + \frac{p_2^2}{2M}
       + \frac k2\left[(\eta_2 - \eta_1)^2 + (\eta_3 - \eta_2)^2\right], $$

    η the displacements from equilibrium (eq. 5.34–5.39). The secular equation
    $\omega^2(k - \omega^2 m)[k(M + 2m) - \omega^2 mM] = 0$ (eq. 5.41) gives
    $\omega_1 = 0$ (translation, $a_{i1} = 1/\sqrt{2m + M}$),
    $\omega_2 = \sqrt{k/m}$ (symmetric stretch, carbon at rest,
    $a_{12} = -a_{32} = 1/\sqrt{2m}$) and
    $\omega_3 = \sqrt{(k/m)(1 + 2m/M)}$ (asymmetric stretch,
    $a_{13} = a_{33} = 1/\sqrt{2m(1 + 2m/M)}$, $a_{23} = -(2m/M)a_{13}$),
    eq. 5.47–5.51, normalised $A^T T A = 1$.

    **Parameters** (SI): `outer_mass` m (¹⁶O, 15.9949 u), `central_mass` M (¹²C,
    12 u), `spring_constant` k (1680 N/m, which puts $\omega_2$ at the observed
    symmetric stretch, ≈ 1335 cm⁻¹; the model's asymmetric stretch, 2556 cm⁻¹, then
    overshoots the observed 2349 cm⁻¹ — real CO₂ couples its two bonds). Starts in
    the asymmetric stretch with the oxygens 1 pm out (`mode_state`).
    """

    outer_mass: jax.Array = parameter(15.9949146 * ATOMIC_MASS_UNIT, positive=True)
    central_mass: jax.Array = parameter(12.0 * ATOMIC_MASS_UNIT, positive=True)
    spring_constant: jax.Array = parameter(1680.0, positive=True)

    default_t1: ClassVar[float] = 1e-12
    default_dt: ClassVar[float] = 5e-17
    state_kind: ClassVar[StateKind] = "momentum"
    coordinate_names: ClassVar[tuple[str, ...]] = ("η₁", "η₂", "η₃")
    coordinate_units: ClassVar[tuple[str, ...]] = ("m", "m", "m")

    def system(self) -> SeparableHamiltonian:
        return SeparableHamiltonian(_kinetic, _triatomic_potential)

    def masses(self) -> jax.Array:
        """(m, M, m)."""
        return jnp.stack([self.outer_mass, self.central_mass, self.outer_mass])

    def normal_mode_frequencies(self) -> jax.Array:
        """(0, √(k/m), √((k/m)(1 + 2m/M))) (rad/s), eq. 5.41."""
        m, big_m, k = self.outer_mass, self.central_mass, self.spring_constant
        stretch = jnp.sqrt(k / m)
        return jnp.stack(
            [jnp.zeros_like(stretch), stretch, stretch * jnp.sqrt(1 + 2 * m / big_m)]
        )

    def normal_modes(self) -> jax.Array:
        """The course text's A (eq. 5.47–5.51): mode k in column k, Aᵀ T A = 1."""
        m, big_m = self.outer_mass, self.central_mass
        translation = jnp.ones(3) / jnp.sqrt(2 * m + big_m)
        symmetric = jnp.stack([1.0, 0.0, -1.0]) / jnp.sqrt(2 * m)
        outer = 1 / jnp.sqrt(2 * m * (1 + 2 * m / big_m))
        asymmetric = jnp.stack([outer, -2 * m / big_m * outer, outer])
        return jnp.stack([translation, symmetric, asymmetric], axis=1)

    def normal_coordinates(self, q: jax.Array) -> jax.Array:
        """ξ = Aᵀ T η; q may have a leading time axis."""
        return (q * self.masses()) @ self.normal_modes()

    def mode_state(self, mode: int, displacement=1e-12) -> tuple[jax.Array, jax.Array]:
        """At rest in normal mode `mode` (0, 1, 2), its largest η `displacement` (m)."""
        shape = self.normal_modes()[:, mode]
        return displacement * shape / jnp.max(jnp.abs(shape)), jnp.zeros(3)

    def initial_state(self) -> tuple[jax.Array, jax.Array]:
        return self.mode_state(2)

    def exact_solution(self, t: jax.Array) -> tuple[jax.Array, jax.Array]:
        """(η(t), p(t)) from `initial_state()` at t = 0 (time leads for array t)."""
        return normal_mode_motion(
            self.normal_mode_frequencies(),
            self.normal_modes(),
            self.masses(),
            self.initial_state(),
            t,
        )

    def checks(self, trajectory) -> dict[str, tuple[jax.Array, jax.Array]]:
        """The motion against the mode's exact oscillation; no leakage into others."""
        exact_q, _ = self.exact_solution(trajectory.ts)
        xi = self.normal_coordinates(trajectory.q)
        return {
            "η(t)": (trajectory.q, exact_q),
            "normal coordinates ξ(t)": (xi, self.normal_coordinates(exact_q)),
            "leakage out of the asymmetric stretch": (
                _mode_leakage(xi, excited=2),
                jnp.zeros(()),
            ),
        }


# --- Uniform chain with fixed ends ------------------------------------------------


def _chain_potential(q, t, scene):
    stretches = jnp.diff(jnp.pad(q, 1))  # the two walls hold q₀ = q_{N+1} = 0
    return 0.5 * scene.spring_constant * jnp.sum(stretches**2)


class SpringChain(AbstractScene):
    r"""N equal masses in a row, joined by N + 1 equal springs between two fixed walls.

    $$ H = \sum_{i=1}^N \frac{p_i^2}{2m}
       + \frac k2 \sum_{i=0}^{N} (q_{i+1} - q_i)^2,\qquad q_0 = q_{N+1} = 0. $$

    Normal modes $j = 1..N$ (the loaded string): frequencies
    $\omega_j = 2\sqrt{k/m}\,\sin\frac{j\pi}{2(N + 1)}$ and shapes
    $a_{ij} = \sqrt{2/((N+1)m)}\,\sin\frac{ij\pi}{N + 1}$ ($A^T T A = 1$).

    **Parameters:** `mass` m (kg, 0.5), `spring_constant` k (N/m, 50), `size` N
    (static, 8). Starts with the first mass 0.1 m out, at rest (all modes excited).
    """

    mass: jax.Array = parameter(0.5, positive=True)
    spring_constant: jax.Array = parameter(50.0, positive=True)
    size: int = count(8)

    default_t1: ClassVar[float] = 10.0
    default_dt: ClassVar[float] = 0.0025
    state_kind: ClassVar[StateKind] = "momentum"

    def coordinates(self) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """q₁ … q_N, displacements from equilibrium in m."""
        return numbered("q", self.size), ("m",) * self.size

    def system(self) -> SeparableHamiltonian:
        return SeparableHamiltonian(_kinetic, _chain_potential)

    def masses(self) -> jax.Array:
        return self.mass * jnp.ones(self.size)

    def initial_state(self) -> tuple[jax.Array, jax.Array]:
        return jnp.zeros(self.size).at[0].set(0.1), jnp.zeros(self.size)

    def normal_mode_frequencies(self) -> jax.Array:
        """ω_j = 2√(k/m) sin(jπ/(2(N+1))), ascending (rad/s)."""
        j = jnp.arange(1, self.size + 1)
        top = 2 * jnp.sqrt(self.spring_constant / self.mass)
        return top * jnp.sin(j * jnp.pi / (2 * (self.size + 1)))

    def normal_modes(self) -> jax.Array:
        """a_ij = √(2/((N+1)m)) sin(ijπ/(N+1)): mode j in column j."""
        i = jnp.arange(1, self.size + 1)
        phase = jnp.outer(i, i) * jnp.pi / (self.size + 1)
        return jnp.sqrt(2 / ((self.size + 1) * self.mass)) * jnp.sin(phase)

    def exact_solution(self, t: jax.Array) -> tuple[jax.Array, jax.Array]:
        """(q(t), p(t)) from `initial_state()` at t = 0 (time leads for array t)."""
        return normal_mode_motion(
            self.normal_mode_frequencies(),
            self.normal_modes(),
            self.masses(),
            self.initial_state(),
            t,
        )

    def checks(self, trajectory) -> dict[str, tuple[jax.Array, jax.Array]]:
        """State against the sum of normal modes; energy conservation."""
        exact_q, exact_p = self.exact_solution(trajectory.ts)
        energy = trajectory.energy()
        start_energy = self.system()(*self.initial_state(), 0.0, self)
        return {
            "q(t)": (trajectory.q, exact_q),
            "p(t)": (trajectory.p, exact_p),
            "energy": (energy, start_energy * jnp.ones_like(energy)),
        }


# --- Fermi–Pasta–Ulam chain (Hairer, Lubich & Wanner) -----------------------------


def _fpu_potential(q, t, scene):
    stiff = q[1::2] - q[0::2]  # q_{2i} − q_{2i−1}, i = 1..m
    walled = jnp.pad(q, 1)  # q₀ = q_{2m+1} = 0
    soft = walled[1::2] - walled[0::2]  # q_{2i+1} − q_{2i}, i = 0..m
    return scene.frequency**2 / 4 * jnp.sum(stiff**2) + jnp.sum(soft**4)


class FermiPastaUlamChain(AbstractScene):
    r"""The Fermi–Pasta–Ulam chain: stiff linear springs alternating with soft quartic.

    2m unit masses between two walls (Hairer, Lubich & Wanner's formulation):

    $$ H = \frac12\sum_{i=1}^{2m} p_i^2 + \frac{\omega^2}{4}\sum_{i=1}^{m}
       (q_{2i} - q_{2i-1})^2 + \sum_{i=0}^{m} (q_{2i+1} - q_{2i})^4,
       \qquad q_0 = q_{2m+1} = 0, $$

    (GNI §I.5.1). With
    $x_{1,j} = (q_{2j} - q_{2j-1})/\sqrt2$ and $y_{1,j}$ likewise from p, the stiff
    spring j oscillates at ≈ ω with energy $I_j = \tfrac12(y_{1,j}^2 + \omega^2
    x_{1,j}^2)$. The $I_j$ exchange energy on the time scale ω, but their sum
    $I = \sum_j I_j$ is an adiabatic invariant, $I(t) = I(0) + O(\omega^{-1})$ over
    times much longer than ω (GNI Chapter XIII); Störmer–Verlet at
    $h\omega \approx 1$ keeps it with a bounded error and no drift (measured in the
    tests: max |I − I(0)| = 0.22 at hω = 1 over 10³ time units, against 0.06 for
    the exact flow, and no change of its mean).

    **Parameters** (dimensionless, as in GNI): `frequency` ω (50), `pairs` m
    (static, 3). Starts from GNI's values $x_{0,1} = 1$, $y_{0,1} = 1$,
    $x_{1,1} = 1/\omega$, $y_{1,1} = 1$, all others zero ($I(0) = 1$), where
    $x_{0,j} = (q_{2j} + q_{2j-1})/\sqrt2$.
    """

    frequency: jax.Array = parameter(50.0, positive=True)
    pairs: int = count(3)

    default_t1: ClassVar[float] = 200.0
    default_dt: ClassVar[float] = 0.02
    state_kind: ClassVar[StateKind] = "momentum"
    time_unit: ClassVar[str] = ""  # dimensionless, as in GNI

    def coordinates(self) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """q₁ … q₂ₘ, dimensionless (GNI's units)."""
        return numbered("q", 2 * self.pairs), ("",) * (2 * self.pairs)

    def system(self) -> SeparableHamiltonian:
        return SeparableHamiltonian(_kinetic, _fpu_potential)

    def masses(self) -> jax.Array:
        return jnp.ones(2 * self.pairs)

    def initial_state(self) -> tuple[jax.Array, jax.Array]:
        first = jnp.zeros(self.pairs).at[0].set(1.0)
        q0 = _from_pair_coordinates(first, first / self.frequency)  # x₀,₁, x₁,₁
        p0 = _from_pair_coordinates(first, first)  # y₀,₁, y₁,₁
        return q0, p0

    def oscillatory_energies(self, q: jax.Array, p: jax.Array) -> jax.Array:
        """I_j = ½(y₁,ⱼ² + ω² x₁,ⱼ²), j = 1..m, on the last axis."""
        stretch = (q[..., 1::2] - q[..., 0::2]) / jnp.sqrt(2.0)
        stretch_rate = (p[..., 1::2] - p[..., 0::2]) / jnp.sqrt(2.0)
        return 0.5 * (stretch_rate**2 + self.frequency**2 * stretch**2)

    def checks(self, trajectory) -> dict[str, tuple[jax.Array, jax.Array]]:
        """Total oscillatory energy I near I(0) (to O(1/ω)); H conserved."""
        start = self.initial_state()
        total = jnp.sum(self.oscillatory_energies(trajectory.q, trajectory.p), -1)
        start_total = jnp.sum(self.oscillatory_energies(*start))
        energy = trajectory.energy()
        start_energy = self.system()(*start, 0.0, self)
        return {
            "oscillatory energy I": (total, start_total * jnp.ones_like(total)),
            "energy": (energy, start_energy * jnp.ones_like(energy)),
        }


def _from_pair_coordinates(centre: jax.Array, stretch: jax.Array) -> jax.Array:
    """q from (x₀, x₁): q_{2j−1} = (x₀ − x₁)/√2, q_{2j} = (x₀ + x₁)/√2."""
    odd, even = (centre - stretch) / jnp.sqrt(2.0), (centre + stretch) / jnp.sqrt(2.0)
    return jnp.stack([odd, even], axis=-1).reshape(*centre.shape[:-1], -1)


SCENES = (LinearTriatomicMolecule, SpringChain, FermiPastaUlamChain)
