"""Cost of deriving the equations of motion by autodiff, against hand-written ones.

Double pendulum (m = l = 1, g = 9.81), 10⁴ fixed RK4 steps inside `jax.lax.scan`,
single trajectory and vmapped over a batch of initial states. The right-hand side is
(a) the hand-written equations of motion, or (b) `lj.Lagrangian(L).acceleration` for
L written two ways a user would write it: with indexing (`q[0]`, `q[1]`) and in
matrix form (`qd @ M(q) @ qd`), with `check=False` as integration loops call it, and
once with the default `check=True` (a run-time singular-mass-matrix branch per call). Compile time is reported apart from run time; run
time is the median of repeats after a warm-up, with `block_until_ready`.

Run: `python -m benchmarks.derivation_overhead [--steps N] [--batch B] [--repeats R]`.
"""

from __future__ import annotations

import argparse
import statistics
import time
from functools import partial

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402

import lagjax as lj  # noqa: E402

# The demo's L, written with indexing (`q[0]`, `q[1]`), and the textbook closed form
# of its equations of motion (m = l = 1, g = G = 9.81).
from lagjax.demo import G, handwritten_acceleration  # noqa: E402
from lagjax.demo import double_pendulum as lagrangian_indexed  # noqa: E402


def lagrangian_matrix(q, qd):
    c = jnp.cos(q[0] - q[1])
    mass = jnp.array([[2.0, c], [c, 1.0]])
    potential = -G * (2.0 * jnp.cos(q[0]) + jnp.cos(q[1]))
    return 0.5 * qd @ mass @ qd - potential


def rk4_integrator(acceleration, steps: int, dt: float):
    def rhs(y):
        q, qd = y
        return qd, acceleration(q, qd)

    def step(y, _):
        k1 = rhs(y)
        k2 = rhs(jax.tree_util.tree_map(lambda a, b: a + 0.5 * dt * b, y, k1))
        k3 = rhs(jax.tree_util.tree_map(lambda a, b: a + 0.5 * dt * b, y, k2))
        k4 = rhs(jax.tree_util.tree_map(lambda a, b: a + dt * b, y, k3))
        y = jax.tree_util.tree_map(
            lambda a, b1, b2, b3, b4: a + dt / 6 * (b1 + 2 * b2 + 2 * b3 + b4),
            y,
            k1,
            k2,
            k3,
            k4,
        )
        return y, None

    def integrate(q0, qd0):
        return jax.lax.scan(step, (q0, qd0), None, length=steps)[0]

    return integrate


def measure(fn, *inputs, repeats: int) -> tuple[float, float]:
    """(compile seconds, median run seconds)."""
    start = time.perf_counter()
    compiled = jax.jit(fn).lower(*inputs).compile()
    compile_time = time.perf_counter() - start
    jax.block_until_ready(compiled(*inputs))
    runs = []
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(compiled(*inputs))
        runs.append(time.perf_counter() - start)
    return compile_time, statistics.median(runs)


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--steps", type=int, default=10_000)
    parser.add_argument("--batch", type=int, default=1024)
    parser.add_argument("--repeats", type=int, default=5)
    options = parser.parse_args()

    dt = 1e-3
    q0 = jnp.array([1.2, -0.4])
    qd0 = jnp.array([0.3, 0.1])
    key = jax.random.PRNGKey(0)
    q0s = q0 + 0.1 * jax.random.normal(key, (options.batch, 2))
    qd0s = jnp.broadcast_to(qd0, (options.batch, 2))

    indexed = lj.Lagrangian(lagrangian_indexed)
    matrix = lj.Lagrangian(lagrangian_matrix)
    candidates = {
        "hand-written": handwritten_acceleration,
        "L with q[0] indexing": partial(indexed.acceleration, check=False),
        "L as qd @ M(q) @ qd": partial(matrix.acceleration, check=False),
        "q[0] indexing, check=True": indexed.acceleration,
    }
    reference_state = None
    baseline: dict[str, float] = {}
    print(f"double pendulum, {options.steps} RK4 steps, batch {options.batch}")
    print(
        f"{'right-hand side':32s} {'mode':8s} {'compile s':>9s} {'run ms':>10s} {'ratio':>6s}"
    )
    for name, acceleration in candidates.items():
        single = rk4_integrator(acceleration, options.steps, dt)
        batched = jax.vmap(single)
        for mode, fn, inputs in (
            ("single", single, (q0, qd0)),
            ("batched", batched, (q0s, qd0s)),
        ):
            compile_time, run_time = measure(fn, *inputs, repeats=options.repeats)
            baseline.setdefault(mode, run_time)
            ratio = run_time / baseline[mode]
            print(
                f"{name:32s} {mode:8s} {compile_time:9.2f} {1e3 * run_time:10.2f} "
                f"{ratio:6.2f}"
            )
        final = single(q0, qd0)
        if reference_state is None:
            reference_state = final
        difference = max(
            float(jnp.max(jnp.abs(a - b)))
            for a, b in zip(
                jax.tree_util.tree_leaves(final),
                jax.tree_util.tree_leaves(reference_state),
            )
        )
        print(
            f"{'':32s} max |state - hand-written state| after the run: {difference:.1e}"
        )


if __name__ == "__main__":
    main()
