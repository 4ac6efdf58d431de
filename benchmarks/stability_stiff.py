r"""The stability suite's stiff and singular cases (final state against physics).

- the stiff Fermi–Pasta–Ulam chain at ω = 50, 10³ and 10⁴ (a step of 0.01 puts hω
  at 0.5 … 100);
- a heavily overdamped oscillator, ζ = 10² and 10⁴, where the L-stable Kvaerno5
  must beat the explicit methods;
- a pendulum on a stiff spring (ω = 1000 against √g);
- a pendulum released at 179.9° and a Kepler orbit with e = 0.99 (the milder
  cousins of the cases in `stability_extreme.py`);
- singular or near-singular mass matrices: a degenerate Lagrangian, and a free body
  in Euler angles next to gimbal lock, with the quaternion route as the remedy.

References: Hairer & Wanner, *Solving Ordinary Differential Equations II*, 2nd ed.,
Springer 1996, §IV.1–IV.3 (stiffness, A- and L-stability); Hairer, Lubich & Wanner,
*Geometric Numerical Integration*, 2nd ed., Springer 2006, §XIII (FPU).
"""

from __future__ import annotations

import math

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

import lagjax as lj
from benchmarks.stability_engine import Attempt, Case
from lagjax.rigid import quaternion_to_matrix
from lagjax.rigid.euler_angles import (
    euler_zxz_body_angular_velocity,
    euler_zxz_to_rotation,
)
from lagjax.scenes.central import KeplerCartesian
from lagjax.scenes.chains import FermiPastaUlamChain
from lagjax.scenes.pendulums import SimplePendulum
from lagjax.scenes.rigid import TorqueFreeBody
from lagjax.solvers.lie_poisson import RigidBodyYoshida4

# Gauss–Legendre's default fixed-point stage solver needs h·Lip(f) < 1; Newton does
# not (its residual test is absolute, so atol sits above the round-off, see
# lagjax.solvers.implicit.GaussLegendre).
NEWTON = optx.Newton(rtol=1e-12, atol=1e-12)


def _overdamped_lagrangian(q, qdot, t, damping_ratio):
    return 0.5 * qdot**2 - 0.5 * q**2  # ω₀ = 1


def _overdamped_dissipation(q, qdot, t, damping_ratio):
    return damping_ratio * qdot**2  # −∂D/∂q̇ = −2ζ q̇


def overdamped_case(damping_ratio: float) -> Case:
    r"""q̈ + 2ζq̇ + q = 0 from q = 1 at rest: rates λ = −ζ ± √(ζ² − 1), both real."""
    root = math.sqrt(damping_ratio**2 - 1)
    slow, fast = -1 / (damping_ratio + root), -(damping_ratio + root)  # no cancellation
    t1 = 100.0
    weights = fast / (fast - slow), -slow / (fast - slow)
    q1 = weights[0] * math.exp(slow * t1) + weights[1] * math.exp(fast * t1)
    qdot1 = weights[0] * slow * math.exp(slow * t1) + weights[1] * fast * math.exp(
        fast * t1
    )
    lag = lj.Lagrangian(
        _overdamped_lagrangian,
        dissipation=_overdamped_dissipation,
        quadratic_in_velocity=True,
    )
    attempts = [
        Attempt("Tsit5 (explicit)", diffrax.Tsit5()),
        Attempt("Dopri8 (explicit)", diffrax.Dopri8(), in_quick=False),
        Attempt("Kvaerno5 (implicit, L-stable)", diffrax.Kvaerno5()),
        Attempt("Kvaerno5, fixed step", diffrax.Kvaerno5(), steps=1000, in_quick=False),
        Attempt("GaussLegendre(2) (A-stable)", lj.GaussLegendre(stages=2), steps=1000,
                in_quick=False),
        Attempt("GaussLegendre(2), Newton stages", lj.GaussLegendre(stages=2, root_finder=NEWTON),
                steps=1000, in_quick=False),
        Attempt("VariationalMidpoint", lj.VariationalMidpoint(), steps=1000, in_quick=False),
    ]  # fmt: skip
    return Case(
        f"overdamped oscillator ζ = {damping_ratio:g}", lag,
        (jnp.asarray(1.0), jnp.asarray(0.0)), t1, attempts, tolerance=1e-5,
        expected=np.array([q1, qdot1]), args=jnp.asarray(float(damping_ratio)),
        conservative=False,
    )  # fmt: skip


