"""Per-step cost of lagjax's implicit solvers against hand-written twins.

One row per solver: lagjax's run and a twin written by hand with the same method and
the same stage solve (same iteration, starting guess, stopping test, tolerance and
iteration limit), on the same system, so that both take the same iterations and
their final states agree to round-off (printed as max |Δq|). The ratio is lagjax's
time per step over the twin's.

Systems, at a fixed step h = 10⁻³:

- double pendulum (m = l = 1, g = 9.81) from q = (1.2, −0.4), q̇ = (0.3, 0.1);
  lagjax runs `lj.simulate(Lagrangian(L), …, dt=h, solver=…)` on the user's L (not
  declared quadratic in q̇) — the rows GaussLegendre(stages=2 and 3),
  ImplicitMidpoint and VariationalMidpoint;
- pendulum in Cartesian coordinates q = (x, y), L = ½|q̇|² − g y with the holonomic
  constraint x² + y² − 1 = 0, from 1 rad at 0.5 rad/s; lagjax runs
  `lj.simulate(Lagrangian(L, constraints=g), …, solver=Rattle())` — the row Rattle.

The twins, each a `lax.scan` over steps on a flat state:

- `GaussLegendre(stages=2, 3)`, `ImplicitMidpoint` (Gauss–Legendre, s = 2, 3, 1):
  Hamilton's equations in y = (θ₁, θ₂, p₁, p₂) with q̇ = M(q)⁻¹p from the
  closed-form 2×2 mass matrix; the stage increments Z = h A f(y₀ + Z) iterated by
  fixed point in a `lax.while_loop` until max |Z_new − Z| / (10⁻¹⁴(1 + |Z_new|)) < 1,
  at most 30 iterations, started from the previous step's collocation polynomial
  (h E Z_prev/h); update y₁ = y₀ + dᵀZ (d = bᵀA⁻¹) added with Kahan summation.
- `VariationalMidpoint`: the midpoint discrete Euler–Lagrange equation
  p₀ + ∂L_d/∂q₀ − ∂L_d/∂Δq = 0 for Δq, scaled by 1 + max|p₀|, with L_d written by
  hand; Newton's method from Δq = h q̇(q₀, p₀), the 2×2 Jacobian by `jax.jacfwd`
  of the residual solved by Cramer's rule (lagjax: LU with partial pivoting
  unrolled into scalars, `InStepLU`; both LAPACK-free), stopped as `optimistix.Newton` stops
  (step below 10⁻¹³(1 + |Δq|) and residual below 10⁻¹³), at most 32 iterations;
  q and p updated with Kahan summation.
- `Rattle`: SHAKE's multiplier Λ = h²λ/2 for the one constraint g = |q|² − 1 by
  scalar Newton on g(q₀ + Δq_free − M⁻¹Gᵀ(q₀)Λ) with its closed-form derivative
  (M = 1, Gᵀ = 2q₀), from the previous step's Λ, stopped as
  `optimistix.Newton` stops (at 10⁻¹⁴), at most 16 iterations; then the RATTLE
  momentum projection onto ġ = 0 (one scalar division); q and p updated with Kahan
  summation.

Compile time is reported apart from run time; run time is the median of repeats
after a warm-up, with `block_until_ready`, lagjax and twin run alternately. The
machine is shared: read the ratios, not the absolute times; `--clock cpu` measures
process CPU time, which a loaded machine disturbs less than wall time.

Run: `python -m benchmarks.implicit_overhead [--steps N] [--repeats R] [--clock cpu]`.
"""

from __future__ import annotations

import argparse
import statistics
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import lagjax as lj  # noqa: E402
from benchmarks.kepler_saved import CLOCKS  # noqa: E402
from lagjax.cli.demo import G  # noqa: E402
from lagjax.cli.demo import double_pendulum as lagrangian  # noqa: E402
from lagjax.solvers.implicit import (  # noqa: E402
    GAUSS_LEGENDRE_1,
    GAUSS_LEGENDRE_2,
    GAUSS_LEGENDRE_3,
    CollocationTableau,
)

