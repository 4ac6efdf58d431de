r"""Free linear oscillators: harmonic in one and n dimensions, normal modes.

Near a stable equilibrium every system is a set of harmonic oscillators (the course
text §5): a quadratic $L = \tfrac12\dot q^T T\dot q - \tfrac12 q^T V q$ separates into
normal modes $\xi_k$, each oscillating at its own $\omega_k$ with a constant action
$J_k = E_k/\omega_k$ and an angle advancing at $\omega_k$. These scenes are the
conservative linear cases, solved in closed form: the oscillator in one dimension
and with a general stiffness matrix (exact solution, action–angle variables). The
oscillator with friction and a driving force is in `driven.py`, pendulums in
`pendulums.py`, chains of springs in `chains.py`.

Every `checks(trajectory)` assumes a run from `initial_state()` at $t = 0$ and
compares each saved time with the closed form.

References: the course text §5 (small oscillations, eq. 5.12–5.33); Goldstein, Poole
& Safko, *Classical Mechanics*, 3rd ed., §6.2–6.3 and §10.6 (action–angle
variables); Landau & Lifshitz, *Mechanics*, §21–§23.
"""

from __future__ import annotations

from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from lagjax.mechanics.hamiltonian import SeparableHamiltonian
from lagjax.scenes.base import (
    AbstractScene,
    StateKind,
    concrete,
    numbered,
    parameter,
)


def angle_advance(start: jax.Array, angles: jax.Array) -> jax.Array:
    """φ(t) − φ(0) counted continuously, from angles in (−π, π] sampled along a run.

    `angles` has a leading time axis; consecutive samples (and the first after
    `start`) must be less than half a turn apart.
    """
    joined = jnp.concatenate([jnp.asarray(start)[None], angles])
    return jnp.unwrap(joined, axis=0)[1:] - start


def normal_mode_motion(
    frequencies: jax.Array,
    modes: jax.Array,
    masses: jax.Array,
    state0: tuple[jax.Array, jax.Array],
    t: jax.Array,
) -> tuple[jax.Array, jax.Array]:
    r"""Exact (q(t), p(t)) of $H = \sum p_i^2/2m_i + \tfrac12 q^T K q$ from its modes.

    `modes` has mode k in column k with $A^T M A = 1$, $M = \mathrm{diag}$(`masses`).
    Normal coordinates $\xi = A^T M q$, $\pi = A^T p$ move as
    $\xi_k(t) = \xi_k\cos\omega_k t + \pi_k \sin(\omega_k t)/\omega_k$ (uniformly,
    $\xi_k + \pi_k t$, for a zero mode); then $q = A\xi$, $p = M A\pi$. `t` may be
    an array; time is the leading axis of the result.
    """
    q0, p0 = state0
    xi0, pi0 = (q0 * masses) @ modes, p0 @ modes
    t = jnp.asarray(t)[..., None]
    moving = frequencies > 0
    safe = jnp.where(moving, frequencies, 1.0)
    cos, sin = jnp.cos(frequencies * t), jnp.sin(frequencies * t)
    xi = xi0 * cos + pi0 * jnp.where(moving, sin / safe, t)
    pi = pi0 * cos - frequencies * xi0 * sin
    return xi @ modes.T, (pi @ modes.T) * masses


# --- Harmonic oscillator, one dimension -------------------------------------------


def _harmonic_kinetic(p, t, scene):
    return 0.5 * p**2 / scene.mass


def _harmonic_potential(q, t, scene):
    return 0.5 * scene.stiffness * q**2


