"""What dense output and events cost, and that runs which do not ask for them pay nothing.

Kepler orbit (e = 0.6, `SeparableHamiltonian`, V = −1/|q| by autodiff), `Yoshida4`
at a fixed step over one period, each run jit-compiled once and timed as the median
of rounds over all runs:

- `final state` and `ts on the grid`: the fixed-step scan path (`fixed_step.py`),
  untouched by dense output — the baseline;
- `ts off the grid, linear`: `diffeqsolve` with the solver's own linear
  interpolation (what `simulate` did before `lagjax.solvers.hermite`);
- `ts off the grid, Hermite`, `dense=True` (+ 100 `evaluate`s), `event` (apoapsis,
  half a period): what those requests cost now.

The second table puts the fixed-step scan routes (`lagjax._integrate.scan_saving`) beside
hand-written `lax.scan` twins of the same method (Yoshida's triple jump, plain
sums, the cubic Hermite extension written out) in the same run, on Kepler and
on the pendulum, 1001 states each:

- `ts off the grid`: twin = a scan over the saves, a `while_loop` stepping to
  each save's step, the cubic between its two ends;
- `SaveAt(steps=True)`: twin = one scan stacking every state;
- `dense=True` + 1001 `evaluate`s: twin = the states stacked, the cubic between
  the two states around each time.

Measured 2026-11-25 (2-core CPU under load, `--steps 20000 --repeats 7 --clock
cpu`, lagjax / twin; before = diffeqsolve's loop with the Hermite wrapper, after =
the scans of `lagjax._integrate.scan_saving`):

| row | Kepler before → after | pendulum before → after |
|---|---|---|
| ts off the grid | 1.64 → 1.49 | 2.04 → 1.60 |
| SaveAt(steps=True) | 1.46 → 1.66 | 1.67 → 1.74 |
| dense=True + 1001 evaluate | 1.74 → 1.72 | 1.74 → 1.81 |

With the XLA CPU defaults of `lagjax._core.cpu_loops`, diffeqsolve's loop already
ran these fixed-step runs about as fast as the scans do (the differences in
steps/dense rows are within the run-to-run noise here, ±10%); the off-grid saves
gain because the scan evaluates the field at bracket steps only. The rest of the
gap to the twin is the step itself: lagjax's final-state scan alone takes
2.1–2.3 ms against the twin's 1.6 ms for stepping and stacking every state
(1.8–2.0 ms with `Yoshida4(compensated=False)`).

Re-measured 2026-11-26 (`--steps 20000 --repeats 9 --clock cpu`, medians, the
code before and after this session's changes alternated in the same session):
ts off the grid Kepler 1.30–1.39, pendulum 1.31–1.36 (unchanged: taking the
plain steps between saves with the tracking body instead of the refusing one
measured no gain, and was not kept); SaveAt(steps=True), whose loop now emits the
running state and masks the entries from a failure on after the loop, Kepler
1.16–1.21 (1.29–1.34 before), pendulum 1.08–1.19 (1.13–1.16).

    python -m benchmarks.dense_output [--steps N] [--repeats R] [--clock cpu]
"""

import argparse
import statistics
import time

import diffrax
import jax
import jax.numpy as jnp

import lagjax as lj
from benchmarks.dense_twins import TWIN_SYSTEMS, scan_rows
from benchmarks.kepler_saved import CLOCKS

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


def seconds(function, clock=time.perf_counter) -> float:
    start = clock()
    jax.block_until_ready(function(START))
    return clock() - start


def typical(compiled: dict, repeats: int, clock, start=START) -> dict:
    """Median of `repeats` rounds over all runs (a busy machine slows each run of
    a round alike). Not the fastest round: process CPU time occasionally reads far
    low on a shared machine (a 1.4 ms run once measured 0.11 ms)."""
    for function in compiled.values():
        jax.block_until_ready(function(start))  # compile
    timings = {name: [] for name in compiled}
    for _ in range(repeats):
        for name, function in compiled.items():
            begin = clock()
            jax.block_until_ready(function(start))
            timings[name].append(clock() - begin)
    return {name: statistics.median(times) for name, times in timings.items()}


def main():
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--steps", type=int, default=10_000)
    parser.add_argument("--repeats", type=int, default=15)
    parser.add_argument("--clock", choices=sorted(CLOCKS), default="wall")
    options = parser.parse_args()
    clock = CLOCKS[options.clock]
    print(f"Kepler e = {ECCENTRICITY}, Yoshida4, {options.steps} steps over a period")
    compiled = {name: jax.jit(f) for name, f in runs(options.steps).items()}
    best = typical(compiled, options.repeats, clock)
    baseline = next(iter(best.values()))
    for name, seconds_taken in best.items():
        ratio = seconds_taken / baseline
        print(f"{name:28s} {seconds_taken * 1e3:8.2f} ms  ({ratio:5.2f}×)")
    print(
        f"\nfixed-step saving vs a hand-written scan, {options.steps} steps, 1001 saves"
    )
    print(f"{'system, saving':36s} {'lagjax ms':>10s} {'twin ms':>9s} {'ratio':>6s}")
    for system in TWIN_SYSTEMS:
        for name, (ours, twin, start) in scan_rows(system, options.steps).items():
            pair = {"lagjax": jax.jit(ours), "twin": jax.jit(twin)}
            best = typical(pair, options.repeats, clock, start)
            ratio = best["lagjax"] / best["twin"]
            print(
                f"{system + ', ' + name:36s} {best['lagjax'] * 1e3:10.2f} "
                f"{best['twin'] * 1e3:9.2f} {ratio:6.2f}"
            )


if __name__ == "__main__":
    main()
