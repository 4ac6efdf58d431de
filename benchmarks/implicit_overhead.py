"""Per-step cost of lagjax's implicit solvers against hand-written twins.

Double pendulum (m = l = 1, g = 9.81) from q = (1.2, −0.4), q̇ = (0.3, 0.1), fixed
step h = 10⁻³. lagjax runs `lj.simulate(Lagrangian(L), …, dt=h, solver=…)` on the
user's L (not declared quadratic in q̇), under `jax.jit`. The twin is the same
method with the same stage solve, written by hand on the closed-form equations:

- `GaussLegendre(stages=2)`, `ImplicitMidpoint`: Hamilton's equations in (q, p)
  with q̇ = M(q)⁻¹p from the closed-form 2×2 mass matrix, the stage increments
  Z = h A f(y₀ + Z) iterated in a `lax.while_loop` until the max-norm change is
  below 10⁻¹⁴(1 + |Z|), at most 30 iterations, started from the previous step's
  collocation polynomial, and the update added with Kahan summation — lagjax's
  method step for step, so the final angles agree to round-off (printed).
- `VariationalMidpoint`: the midpoint discrete Euler–Lagrange equation for
  Δq, solved by Newton's method (2×2 Jacobian by autodiff of the hand-written
  residual, `jnp.linalg.solve`) to a step below 10⁻¹³(1 + |Δq|).

Compile time is reported apart from run time; run time is the median of repeats
after a warm-up, with `block_until_ready`, lagjax and twin run alternately (the
machine is shared: read the ratios, not the absolute times).

Run: `python -m benchmarks.implicit_overhead [--steps N] [--repeats R]`.
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
from lagjax.demo import G  # noqa: E402
from lagjax.demo import double_pendulum as lagrangian  # noqa: E402
from lagjax.solvers.implicit import (  # noqa: E402
    GAUSS_LEGENDRE_1,
    GAUSS_LEGENDRE_2,
    CollocationTableau,
)

Q0, QDOT0 = np.array([1.2, -0.4]), np.array([0.3, 0.1])
TOLERANCE = 1e-14
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
            change = jnp.max(jnp.abs(new - z) / (TOLERANCE + TOLERANCE * jnp.abs(new)))
            return new, change, k + 1

        def unfinished(state):
            return (state[1] >= 1) & (state[2] < MAX_ITERATIONS)

        start = (h * (extrapolate @ rates), jnp.inf, 0)
        z, _, _ = jax.lax.while_loop(unfinished, iterate, start)
        corrected = weights @ z + compensation
        total = y + corrected
        return (total, corrected - (total - y), z / h), None

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

    def residual(q0, p0, dq):
        d_q0, d_dq = gradients(q0, dq)
        return (p0 + d_q0 - d_dq) / (1.0 + jnp.max(jnp.abs(p0)))

    def step(carry, _):
        q, p, cq, cp = carry
        guess = h * hamilton_rates(jnp.concatenate([q, p]))[:2]

        def iterate(state):
            dq, _, k = state
            jac = jax.jacfwd(lambda x: residual(q, p, x))(dq)
            delta = jnp.linalg.solve(jac, residual(q, p, dq))
            small = jnp.max(jnp.abs(delta) / (1e-13 + 1e-13 * jnp.abs(dq))) < 1
            return dq - delta, small, k + 1

        def unfinished(state):
            return ~state[1] & (state[2] < 32)

        dq, _, _ = jax.lax.while_loop(unfinished, iterate, (guess, False, 0))
        dp = gradients(q, dq)[0]
        (q, cq), (p, cp) = _kahan(q, dq, cq), _kahan(p, dp, cp)
        return (q, p, cq, cp), None

    def integrate(y0):
        q, p = y0[:2], y0[2:]
        zero = jnp.zeros(2)
        q, p, _, _ = jax.lax.scan(step, (q, p, zero, zero), None, length=steps)[0]
        return jnp.concatenate([q, p])

    return integrate


def _kahan(y, increment, compensation):
    corrected = increment + compensation
    total = y + corrected
    return total, corrected - (total - y)


def lagjax_run(solver, steps: int, h: float):
    system = lj.Lagrangian(lagrangian)

    def integrate(y0):
        q, p = y0[:2], y0[2:]
        qdot = system.to_hamiltonian().velocity(q, p)
        trajectory = lj.simulate(system, (q, qdot), 0.0, steps * h, dt=h, solver=solver)
        return trajectory.ys[0][-1]  # the final angles

    return integrate


def compile_and_time(functions: dict, y0, repeats: int) -> dict:
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
            start = time.perf_counter()
            jax.block_until_ready(fn(y0))
            runs[name].append(time.perf_counter() - start)
    return {
        name: (compile_times[name], statistics.median(runs[name]), compiled[name](y0))
        for name in functions
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--steps", type=int, default=20_000)
    parser.add_argument("--repeats", type=int, default=5)
    options = parser.parse_args()
    steps, h = options.steps, 1e-3
    p0 = lj.Lagrangian(lagrangian).momentum(jnp.asarray(Q0), jnp.asarray(QDOT0))
    y0 = jnp.concatenate([jnp.asarray(Q0), p0])
    cases = {
        "GaussLegendre(stages=2)": (
            lj.GaussLegendre(stages=2),
            collocation_twin(GAUSS_LEGENDRE_2, steps, h),
        ),
        "ImplicitMidpoint": (
            lj.ImplicitMidpoint(),
            collocation_twin(GAUSS_LEGENDRE_1, steps, h),
        ),
        "VariationalMidpoint": (lj.VariationalMidpoint(), variational_twin(steps, h)),
    }
    print(f"double pendulum, {steps} steps of h = {h}, single trajectory")
    print(
        f"{'solver':26s} {'variant':8s} {'compile s':>9s} {'us/step':>9s} "
        f"{'ratio':>6s} {'max |dq|':>9s}"
    )
    for name, (solver, twin) in cases.items():
        results = compile_and_time(
            {"twin": twin, "lagjax": lagjax_run(solver, steps, h)}, y0, options.repeats
        )
        twin_time, twin_state = results["twin"][1], results["twin"][2]
        for variant, (compile_time, run_time, state) in results.items():
            difference = float(jnp.max(jnp.abs(state[:2] - twin_state[:2])))
            print(
                f"{name:26s} {variant:8s} {compile_time:9.2f} "
                f"{1e6 * run_time / steps:9.2f} {run_time / twin_time:6.2f} "
                f"{difference:9.1e}"
            )


if __name__ == "__main__":
    main()
