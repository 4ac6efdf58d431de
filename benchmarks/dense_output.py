"""What dense output and events cost, and that runs which do not ask for them pay nothing.

Kepler orbit (e = 0.6, `SeparableHamiltonian`, V = −1/|q| by autodiff), `Yoshida4`
at a fixed step over one period, each run jit-compiled once and timed as the fastest
of rounds over all runs:

- `final state` and `ts on the grid`: the fixed-step scan path (`fixed_step.py`),
  untouched by dense output — the baseline;
- `ts off the grid, linear`: `diffeqsolve` with the solver's own linear
  interpolation (what `simulate` did before `lagjax.hermite`);
- `ts off the grid, Hermite`, `dense=True` (+ 100 `evaluate`s), `event` (apoapsis,
  half a period): what those requests cost now.

    python -m benchmarks.dense_output [--steps N] [--repeats R]
"""

import argparse
import time

import diffrax
import jax
import jax.numpy as jnp

import lagjax as lj

jax.config.update("jax_enable_x64", True)

KEPLER = lj.SeparableHamiltonian(
    lambda p: 0.5 * jnp.sum(p**2), lambda q: -1.0 / jnp.linalg.norm(q)
)
ECCENTRICITY = 0.6
START = (
    jnp.array([1.0 - ECCENTRICITY, 0.0]),
    jnp.array([0.0, jnp.sqrt((1 + ECCENTRICITY) / (1 - ECCENTRICITY))]),
)
PERIOD = 2 * jnp.pi


def radial_velocity(t, y, args, **kwargs):
    return jnp.dot(y[0], y[1])


def runs(steps: int) -> dict:
    dt = float(PERIOD) / steps
    on_grid = jnp.linspace(0.0, float(PERIOD), 101)
    off_grid = on_grid[:-1] + 0.37 * dt
    solver = lj.Yoshida4()

    def simulate(y0, **kwargs):
        return lj.simulate(KEPLER, y0, t1=float(PERIOD), dt=dt, solver=solver, **kwargs)

    def linear(y0):
        terms, state0, _ = KEPLER.integration(solver, y0, 0.0, None)
        solution = diffrax.diffeqsolve(
            terms, solver, 0.0, float(PERIOD), dt, state0,
            saveat=diffrax.SaveAt(ts=off_grid), max_steps=steps + 1,
        )  # fmt: skip
        return solution.ys

    return {
        "final state (scan)": lambda y0: simulate(y0).ys,
        "ts on the grid (scan)": lambda y0: simulate(y0, ts=on_grid).ys,
        "ts off the grid, linear": linear,
        "ts off the grid, Hermite": lambda y0: simulate(y0, ts=off_grid).ys,
        "dense=True + 100 evaluate": lambda y0: simulate(y0, dense=True).evaluate(
            off_grid
        ),
        "event (apoapsis)": lambda y0: (
            simulate(y0, event=diffrax.Event(radial_velocity, direction=False)).ys
        ),
    }


def seconds(function) -> float:
    start = time.perf_counter()
    jax.block_until_ready(function(START))
    return time.perf_counter() - start


def main():
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--steps", type=int, default=10_000)
    parser.add_argument("--repeats", type=int, default=15)
    options = parser.parse_args()
    print(f"Kepler e = {ECCENTRICITY}, Yoshida4, {options.steps} steps over a period")
    compiled = {name: jax.jit(f) for name, f in runs(options.steps).items()}
    for function in compiled.values():
        seconds(function)  # compile
    # Rounds over all runs, so a busy machine slows each alike; the fastest of
    # the rounds is the cost of the run itself.
    timings = {name: [] for name in compiled}
    for _ in range(options.repeats):
        for name, function in compiled.items():
            timings[name].append(seconds(function))
    baseline = min(next(iter(timings.values())))
    for name, times in timings.items():
        best = min(times)
        print(f"{name:28s} {best * 1e3:8.2f} ms  ({best / baseline:5.2f}×)")


if __name__ == "__main__":
    main()