Q0, QDOT0 = np.array([1.2, -0.4]), np.array([0.3, 0.1])
STAGE_TOLERANCE = 1e-14  # lagjax's default stage tolerance (GaussLegendre, Rattle)
NEWTON_TOLERANCE = 1e-13  # VariationalMidpoint's default rtol = atol
MAX_ITERATIONS = 30


def hamilton_rates(y):
    """(q̇, ṗ) of the double pendulum in closed form; y = (θ₁, θ₂, p₁, p₂)."""
    t1, t2, p1, p2 = y[0], y[1], y[2], y[3]
    c, s = jnp.cos(t1 - t2), jnp.sin(t1 - t2)
    det = 2.0 - c * c
    w1 = (p1 - c * p2) / det
    w2 = (2.0 * p2 - c * p1) / det
    pdot1 = -w1 * w2 * s - 2.0 * G * jnp.sin(t1)
    pdot2 = w1 * w2 * s - G * jnp.sin(t2)
    return jnp.stack([w1, w2, pdot1, pdot2])


def _kahan(y, increment, compensation):
    corrected = increment + compensation
    total = y + corrected
    return total, corrected - (total - y)


def newton_loop(residual, derivative_solve, guess, tolerance, max_steps):
    """x ← x − J⁻¹r(x) with `optimistix.Newton`'s stopping test: the step below
    tolerance·(1 + |x|) and the residual below tolerance (max norms)."""

    def iterate(state):
        x, _, k = state
        value = residual(x)
        step = derivative_solve(x, value)
        small = jnp.max(jnp.abs(step) / (tolerance + tolerance * jnp.abs(x))) < 1
        converged = small & (jnp.max(jnp.abs(value)) < tolerance)
        return x - step, converged, k + 1

    def unfinished(state):
        return ~state[1] & (state[2] < max_steps)

    start = (guess, jnp.asarray(False), 0)
    return jax.lax.while_loop(unfinished, iterate, start)[0]


def collocation_twin(tableau: CollocationTableau, steps: int, h: float):
    """The Gauss–Legendre step by hand: fixed-point stages, extrapolated guess,
    compensated update (the method of `lagjax.solvers.implicit`)."""
    a = jnp.asarray(tableau.a)
    weights = jnp.asarray(tableau.update_weights())
    extrapolate = jnp.asarray(tableau.extrapolation())

    def stages(y, z):
        return h * (a @ jnp.stack([hamilton_rates(y + z_i) for z_i in z]))

    def step(carry, _):
        y, compensation, rates = carry

        def iterate(state):
            z, _, k = state
            new = stages(y, z)
            scale = STAGE_TOLERANCE + STAGE_TOLERANCE * jnp.abs(new)
            return new, jnp.max(jnp.abs(new - z) / scale), k + 1

        def unfinished(state):
            return (state[1] >= 1) & (state[2] < MAX_ITERATIONS)

        start = (h * (extrapolate @ rates), jnp.inf, 0)
        z, _, _ = jax.lax.while_loop(unfinished, iterate, start)
        y, compensation = _kahan(y, weights @ z, compensation)
        return (y, compensation, z / h), None

    def integrate(y0):
        rates = jnp.zeros((len(tableau.b), 4))
        carry = (y0, jnp.zeros(4), rates)
        return jax.lax.scan(step, carry, None, length=steps)[0][0]

    return integrate