class HarmonicOscillator(AbstractScene):
    r"""A mass on a spring, in one dimension: exact solution, action–angle variables.

    $H = \dfrac{p^2}{2m} + \dfrac{k q^2}{2}$, $\omega = \sqrt{k/m}$. Exact solution
    $q = q_0\cos\omega t + \frac{p_0}{m\omega}\sin\omega t$,
    $p = p_0\cos\omega t - m\omega q_0\sin\omega t$. Action–angle variables
    $(J, \varphi)$: $q = \sqrt{2J/m\omega}\,\sin\varphi$,
    $p = \sqrt{2m\omega J}\,\cos\varphi$, so $H = \omega J$, $J = E/\omega$ is
    constant and $\dot\varphi = \partial H/\partial J = \omega$.

    **Parameters:** `mass` m (kg, default 1), `stiffness` k (N/m, default 4).
    Starts at $q_0 = 1$ m, $p_0 = 0.5$ kg m/s.

    References: Goldstein, Poole & Safko §10.6 (action–angle variables for the
    oscillator); the course text §5.
    """

    mass: jax.Array = parameter(1.0, positive=True)
    stiffness: jax.Array = parameter(4.0, positive=True)

    default_t1: ClassVar[float] = 10.0
    default_dt: ClassVar[float] = 0.01
    state_kind: ClassVar[StateKind] = "momentum"
    coordinate_names: ClassVar[tuple[str, ...]] = ("q",)
    coordinate_units: ClassVar[tuple[str, ...]] = ("m",)

    def system(self) -> SeparableHamiltonian:
        return SeparableHamiltonian(_harmonic_kinetic, _harmonic_potential)

    def initial_state(self) -> tuple[jax.Array, jax.Array]:
        return jnp.asarray(1.0), jnp.asarray(0.5)

    def frequency(self) -> jax.Array:
        """ω = √(k/m) (rad/s)."""
        return jnp.sqrt(self.stiffness / self.mass)

    def period(self) -> jax.Array:
        """2π/ω (s)."""
        return 2 * jnp.pi / self.frequency()

    def exact_solution(self, t: jax.Array) -> tuple[jax.Array, jax.Array]:
        """(q(t), p(t)) from `initial_state()` at t = 0."""
        q0, p0 = self.initial_state()
        omega, phase = self.frequency(), self.frequency() * jnp.asarray(t)
        q = q0 * jnp.cos(phase) + p0 / (self.mass * omega) * jnp.sin(phase)
        p = p0 * jnp.cos(phase) - self.mass * omega * q0 * jnp.sin(phase)
        return q, p

    def action(self, q: jax.Array, p: jax.Array) -> jax.Array:
        """J = E/ω = (p²/m + m ω² q²)/(2ω)."""
        omega = self.frequency()
        return (p**2 / self.mass + self.mass * omega**2 * q**2) / (2 * omega)

    def angle(self, q: jax.Array, p: jax.Array) -> jax.Array:
        """φ = atan2(m ω q, p) in (−π, π]."""
        return jnp.arctan2(self.mass * self.frequency() * q, p)

    def checks(self, trajectory) -> dict[str, tuple[jax.Array, jax.Array]]:
        """State against the exact solution, J constant, φ advancing at ω.

        The angle advance needs samples less than half a period apart.
        """
        q, p = trajectory.q, trajectory.p
        exact_q, exact_p = self.exact_solution(trajectory.ts)
        q0, p0 = self.initial_state()
        advance = angle_advance(self.angle(q0, p0), self.angle(q, p))
        return {
            "q(t)": (q, exact_q),
            "p(t)": (p, exact_p),
            "action J": (self.action(q, p), self.action(q0, p0) * jnp.ones_like(q)),
            "angle advance φ(t) − φ(0)": (advance, self.frequency() * trajectory.ts),
        }


# --- Coupled oscillators: n dimensions, stiffness matrix K ----------------------


def _coupled_kinetic(p, t, scene):
    return 0.5 * jnp.sum(p**2 / scene.masses)


def _coupled_potential(q, t, scene):
    return 0.5 * q @ scene.stiffness @ q


def _stiffness_matrix(stiffness: jax.Array) -> jax.Array:
    """A vector of diagonal entries becomes the diagonal matrix."""
    return jnp.diag(stiffness) if stiffness.ndim == 1 else stiffness


