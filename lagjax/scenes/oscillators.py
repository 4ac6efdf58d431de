r"""Linear oscillators: harmonic in one and n dimensions, damped and driven.

Near a stable equilibrium every system is a set of harmonic oscillators (the course
text §5): a quadratic $L = \tfrac12\dot q^T T\dot q - \tfrac12 q^T V q$ separates into
normal modes $\xi_k$, each oscillating at its own $\omega_k$ with a constant action
$J_k = E_k/\omega_k$ and an angle advancing at $\omega_k$. These scenes are the linear
cases, solved in closed form: the oscillator in one dimension and with a general
stiffness matrix (exact solution, action–angle variables), and the oscillator with
viscous friction and a harmonic force (transient, steady-state response, energy
decay). Pendulums are in `pendulums.py`, chains of springs in `chains.py`.

Every `checks(trajectory)` assumes a run from `initial_state()` at $t = 0$ and
compares each saved time with the closed form.

References: the course text §5 (small oscillations, eq. 5.12–5.33); Goldstein, Poole
& Safko, *Classical Mechanics*, 3rd ed., §6.2–6.3 and §10.6 (action–angle
variables); Landau & Lifshitz, *Mechanics*, §21–§26.
"""

from __future__ import annotations

from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from lagjax.mechanics.hamiltonian import SeparableHamiltonian
from lagjax.mechanics.lagrangian import Lagrangian
from lagjax.scenes.base import AbstractScene, StateKind, concrete, parameter


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


# --- Damped and driven oscillator -------------------------------------------------


def _spring_lagrangian(q, qdot, t, scene):
    return 0.5 * scene.mass * qdot**2 - 0.5 * scene.stiffness * q**2


def _viscous_dissipation(q, qdot, t, scene):
    return 0.5 * scene.mass * scene.damping * qdot**2


def _harmonic_drive(q, qdot, t, scene):
    return scene.drive_amplitude * jnp.cos(scene.drive_frequency * t)