def variational_twin(steps: int, h: float):
    """The midpoint variational integrator by hand, Newton on Δq."""

    def discrete(q0, dq):
        mid, v = q0 + 0.5 * dq, dq / h
        kinetic = v[0] ** 2 + 0.5 * v[1] ** 2 + v[0] * v[1] * jnp.cos(mid[0] - mid[1])
        return h * (kinetic + G * (2.0 * jnp.cos(mid[0]) + jnp.cos(mid[1])))

    gradients = jax.grad(discrete, argnums=(0, 1))

    def step(carry, _):
        q, p, cq, cp = carry
        scale = 1.0 + jnp.max(jnp.abs(p))

        def residual(dq):
            d_q0, d_dq = gradients(q, dq)
            return (p + d_q0 - d_dq) / scale

        def solve(dq, value):
            # The 2 × 2 Newton system by Cramer's rule, as one writes it by hand
            # (`jnp.linalg.solve`, a LAPACK call, kept the loop body from being
            # one kernel: 2.7 µs/step against lagjax's 0.8).
            (a, b), (c, d) = jax.jacfwd(residual)(dq)
            det = a * d - b * c
            return (
                jnp.stack([d * value[0] - b * value[1], a * value[1] - c * value[0]])
                / det
            )

        guess = h * hamilton_rates(jnp.concatenate([q, p]))[:2]
        dq = newton_loop(residual, solve, guess, NEWTON_TOLERANCE, 32)
        dp = gradients(q, dq)[0]
        (q, cq), (p, cp) = _kahan(q, dq, cq), _kahan(p, dp, cp)
        return (q, p, cq, cp), None

    def integrate(y0):
        q, p = y0[:2], y0[2:]
        zero = jnp.zeros(2)
        q, p, _, _ = jax.lax.scan(step, (q, p, zero, zero), None, length=steps)[0]
        return jnp.concatenate([q, p])

    return integrate


def pendulum_on_circle(q, qdot):
    """Unit mass at q = (x, y), gravity along −y (the constraint keeps |q| = 1)."""
    return 0.5 * jnp.sum(qdot**2) - G * q[1]


def on_circle(q):
    return jnp.stack([jnp.sum(q**2) - 1.0])


ANGLE, RATE = 1.0, 0.5
CIRCLE_START = np.array(
    [np.sin(ANGLE), -np.cos(ANGLE), RATE * np.cos(ANGLE), RATE * np.sin(ANGLE)]
)


def rattle_twin(steps: int, h: float):
    """RATTLE by hand on the pendulum on a circle (M = 1, G(q) = 2qᵀ)."""
    force = jnp.array([0.0, -G])

    def step(carry, _):
        q, p, multiplier, cq, cp = carry
        half_kick_free = 0.5 * h * force
        free = h * (p + half_kick_free)
        direction = 2.0 * q  # M⁻¹Gᵀ

        def defect(x):
            moved = q + free - direction * x
            return jnp.sum(moved**2) - 1.0

        def solve(x, value):
            return value / (-2.0 * jnp.dot(q + free - direction * x, direction))

        multiplier = newton_loop(defect, solve, multiplier, STAGE_TOLERANCE, 16)
        q1, cq = _kahan(q, free - direction * multiplier, cq)
        kick = half_kick_free - 2.0 * q * multiplier / h + 0.5 * h * force
        normal = 2.0 * q1
        mu = jnp.dot(normal, p + kick) / jnp.dot(normal, normal)
        p1, cp = _kahan(p, kick - normal * mu, cp)
        return (q1, p1, multiplier, cq, cp), None

    def integrate(y0):
        zero = jnp.zeros(2)
        carry = (y0[:2], y0[2:], jnp.zeros(()), zero, zero)
        q, p = jax.lax.scan(step, carry, None, length=steps)[0][:2]
        return jnp.concatenate([q, p])

    return integrate


def lagjax_run(solver, steps: int, h: float):
    system = lj.Lagrangian(lagrangian)

    def integrate(y0):
        q, p = y0[:2], y0[2:]
        qdot = system.to_hamiltonian().velocity(q, p)
        trajectory = lj.simulate(system, (q, qdot), 0.0, steps * h, dt=h, solver=solver)
        return trajectory.ys[0][-1]  # the final angles

    return integrate


