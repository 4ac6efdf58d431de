"""Constrained equations of motion by autodiff and multipliers, against hand-written.

A double pendulum in Cartesian coordinates, q = (x₁, y₁, x₂, y₂), two unit masses
under gravity, kept on their unit rods by the holonomic constraints
g₁ = x₁² + y₁² − 1 = 0 and g₂ = (x₂ − x₁)² + (y₂ − y₁)² − 1 = 0. lagjax's
`Lagrangian(L, constraints=g).acceleration` derives M = ∂²L/∂q̇², the constraint
Jacobian A = ∂g/∂q and the bias β = q̇ᵀ g_qq q̇ by autodiff and solves the
saddle-point system (M, Aᵀ; A, 0) at every evaluation (Goldstein §2.4; Hairer,
Lubich & Wanner §VII.1). The hand-written twin is what one writes knowing M = I:
q̈ = a + Aᵀλ with the 2 × 2 system (A Aᵀ) λ = −β − A a solved by Cramer's rule.

Each right-hand side drives the same fixed-step RK4 `lax.scan`
(`benchmarks.derivation_overhead.rk4_integrator`), one trajectory and vmapped
over a batch of starts; variants are run alternately, compile time apart. lagjax
is measured with its default arguments (under a trace a singular saddle matrix
makes q̈ NaN, one select), with `check=True` (a run-time error branch per call)
and with `check=False` (no test).

Then `lj.simulate` as users run it (Tsit5, fixed steps, projected onto the
constraints after every step, `lagjax.solvers.projection`) against diffrax's Tsit5
on the hand-written equations *without* projection — a lower bound, not a twin:
its constraint residual drifts, which the table shows beside the time.

Run: `python -m benchmarks.constrained_overhead [--steps 2000] [--batch 64]
[--repeats 7] [--clock cpu]`.
"""

from __future__ import annotations

import argparse
import statistics
from functools import partial

import jax

jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import lagjax as lj  # noqa: E402
from benchmarks.derivation_overhead import alternating_runs, rk4_integrator  # noqa: E402
from benchmarks.kepler_saved import CLOCKS  # noqa: E402
from lagjax.cli.demo import G  # noqa: E402


def cartesian_lagrangian(q, qd):
    return 0.5 * jnp.sum(qd**2) - G * (q[1] + q[3])


def rods(q):
    return jnp.array(
        [q[0] ** 2 + q[1] ** 2 - 1.0, (q[2] - q[0]) ** 2 + (q[3] - q[1]) ** 2 - 1.0]
    )


def handwritten_acceleration(q, qd):
    """q̈ = a + Aᵀλ, (A Aᵀ)λ = −β − A a, for M = I and the two rods above."""
    x1, y1, x2, y2 = q[0], q[1], q[2], q[3]
    u1, v1, u2, v2 = qd[0], qd[1], qd[2], qd[3]
    dx, dy, du, dv = x2 - x1, y2 - y1, u2 - u1, v2 - v1
    # Rows of A = ∂g/∂q: (2x₁, 2y₁, 0, 0) and (−2dx, −2dy, 2dx, 2dy); a = (0, −G, 0, −G).
    rhs1 = -2.0 * (u1**2 + v1**2) + 2.0 * G * y1
    rhs2 = -2.0 * (du**2 + dv**2)  # A₂a = 2G dy − 2G dy = 0
    k11 = 4.0 * (x1**2 + y1**2)
    k12 = -4.0 * (x1 * dx + y1 * dy)
    k22 = 8.0 * (dx**2 + dy**2)
    det = k11 * k22 - k12**2
    lam1 = (k22 * rhs1 - k12 * rhs2) / det
    lam2 = (k11 * rhs2 - k12 * rhs1) / det
    return jnp.stack(
        [
            2.0 * x1 * lam1 - 2.0 * dx * lam2,
            -G + 2.0 * y1 * lam1 - 2.0 * dy * lam2,
            2.0 * dx * lam2,
            -G + 2.0 * dy * lam2,
        ]
    )