class DampedDrivenOscillator(AbstractScene):
    r"""A spring with viscous friction and a harmonic driving force.

    $L = \tfrac12 m\dot q^2 - \tfrac12 k q^2$, Rayleigh dissipation
    $D = \tfrac12 m\gamma\dot q^2$ and force $Q = F_0\cos\Omega t$ give
    $\ddot q + \gamma\dot q + \omega_0^2 q = (F_0/m)\cos\Omega t$, $\omega_0^2 = k/m$.
    The steady state is $q = A\cos(\Omega t - \delta)$ with

    $$ A = \frac{F_0/m}{\sqrt{(\omega_0^2 - \Omega^2)^2 + (\gamma\Omega)^2}},\qquad
       \tan\delta = \frac{\gamma\Omega}{\omega_0^2 - \Omega^2}, $$

    reached once the transient
    $e^{-\gamma t/2}(C_1\cos\omega_d t + C_2\sin\omega_d t)$,
    $\omega_d = \sqrt{\omega_0^2 - \gamma^2/4}$ (underdamped, $\gamma < 2\omega_0$,
    assumed throughout), dies out. Without drive the energy
    $E = \tfrac12 m\dot q^2 + \tfrac12 k q^2$ times $e^{\gamma t}$ is periodic with
    period $\pi/\omega_d$: E decays as $e^{-\gamma t}$ on average, exactly so between
    times $n\pi/\omega_d$ apart.

    **Parameters:** `mass` m (kg, 1), `stiffness` k (N/m, 4), `damping` γ (1/s, 1),
    `drive_amplitude` F₀ (N, 1; 0 for free damped motion), `drive_frequency` Ω
    (rad/s, 1.5). Starts at $q_0 = 1$ m at rest.

    References: Landau & Lifshitz, *Mechanics*, §22 and §25–§26; Goldstein, Poole & Safko
    §1.5 (Rayleigh's dissipation function).
    """

    mass: jax.Array = parameter(1.0, positive=True)
    stiffness: jax.Array = parameter(4.0, positive=True)
    damping: jax.Array = parameter(1.0, nonnegative=True)
    drive_amplitude: jax.Array = parameter(1.0)
    drive_frequency: jax.Array = parameter(1.5, nonnegative=True)

    default_t1: ClassVar[float] = 60.0
    default_dt: ClassVar[float] = 0.01
    state_kind: ClassVar[StateKind] = "velocity"

    def __check_init__(self):
        values = concrete(self.mass, self.stiffness, self.damping)
        if values is None:
            return  # traced (vmap, jit): not checked, see lagjax.scenes.base
        mass, stiffness, damping = values
        if np.any(damping >= 2 * np.sqrt(stiffness / mass)):
            raise ValueError(
                "DampedDrivenOscillator's closed forms are for the underdamped case: "
                f"damping must be below 2√(k/m) = {2 * np.sqrt(stiffness / mass)}"
            )

    def system(self) -> Lagrangian:
        return Lagrangian(
            _spring_lagrangian,
            force=_harmonic_drive,
            dissipation=_viscous_dissipation,
            quadratic_in_velocity=True,
        )

    def initial_state(self) -> tuple[jax.Array, jax.Array]:
        return jnp.asarray(1.0), jnp.asarray(0.0)

    def damped_frequency(self) -> jax.Array:
        """ω_d = √(ω₀² − γ²/4) of the free (transient) oscillation."""
        return jnp.sqrt(self.stiffness / self.mass - self.damping**2 / 4)

    def steady_state_amplitude(self) -> jax.Array:
        """A = (F₀/m) / √((ω₀² − Ω²)² + (γΩ)²)."""
        detuning = self.stiffness / self.mass - self.drive_frequency**2
        friction = self.damping * self.drive_frequency
        return self.drive_amplitude / self.mass / jnp.hypot(detuning, friction)

    def steady_state_phase(self) -> jax.Array:
        """δ = atan2(γΩ, ω₀² − Ω²) ∈ [0, π]: how far q lags the force."""
        detuning = self.stiffness / self.mass - self.drive_frequency**2
        return jnp.arctan2(self.damping * self.drive_frequency, detuning)

    def settling_time(self) -> jax.Array:
        """40/γ: the transient has decayed by e^{−20} ≈ 2e-9 by then."""
        return 40 / self.damping

    def exact_solution(self, t: jax.Array) -> tuple[jax.Array, jax.Array]:
        """(q(t), q̇(t)) from `initial_state()` at t = 0: transient + steady state."""
        # q = Re(S e^{iΩt} + C e^{λt}), S = A e^{−iδ}, λ = −γ/2 + iω_d, C from q₀, q̇₀.
        t, omega = jnp.asarray(t), self.drive_frequency
        response = self.steady_state_amplitude() * jnp.exp(
            -1j * self.steady_state_phase()
        )
        rate = -self.damping / 2 + 1j * self.damped_frequency()
        q0, qdot0 = self.initial_state()
        c1 = q0 - response.real
        c2 = (qdot0 - (1j * omega * response).real - rate.real * c1) / rate.imag
        steady = response * jnp.exp(1j * omega * t)
        transient = (c1 - 1j * c2) * jnp.exp(rate * t)
        return (steady + transient).real, (1j * omega * steady + rate * transient).real

    def energy(self, q: jax.Array, qdot: jax.Array) -> jax.Array:
        """E = ½ m q̇² + ½ k q² (the Jacobi integral of L)."""
        return 0.5 * self.mass * qdot**2 + 0.5 * self.stiffness * q**2

    def measured_response(self, trajectory) -> tuple[jax.Array, jax.Array]:
        """(A, δ) fitted to q ≈ A cos(Ωt − δ) over the samples after `settling_time`."""
        settled = (trajectory.ts >= self.settling_time()).astype(float)
        phase = self.drive_frequency * trajectory.ts
        basis = jnp.stack([jnp.cos(phase), jnp.sin(phase)], axis=-1) * settled[:, None]
        (a, b), *_ = jnp.linalg.lstsq(basis, trajectory.q * settled)
        return jnp.hypot(a, b), jnp.arctan2(b, a)

    def checks(self, trajectory) -> dict[str, tuple[jax.Array, jax.Array]]:
        """q(t) and E(t) exact; steady-state response; average energy decay rate.

        The response is fitted after `settling_time` (the run must reach beyond
        it); the decay rate is ln(E(0)/E(t₁))/t₁ over the run, which equals γ for
        a free run whose t₁ is a multiple of π/ω_d.
        """
        exact_q, exact_qdot = self.exact_solution(trajectory.ts)
        energy = trajectory.energy()
        exact_energy = self.energy(exact_q, exact_qdot)
        start_energy, t_end = self.energy(*self.initial_state()), trajectory.ts[-1]
        amplitude, lag = self.measured_response(trajectory)
        return {
            "q(t)": (trajectory.q, exact_q),
            "energy": (energy, exact_energy),
            "steady-state amplitude": (amplitude, self.steady_state_amplitude()),
            "steady-state phase": (lag, self.steady_state_phase()),
            "energy decay rate": (
                jnp.log(start_energy / energy[-1]) / t_end,
                jnp.log(start_energy / exact_energy[-1]) / t_end,
            ),
        }


SCENES = (HarmonicOscillator, CoupledOscillators, DampedDrivenOscillator)
