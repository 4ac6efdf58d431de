"""What an event and dense output cost a JAX Taylor run, per step, and that a run
asking for neither pays nothing.

Pendulum θ̈ = −sin θ from θ₀ = 2 to t = 2000 (about 7000 steps at tol 1e-15),
`lagjax.taylor.taylor_integrate` jit-compiled once per configuration (compile
time reported apart), then the runs alternated over rounds (CPU time of the
process) and the best and the median of each reported as a ratio to the plain
run of the same rounds:

- `plain`: no event, no dense output (the loop as before issue 28);
- `event (never fires)`: a condition θ − 5 watched on every step (sampled at
  `lagjax.taylor.events.SAMPLES` points of each step's polynomial);
- `dense`: every step's polynomial kept (`max_steps` = 8192 rows).

Measured 2026-11-27 (`taskset -c 1`, 2-core machine under heavy load from other
jobs, load average 14, 41 rounds, CPU time; the coefficients by the scalar
graph's order map, 1.4 µs a step): event 1.03× best / 1.09× median, dense
1.09× / 1.10×. The plain loop against the code before events and dense output
(an old copy of `integrate.py` beside the new one, same process, 41 alternated
rounds): 0.995× best, 0.98× median — unchanged.

    python -m benchmarks.taylor_events_dense [--quick] [--rounds R]
"""

import argparse
import statistics
import time

import jax
import jax.numpy as jnp

from lagjax.taylor.events import StepEvent
from lagjax.taylor.integrate import taylor_integrate


def pendulum(t, y, args):
    return jnp.stack([y[1], -jnp.sin(y[0])])


def configurations(max_steps: int) -> dict:
    never = StepEvent((lambda t, y, args: y[0] - 5.0,), (0,))
    return {
        "plain": {},
        "event (never fires)": {"event": never},
        "dense": {"dense": True, "max_steps": max_steps},
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="t = 200, 3 rounds")
    parser.add_argument("--rounds", type=int, default=15)
    options = parser.parse_args()
    jax.config.update("jax_enable_x64", True)
    t1, rounds = (200.0, 3) if options.quick else (2000.0, options.rounds)
    y0 = jnp.array([2.0, 0.0])
    runs, compile_s = {}, {}
    for name, kwargs in configurations(8192).items():
        run = jax.jit(
            lambda y0, kwargs=kwargs: taylor_integrate(pendulum, y0, 0.0, t1, **kwargs)
        )
        start = time.perf_counter()
        compiled = run.lower(y0).compile()
        compile_s[name] = time.perf_counter() - start
        steps = int(compiled(y0).num_steps)
        runs[name] = compiled
    # CPU time of this process: on a loaded machine, wall time mostly measures
    # the other jobs' share of the core.
    times: dict[str, list[float]] = {name: [] for name in runs}
    for round_ in range(rounds):
        names = list(runs)[:: 1 if round_ % 2 else -1]  # no order favoured
        for name in names:
            start = time.process_time()
            jax.block_until_ready(runs[name](y0).ys)
            times[name].append(time.process_time() - start)
    plain_best, plain_median = min(times["plain"]), statistics.median(times["plain"])
    print(f"pendulum to t = {t1:g}: {steps} steps, {rounds} rounds")
    print("| run | compile s | best ms | median ms | best / plain | median / plain |")
    print("|---|---|---|---|---|---|")
    for name, values in times.items():
        best, median = min(values), statistics.median(values)
        print(
            f"| {name} | {compile_s[name]:.1f} | {1e3 * best:.2f} | {1e3 * median:.2f}"
            f" | {best / plain_best:.2f} | {median / plain_median:.2f} |"
        )


if __name__ == "__main__":
    main()