def _spring_pendulum_lagrangian(q, qdot, t, stiffness):
    radius, angle = q[0], q[1]
    kinetic = 0.5 * (qdot[0] ** 2 + (radius * qdot[1]) ** 2)
    return (
        kinetic + 9.81 * radius * jnp.cos(angle) - 0.5 * stiffness * (radius - 1) ** 2
    )


def spring_pendulum_case() -> Case:
    """Unit mass on a spring of rest length 1 and k = 10⁶ (ω = 1000 against √g)."""
    stiffness, angle = 1e6, 1.0
    start = jnp.array([1 + 9.81 * math.cos(angle) / stiffness, angle])
    lag = lj.Lagrangian(_spring_pendulum_lagrangian, quadratic_in_velocity=True)
    attempts = [
        Attempt("Tsit5", diffrax.Tsit5()),
        Attempt("Dopri8", diffrax.Dopri8()),
        Attempt("Kvaerno5", diffrax.Kvaerno5()),
        Attempt("GaussLegendre(2), hω = 1", lj.GaussLegendre(stages=2), steps=2000),
        Attempt(
            "GaussLegendre(2), hω = 1, Newton",
            lj.GaussLegendre(stages=2, root_finder=NEWTON),
            steps=2000,
        ),
        Attempt("GaussLegendre(2), hω = 0.1", lj.GaussLegendre(stages=2), steps=20000),
    ]
    return Case(
        "stiff spring pendulum, ω = 1000", lag, (start, jnp.zeros(2)), 2.0,
        attempts, tolerance=1e-5, args=jnp.asarray(stiffness),
    )  # fmt: skip


def fpu_case(frequency: float) -> Case:
    """The FPU chain over t = 1; Störmer–Verlet's step 0.01 puts hω at 0.5 … 100."""
    chain = FermiPastaUlamChain(frequency=frequency)
    resolved = 100 * math.ceil(10 * frequency / 100)  # hω = 0.1
    attempts = [
        Attempt("StormerVerlet, h = 0.01", lj.StormerVerlet(), steps=100),
        Attempt(f"StormerVerlet, hω = {frequency / resolved:.2g}", lj.StormerVerlet(), steps=resolved, in_quick=False),
        Attempt("GaussLegendre(2), h = 0.01", lj.GaussLegendre(stages=2), steps=100, in_quick=False),
        Attempt("Tsit5", diffrax.Tsit5()),
        Attempt("Kvaerno5", diffrax.Kvaerno5(), in_quick=False),
    ]  # fmt: skip
    return Case(
        f"stiff FPU chain, ω = {frequency:g}", chain, chain.initial_state(), 1.0,
        attempts, tolerance=1e-4,
    )  # fmt: skip


def near_separatrix_case() -> Case:
    """Released at 179.9°: after one exact period (AGM) it must be back at rest."""
    pendulum = SimplePendulum(amplitude=math.radians(179.9))
    period = float(pendulum.period())
    attempts = [
        Attempt("Yoshida4, 2000 steps", lj.Yoshida4(), steps=2000),
        Attempt("Yoshida4, 20000 steps", lj.Yoshida4(), steps=20000),
        Attempt("KahanLi8, 2000 steps", lj.KahanLi8(), steps=2000),
        Attempt("Tsit5, rtol 1e-8", diffrax.Tsit5()),
        Attempt("Dopri8, rtol 1e-12", diffrax.Dopri8(), rtol=1e-12),
    ]
    return Case(
        "pendulum at 179.9°, one period", pendulum, pendulum.initial_state(), period,
        attempts, tolerance=1e-4, expected=np.array([math.radians(179.9), 0.0]),
    )  # fmt: skip


