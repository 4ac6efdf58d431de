"""Work-precision with saved output: Kepler e = 0.6 over 1000 periods, 1001 states.

The question a user asks: what is the cheapest run whose energy error, at every one
of 1001 saved states, stays below 1e-10? lagjax's symplectic splittings at fixed
steps (saving on the step grid: nested scans) against diffrax's built-in adaptive
solvers (Dopri8, Tsit5) through the same `lj.simulate` with `ts`. Run time is the
median of repeats after compilation, with `block_until_ready`; the error is
max |H(t_k) − H(0)| over the saved states.

    python -m benchmarks.kepler_saved [--periods N] [--repeats R] [--level L]
"""

from __future__ import annotations

import argparse
import statistics
import time

import diffrax
import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402

import lagjax as lj  # noqa: E402

KEPLER = lj.SeparableHamiltonian(
    lambda p: 0.5 * jnp.sum(p * p), lambda q: -1.0 / jnp.sqrt(jnp.sum(q * q))
)
START = (jnp.array([0.4, 0.0]), jnp.array([0.0, 2.0]))  # e = 0.6, a = 1, T = 2π
PERIOD = 2 * jnp.pi


CLOCKS = {"wall": time.perf_counter, "cpu": time.process_time}


def measure(options, t1, ts, repeats, clock=time.perf_counter):
    """(median run seconds, max energy error over the saves, compile seconds)."""

    def run(y0):
        trajectory = lj.simulate(KEPLER, y0, t1=t1, ts=ts, **options)
        return trajectory.energy()

    start = time.perf_counter()
    compiled = jax.jit(run).lower(START).compile()
    compile_seconds = time.perf_counter() - start
    energies = jax.block_until_ready(compiled(START))
    times = []
    for _ in range(repeats):
        start = clock()
        jax.block_until_ready(compiled(START))
        times.append(clock() - start)
    error = float(jnp.max(jnp.abs(energies - KEPLER(*START))))
    return statistics.median(times), error, compile_seconds


def candidates(periods):
    for name, solver, steps_per_period in (
        ("KahanLi8", lj.KahanLi8(), (50, 100, 200, 400)),
        ("SofSpa10", lj.SofSpa10(), (25, 50, 100, 200)),
        ("Yoshida6", lj.Yoshida6(), (100, 200, 400, 800)),
    ):
        for n in steps_per_period:
            # n·periods steps, a multiple of the 1000 save intervals
            steps = max(1000, round(n * periods / 1000) * 1000)
            dt = float(periods * PERIOD / steps)
            yield f"{name} h=T/{steps // periods}", dict(solver=solver, dt=dt)
    for name, solver in (("Dopri8", diffrax.Dopri8()), ("Tsit5", diffrax.Tsit5())):
        for rtol in (1e-10, 1e-11, 1e-12, 1e-13):
            yield (
                f"{name} rtol={rtol:g}",
                dict(solver=solver, rtol=rtol, atol=rtol, max_steps=10**7),
            )


def main():
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--periods", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--level", type=float, default=1e-10)
    parser.add_argument("--clock", choices=sorted(CLOCKS), default="wall")
    options = parser.parse_args()
    t1 = float(options.periods * PERIOD)
    ts = jnp.linspace(0.0, t1, 1001)
    print(
        f"Kepler e = 0.6, {options.periods} periods, 1001 saves, level {options.level:g}"
    )
    print(f"{'run':28s} {'run s':>9s} {'max |dH|':>10s} {'compile s':>10s}")
    best = {}
    for label, run_options in candidates(options.periods):
        seconds, error, compile_seconds = measure(
            run_options, t1, ts, options.repeats, CLOCKS[options.clock]
        )
        print(f"{label:28s} {seconds:9.4f} {error:10.2e} {compile_seconds:10.2f}")
        family = "diffrax" if "rtol" in label else "lagjax"
        if error <= options.level and seconds < best.get(family, (float("inf"),))[0]:
            best[family] = (seconds, label)
    for family, (seconds, label) in best.items():
        print(f"best {family}: {label} {seconds:.4f} s")
    if len(best) == 2:
        print(f"diffrax / lagjax: {best['diffrax'][0] / best['lagjax'][0]:.1f}")


if __name__ == "__main__":
    main()