class CoupledOscillators(AbstractScene):
    r"""n masses coupled by a symmetric positive definite stiffness matrix K.

    $$ H = \sum_i \frac{p_i^2}{2 m_i} + \tfrac12 q^T K q. $$

    With $M = \mathrm{diag}(m)$ and $M^{-1/2} K M^{-1/2} = U\,\mathrm{diag}(\omega^2)
    U^T$, the normal modes are the columns of $A = M^{-1/2}U$ ($A^T M A = 1$); the
    normal coordinates $\xi = A^T M q$, $\pi = A^T p$ oscillate independently (see
    `normal_mode_motion`), each with a constant action
    $J_k = (\pi_k^2 + \omega_k^2\xi_k^2)/2\omega_k$ and an angle
    $\varphi_k = \operatorname{atan2}(\omega_k\xi_k, \pi_k)$ advancing at $\omega_k$.
    A diagonal K is n independent oscillators.

    **Parameters:** `masses` (n,) (kg, default (1, 2, 0.5)); `stiffness` (n, n) SPD,
    or (n,) for a diagonal matrix (N/m, default a coupled 3 × 3). Starts with
    $q_i = 0.1\,i/n$ m, every mass moving at 0.1 m/s.

    References: the course text §5.2 (eq. 5.23–5.33, normal coordinates);
    Goldstein, Poole & Safko §6.2–6.3 and §10.6.
    """

    masses: jax.Array = parameter((1.0, 2.0, 0.5), positive=True)
    stiffness: jax.Array = parameter(
        ((5.0, -2.0, 1.0), (-2.0, 4.0, -1.0), (1.0, -1.0, 3.0)),
        convert=_stiffness_matrix,
    )

    default_t1: ClassVar[float] = 20.0
    default_dt: ClassVar[float] = 0.01
    state_kind: ClassVar[StateKind] = "momentum"

    def coordinates(self) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """q₁ … qₙ, displacements in m (n is the number of masses)."""
        size = self.masses.shape[-1]
        return numbered("q", size), ("m",) * size

    def __check_init__(self):
        n = self.masses.shape[-1]
        if self.stiffness.shape[-2:] != (n, n):
            raise ValueError(
                f"stiffness must be ({n}, {n}) or ({n},) for {n} masses, "
                f"got shape {self.stiffness.shape}"
            )
        values = concrete(self.stiffness)
        if values is None:
            return  # traced (vmap, jit): not checked, see lagjax.scenes.base
        (stiffness,) = values
        if not np.allclose(stiffness, np.swapaxes(stiffness, -1, -2)):
            raise ValueError("stiffness must be a symmetric matrix (K = Kᵀ)")
        if np.any(np.linalg.eigvalsh(stiffness) <= 0):
            raise ValueError(
                "stiffness must be positive definite: a zero or negative "
                "eigenvalue is a free or unstable direction, with no oscillation"
            )

    def system(self) -> SeparableHamiltonian:
        return SeparableHamiltonian(_coupled_kinetic, _coupled_potential)

    def initial_state(self) -> tuple[jax.Array, jax.Array]:
        # Every coordinate out by a different amount and moving, so that a
        # diagonal K, too, has every mode excited (an unexcited mode has no angle).
        n = self.masses.shape[-1]
        return 0.1 * jnp.arange(1, n + 1) / n, 0.1 * self.masses

    def _mass_weighted_eigensystem(self) -> tuple[jax.Array, jax.Array]:
        root = jnp.sqrt(self.masses)
        reduced = self.stiffness / root[:, None] / root[None, :]
        return jnp.linalg.eigh(0.5 * (reduced + reduced.T))

    def normal_mode_frequencies(self) -> jax.Array:
        """ω_k, ascending (rad/s)."""
        squared, _ = self._mass_weighted_eigensystem()
        return jnp.sqrt(squared)

    def normal_modes(self) -> jax.Array:
        """A = M^{-1/2} U: mode k in column k, Aᵀ M A = 1 (signs arbitrary)."""
        _, vectors = self._mass_weighted_eigensystem()
        return vectors / jnp.sqrt(self.masses)[:, None]

    def exact_solution(self, t: jax.Array) -> tuple[jax.Array, jax.Array]:
        """(q(t), p(t)) from `initial_state()` at t = 0; time leads for array t."""
        return normal_mode_motion(
            self.normal_mode_frequencies(),
            self.normal_modes(),
            self.masses,
            self.initial_state(),
            t,
        )

    def actions(self, q: jax.Array, p: jax.Array) -> jax.Array:
        """J_k = (π_k² + ω_k² ξ_k²)/(2ω_k) = E_k/ω_k, the last axis over modes."""
        omega, modes = self.normal_mode_frequencies(), self.normal_modes()
        xi, pi = (q * self.masses) @ modes, p @ modes
        return (pi**2 + omega**2 * xi**2) / (2 * omega)

    def angles(self, q: jax.Array, p: jax.Array) -> jax.Array:
        """φ_k = atan2(ω_k ξ_k, π_k) in (−π, π]."""
        omega, modes = self.normal_mode_frequencies(), self.normal_modes()
        return jnp.arctan2(omega * ((q * self.masses) @ modes), p @ modes)

    def checks(self, trajectory) -> dict[str, tuple[jax.Array, jax.Array]]:
        """State against the exact solution, each J_k constant, φ_k advancing at ω_k.

        The angle advance needs samples less than half the shortest period apart.
        """
        q, p = trajectory.q, trajectory.p
        exact_q, exact_p = self.exact_solution(trajectory.ts)
        state0 = self.initial_state()
        advance = angle_advance(self.angles(*state0), self.angles(q, p))
        return {
            "q(t)": (q, exact_q),
            "p(t)": (p, exact_p),
            "actions J_k": (
                self.actions(q, p),
                self.actions(*state0) * jnp.ones_like(q),
            ),
            "angle advances φ_k(t) − φ_k(0)": (
                advance,
                trajectory.ts[:, None] * self.normal_mode_frequencies(),
            ),
        }


SCENES = (HarmonicOscillator, CoupledOscillators)