def eccentric_kepler_case() -> Case:
    """e = 0.99 over 10 periods: periapsis speed 14× the mean, against Kepler's equation."""
    orbit = KeplerCartesian(eccentricity=jnp.asarray(0.99))
    t1 = 10 * float(orbit.period())
    expected = np.concatenate(
        [np.asarray(x) for x in orbit.orbit_state(jnp.asarray(t1))]
    )
    attempts = [
        Attempt("StormerVerlet, 10⁵ steps", lj.StormerVerlet(), steps=100_000),
        Attempt("Yoshida4, 10⁵ steps", lj.Yoshida4(), steps=100_000),
        Attempt("Tsit5, rtol 1e-10", diffrax.Tsit5(), rtol=1e-10),
        Attempt("Dopri8, rtol 1e-12", diffrax.Dopri8(), rtol=1e-12),
    ]
    return Case(
        "Kepler e = 0.99, 10 periods", orbit, orbit.initial_state(), t1, attempts,
        tolerance=1e-4, expected=expected,
    )  # fmt: skip


def singular_case() -> Case:
    """L = ½(q̇₁ + q̇₂)² − ½|q|²: the mass matrix is singular everywhere."""
    lag = lj.Lagrangian(lambda q, qd: 0.5 * (qd[0] + qd[1]) ** 2 - 0.5 * jnp.sum(q**2))
    attempts = [
        Attempt("Tsit5, adaptive", diffrax.Tsit5()),
        Attempt("Tsit5, fixed step", diffrax.Tsit5(), steps=100),
        Attempt("GaussLegendre(2)", lj.GaussLegendre(stages=2), steps=100),
    ]
    return Case(
        "singular mass matrix", lag, (jnp.array([1.0, 0.0]), jnp.zeros(2)), 1.0,
        attempts, tolerance=1e-4, expected=np.full(4, np.nan),
    )  # fmt: skip


def gimbal_lock_case() -> Case:
    """A free body whose Euler angle θ starts at 10⁻⁶: cond(M) ≈ 10¹³.

    The same body on quaternions (`RigidBodyYoshida4`) has no such point; the
    reference is Dopri8 on the quaternion equations at rtol = 10⁻¹².
    """
    body = TorqueFreeBody(angles0=(0.3, 1e-6, -0.4))
    rigid, start, t1 = body.rigid_body(), body.initial_body_state(), 2.0

    def final_rotation_and_rate(**options) -> jax.Array:
        trajectory = lj.simulate(rigid, start, t1=t1, **options)
        quaternion, momentum = trajectory.q[-1], trajectory.ys[1][-1]
        return jnp.concatenate(
            [quaternion_to_matrix(quaternion).ravel(), momentum / body.moments]
        )

    def quaternion_route() -> jax.Array:
        return final_rotation_and_rate(dt=t1 / 2000, solver=RigidBodyYoshida4())

    def expected() -> jax.Array:
        return final_rotation_and_rate(solver=diffrax.Dopri8(), rtol=1e-12, atol=1e-12)

    attempts = [
        Attempt("Euler angles, Dopri8", diffrax.Dopri8(), rtol=1e-10, max_steps=10**4),
        Attempt(
            "Euler angles, GaussLegendre(2)",
            lj.GaussLegendre(stages=2),
            steps=2000,
            in_quick=False,
        ),
        Attempt("quaternion, RigidBodyYoshida4", None, route=quaternion_route),
    ]
    return Case(
        "free body near gimbal lock (Euler θ = 1e-6)", body, body.initial_state(), t1,
        attempts, tolerance=1e-4, expected=expected,
        comparable=lambda q, qdot: jnp.concatenate([
            euler_zxz_to_rotation(q).ravel(), euler_zxz_body_angular_velocity(q, qdot)]),
    )  # fmt: skip
