r"""Members per second on an accelerator: the double pendulum at 10⁴–10⁶ trajectories.

What a GPU buys lagjax where its CPU peers (heyoka, REBOUND) have none: one
`jax.jit(jax.vmap(simulate))` over a large ensemble. The double pendulum
(m = l = 1, g = 9.81, θ₁ ∈ [0.1, 1], θ₂ = 0.3, from rest) to t = 10, three
routes, each at several batch sizes:

- `lj.Taylor(rtol=atol=1e-12)`, the JAX-native Taylor route (adaptive order and
  step per member) under `jax.vmap`, and its batch-native loop
  (`lagjax.taylor.batch.taylor_integrate_batch`: one order, a step per member,
  the batch on the minor axis);
- `diffrax.Dopri8` at rtol = atol = 1e-12 through `lj.simulate`;
- `diffrax.Tsit5` at a fixed step h = 1e-3 (10⁴ steps, lagjax's fixed-step scan
  path).

Each row: compile time, the median of repeated runs (`block_until_ready`), members
per second, and the largest difference of the final angles from the Taylor run
at 1e-14 on the first 64 members (the accuracy the rate is bought at). Run from
the repository root: `python -m benchmarks.gpu_throughput [--quick]`; on a CPU
the same script measures the CPU (the device is printed).
"""

from __future__ import annotations

import argparse
import time

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

import lagjax as lj
from benchmarks.taylor import LAGRANGIAN, vector_field  # the same double pendulum
from lagjax.taylor.batch import taylor_integrate_batch

T1 = 10.0


def initial_states(members: int) -> tuple[jax.Array, jax.Array]:
    theta1 = jnp.linspace(0.1, 1.0, members)
    q0 = jnp.stack([theta1, jnp.full_like(theta1, 0.3)], axis=-1)
    return q0, jnp.zeros_like(q0)


def route(name: str):
    """The batched run of one route: (q0s, qdot0s) -> final angles."""
    if name == "taylor-batch":  # batch-native: one order, a step per member

        def batch(q0s, qdot0s):
            y0s = jnp.concatenate([q0s, qdot0s], axis=-1)
            solution = taylor_integrate_batch(
                vector_field, y0s, 0.0, T1, rtol=1e-12, atol=1e-12
            )
            return solution.ys[:, -1, :2]

        return jax.jit(batch)
    options = {
        "taylor": dict(solver=lj.Taylor(rtol=1e-12, atol=1e-12)),
        "taylor-ref": dict(solver=lj.Taylor(rtol=1e-14, atol=1e-14)),
        "dopri8": dict(solver=diffrax.Dopri8(), rtol=1e-12, atol=1e-12),
        "tsit5-fixed": dict(solver=diffrax.Tsit5(), dt=1e-3),
    }[name]

    def one(q0, qdot0):
        return lj.simulate(LAGRANGIAN, (q0, qdot0), t1=T1, **options).q[-1]

    return jax.jit(jax.vmap(one))


def measure(name: str, members: int, repeats: int) -> dict:
    run = route(name)
    y0 = initial_states(members)
    start = time.perf_counter()
    out = jax.block_until_ready(run(*y0))
    compile_and_first = time.perf_counter() - start
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(run(*y0))
        times.append(time.perf_counter() - start)
    median = float(np.median(times))
    return dict(
        route=name,
        members=members,
        first_s=compile_and_first,
        run_s=median,
        per_second=members / median,
        final=np.asarray(out),
    )


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small batches only")
    parser.add_argument(
        "--budget", type=float, default=60.0,
        help="skip a route's next size when it would take longer than this (s)",
    )  # fmt: skip
    parser.add_argument(
        "--routes", default="taylor-batch,taylor,dopri8,tsit5-fixed",
        help="comma-separated routes to measure, in order",
    )  # fmt: skip
    options = parser.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    sizes = [256, 1024] if options.quick else [10_000, 100_000, 1_000_000]
    print(f"device: {jax.devices()[0].device_kind} ({jax.default_backend()})")
    reference = route("taylor-ref")
    print(f"{'route':>11} {'members':>9} {'first s':>8} {'run s':>8} "
          f"{'members/s':>11} {'max |Δθ| (64)':>14}")  # fmt: skip
    for name in options.routes.split(","):
        compile_s, seconds_per_member = 0.0, 0.0  # from the last size measured
        for members in sizes:
            # Compilation does not grow with the batch, and a GPU's run time grows
            # more slowly than the batch until it is full: linear is an upper bound.
            predicted = compile_s + 4 * seconds_per_member * members  # 1 + 3 repeats
            if predicted > options.budget:
                print(f"{name:>11} {members:>9} skipped: about {predicted:.0f} s")
                continue
            try:
                row = measure(name, members, repeats=1 if members > 10**5 else 3)
            except Exception as error:  # report and go on (out of memory)
                print(f"{name:>11} {members:>9} failed: {type(error).__name__}: "
                      f"{str(error).splitlines()[0][:120]}")  # fmt: skip
                continue
            compile_s = row["first_s"] - row["run_s"]
            seconds_per_member = row["run_s"] / members
            picks = np.linspace(0, members - 1, 64).astype(int)
            q0, qdot0 = initial_states(members)
            exact = np.asarray(reference(q0[picks], qdot0[picks]))
            error = np.max(np.abs(row["final"][picks] - exact))
            print(f"{name:>11} {members:>9} {row['first_s']:8.2f} {row['run_s']:8.3f} "
                  f"{row['per_second']:11.3g} {error:14.2e}")  # fmt: skip


if __name__ == "__main__":
    main()