def lagjax_rattle_run(steps: int, h: float):
    system = lj.Lagrangian(pendulum_on_circle, constraints=on_circle)

    def integrate(y0):
        start = (y0[:2], y0[2:])  # M = 1: p = q̇
        trajectory = lj.simulate(
            system, start, 0.0, steps * h, dt=h, solver=lj.Rattle()
        )
        return trajectory.ys[0][-1]  # the final position

    return integrate


def compile_and_time(functions: dict, y0, repeats: int, clock) -> dict:
    """{name: (compile s, median run s, final state)}, variants run alternately."""
    compiled, compile_times = {}, {}
    for name, fn in functions.items():
        start = time.perf_counter()
        compiled[name] = jax.jit(fn).lower(y0).compile()
        compile_times[name] = time.perf_counter() - start
        jax.block_until_ready(compiled[name](y0))
    runs: dict[str, list[float]] = {name: [] for name in functions}
    for _ in range(repeats):
        for name, fn in compiled.items():
            start = clock()
            jax.block_until_ready(fn(y0))
            runs[name].append(clock() - start)
    return {
        name: (compile_times[name], statistics.median(runs[name]), compiled[name](y0))
        for name in functions
    }


def cases(steps: int, h: float) -> dict:
    """{solver name: (lagjax run, twin, start state)}."""
    p0 = lj.Lagrangian(lagrangian).momentum(jnp.asarray(Q0), jnp.asarray(QDOT0))
    y0 = jnp.concatenate([jnp.asarray(Q0), p0])
    return {
        "GaussLegendre(stages=2)": (
            lagjax_run(lj.GaussLegendre(stages=2), steps, h),
            collocation_twin(GAUSS_LEGENDRE_2, steps, h),
            y0,
        ),
        "GaussLegendre(stages=3)": (
            lagjax_run(lj.GaussLegendre(stages=3), steps, h),
            collocation_twin(GAUSS_LEGENDRE_3, steps, h),
            y0,
        ),
        "ImplicitMidpoint": (
            lagjax_run(lj.ImplicitMidpoint(), steps, h),
            collocation_twin(GAUSS_LEGENDRE_1, steps, h),
            y0,
        ),
        "VariationalMidpoint": (
            lagjax_run(lj.VariationalMidpoint(), steps, h),
            variational_twin(steps, h),
            y0,
        ),
        "Rattle (pendulum on circle)": (
            lagjax_rattle_run(steps, h),
            rattle_twin(steps, h),
            jnp.asarray(CIRCLE_START),
        ),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--steps", type=int, default=20_000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--clock", choices=sorted(CLOCKS), default="wall")
    parser.add_argument("--only", help="run only solvers whose name contains this")
    options = parser.parse_args()
    steps, h = options.steps, 1e-3
    print(f"{steps} steps of h = {h}, single trajectory, {options.clock} clock")
    print(
        f"{'solver':28s} {'twin us':>8s} {'lagjax us':>9s} {'ratio':>6s} "
        f"{'compile s (twin/lagjax)':>24s} {'max |dq|':>9s}"
    )
    for name, (run, twin, y0) in cases(steps, h).items():
        if options.only and options.only.lower() not in name.lower():
            continue
        results = compile_and_time(
            {"twin": twin, "lagjax": run}, y0, options.repeats, CLOCKS[options.clock]
        )
        (twin_compile, twin_time, twin_state) = results["twin"]
        (lagjax_compile, lagjax_time, lagjax_state) = results["lagjax"]
        difference = float(jnp.max(jnp.abs(lagjax_state[:2] - twin_state[:2])))
        print(
            f"{name:28s} {1e6 * twin_time / steps:8.2f} "
            f"{1e6 * lagjax_time / steps:9.2f} {lagjax_time / twin_time:6.2f} "
            f"{twin_compile:11.2f} / {lagjax_compile:10.2f} {difference:9.1e}"
        )


if __name__ == "__main__":
    main()