def start(theta1: float, theta2: float) -> jax.Array:
    x1, y1 = jnp.sin(theta1), -jnp.cos(theta1)
    return jnp.stack([x1, y1, x1 + jnp.sin(theta2), y1 - jnp.cos(theta2)])


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--batch", type=int, default=64)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--clock", choices=sorted(CLOCKS), default="wall")
    options = parser.parse_args()
    lagrangian = lj.Lagrangian(cartesian_lagrangian, constraints=rods)
    candidates = {
        "hand-written": handwritten_acceleration,
        "lagjax, default": lagrangian.acceleration,
        "lagjax, check=True": partial(lagrangian.acceleration, check=True),
        "lagjax, check=False": partial(lagrangian.acceleration, check=False),
    }
    angles = jnp.linspace(0.3, 1.2, options.batch)
    batched_inputs = (
        jax.vmap(start)(angles, 1.5 * angles),
        jnp.zeros((options.batch, 4)),
    )
    print(f"Cartesian double pendulum, {options.steps} RK4 steps (dt = 1e-3), "
          f"batch {options.batch}, {options.clock} clock")  # fmt: skip
    print(f"{'right-hand side':22s} {'mode':8s} {'compile s':>9s} {'ms':>8s} "
          f"{'ratio':>6s}")  # fmt: skip
    for mode, inputs in (
        ("single", (start(0.5, 0.9), jnp.zeros(4))),
        ("batched", batched_inputs),
    ):
        functions = {}
        for name, acceleration in candidates.items():
            single = rk4_integrator(acceleration, options.steps, 1e-3)
            functions[name] = single if mode == "single" else jax.vmap(single)
        results = alternating_runs(
            functions, inputs, options.repeats, CLOCKS[options.clock]
        )
        base = results["hand-written"][1]
        for name, (compile_time, run_time) in results.items():
            print(f"{name:22s} {mode:8s} {compile_time:9.2f} {1e3 * run_time:8.2f} "
                  f"{run_time / base:6.2f}")  # fmt: skip
        final = {name: jax.jit(fn)(*inputs) for name, fn in functions.items()}
        difference = max(
            float(jnp.max(jnp.abs(a - b)))
            for name in candidates
            for a, b in zip(final[name], final["hand-written"])
        )
        print(f"{'':22s} max |state − hand-written state|: {difference:.1e}")
    simulate_rows(options.steps, options.repeats, CLOCKS[options.clock])


def simulate_rows(steps: int, repeats: int, clock) -> None:
    """`lj.simulate` (projected Tsit5) against unprojected Tsit5 on the hand-written
    equations, one trajectory, dt = 1e-3."""
    lagrangian = lj.Lagrangian(cartesian_lagrangian, constraints=rods)
    dt, y0 = 1e-3, (start(0.5, 0.9), jnp.zeros(4))

    def projected(y):
        run = lj.simulate(lagrangian, y, t1=steps * dt, dt=dt, solver=diffrax.Tsit5())
        return run.q[-1]

    @jax.jit
    def unprojected(y):
        term = diffrax.ODETerm(lambda t, y, a: (y[1], handwritten_acceleration(*y)))
        solution = diffrax.diffeqsolve(
            term, diffrax.Tsit5(), 0.0, steps * dt, dt, y, max_steps=steps + 1
        )
        return solution.ys[0][-1]

    times: dict[str, list[float]] = {"simulate": [], "unprojected": []}
    finals = {"simulate": projected(y0), "unprojected": unprojected(y0)}
    for _ in range(repeats):
        for name, fn in (("simulate", projected), ("unprojected", unprojected)):
            began = clock()
            jax.block_until_ready(fn(y0))
            times[name].append(clock() - began)
    base = statistics.median(times["unprojected"])
    print(f"\nsimulate, Tsit5, {steps} steps of 1e-3, one trajectory")
    for name, label in (
        ("unprojected", "diffrax Tsit5, hand-written, no projection"),
        ("simulate", "lj.simulate, projected"),
    ):
        median = statistics.median(times[name])
        residual = float(jnp.max(jnp.abs(rods(finals[name]))))
        print(f"{label:44s} {1e3 * median:8.2f} ms {median / base:6.2f}  "
              f"max |g| at the end {residual:.1e}")  # fmt: skip


if __name__ == "__main__":
    main()
