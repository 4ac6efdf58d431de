r"""The damped and driven oscillator: transient, steady-state response, energy decay.

A linear oscillator with viscous friction (a Rayleigh dissipation function) and a
harmonic driving force, solved in closed form: the transient dies out at the rate
γ/2 and the motion settles on the drive's frequency with the amplitude and phase lag
of the resonance curve. Without drive the energy decays as e^{−γt} on average. The
free oscillators are in `oscillators.py`.

`checks(trajectory)` assumes a run from `initial_state()` at t = 0 and compares
each saved time with the closed form.

References: Landau & Lifshitz, *Mechanics*, §22 and §25–§26; Goldstein, Poole &
Safko, *Classical Mechanics*, 3rd ed., §1.5 (Rayleigh's dissipation function).
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from lagjax.mechanics.lagrangian import Lagrangian
from lagjax.scenes.base import (
    AbstractScene,
    Diagnostic,
    StateKind,
    concrete,
    parameter,
)

# The steady state q = A cos(Ωt − δ) has two unknowns; a few more samples than two
# keep the least-squares fit determined.
_FIT_SAMPLES = 4


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
    coordinate_names: ClassVar[tuple[str, ...]] = ("q",)
    coordinate_units: ClassVar[tuple[str, ...]] = ("m",)

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
        a free run whose t₁ is a multiple of π/ω_d. A driven run that saved fewer
        than `_FIT_SAMPLES` states after `settling_time` cannot show the steady
        state: refused (`ValueError`, "not judged" in the command; under `jit` a
        run-time error) rather than compared as a fit of nothing (amplitude 0).
        """
        amplitude, lag = self._judged_response(trajectory)  # first: it may refuse
        exact_q, exact_qdot = self.exact_solution(trajectory.ts)
        energy = trajectory.energy()
        exact_energy = self.energy(exact_q, exact_qdot)
        start_energy, t_end = self.energy(*self.initial_state()), trajectory.ts[-1]
        checks = {
            "q(t)": (trajectory.q, exact_q),
            "energy": (energy, exact_energy),
            "steady-state amplitude": (amplitude, self.steady_state_amplitude()),
            "steady-state phase": (lag, self.steady_state_phase()),
            "energy decay rate": (
                jnp.log(start_energy / energy[-1]) / t_end,
                jnp.log(start_energy / exact_energy[-1]) / t_end,
            ),
        }
        values = concrete(self.drive_amplitude)
        if values is not None and not np.any(values[0]):
            # No drive: the steady state has amplitude 0 and no phase to compare.
            del checks["steady-state phase"]
        return checks

    def _judged_response(self, trajectory) -> tuple[jax.Array, jax.Array]:
        """`measured_response`, or an error when the run ends before the steady
        state (a free run, F₀ = 0, settles to rest: judged at any length)."""
        settled = jnp.sum(trajectory.ts >= self.settling_time())
        short = (settled < _FIT_SAMPLES) & (self.drive_amplitude != 0)
        needed = self.settling_time() + 4 * jnp.pi / self.drive_frequency
        values = concrete(short, settled, trajectory.ts[-1], needed)
        if values is None:
            response = self.measured_response(trajectory)
            return eqx.error_if(response, short, self._too_short_message())
        too_short, count, t_end, t1 = values
        if too_short:
            saved = f"; this run saved {int(count)} (it ends at t = {float(t_end):.4g})"
            raise ValueError(self._too_short_message(saved, f" = {float(t1):.4g}"))
        return self.measured_response(trajectory)

    def _too_short_message(self, saved: str = "", t1: str = "") -> str:
        return (
            f"{type(self).__name__}.checks cannot judge the steady-state response on "
            "this run: it is fitted to the states saved after the transient has "
            "died out, t ≥ settling_time() = 40/γ, and needs at least "
            f"{_FIT_SAMPLES} of them{saved}. Run two drive periods past it, to "
            f"t1 ≥ 40/γ + 4π/Ω{t1}, saving along the way (e.g. "
            "ts=jnp.linspace(0, t1, 2001))"
        )

    def diagnostic(self, trajectory) -> Diagnostic:
        """The energy E(t), lost to friction and fed by the drive, vs closed form."""
        exact_q, exact_qdot = self.exact_solution(trajectory.ts)
        return Diagnostic(
            "energy E = ½ m q̇² + ½ k q² [J]",
            trajectory.ts,
            trajectory.energy(),
            self.energy(exact_q, exact_qdot),
            "closed form (transient + steady state)",
        )


SCENES = (DampedDrivenOscillator,)
