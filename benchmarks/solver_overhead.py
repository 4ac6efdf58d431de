"""Overhead of `lj.simulate` and `diffrax.diffeqsolve` vs a hand-written scan.

Kepler orbit with e = 0.6, 10⁵ fixed steps of `StormerVerlet` and `Yoshida4`, one
trajectory and a vmapped batch of 1024. `lj.simulate` runs a
`SeparableHamiltonian` (force by autodiff of V = −1/|q|), taking its fixed-step
scan path; `diffeqsolve` runs the same solver with hand-written terms, and "fixed"
runs lagjax's fixed-step scan path on those hand-written terms (the loop and solver
overhead alone, without derivation). The twin is the same method written as a
`jax.lax.scan` over steps that carries the force between steps (first-same-as-
last): updating q and p in place, as one would write it by hand, or, for the
compensated solvers, with the same Kahan-summed increments. Compile time is
measured separately from run time (median of repeats after a warm-up, the two
variants run alternately so a busy machine slows both alike).

With `--saves N` every run saves N + 1 states on the step grid (t = 0 included):
`simulate` with `ts = linspace(0, T, N + 1)`, diffeqsolve with `SaveAt(ts=...)`, the
twin with a nested scan. The benchmarks ask XLA's CPU backend to compile whole loop
bodies (`lagjax.enable_fast_cpu_loops`, in `benchmarks/__init__.py`;
`LAGJAX_PLAIN_CPU_LOOPS=1` leaves it off): the header says whether it is in effect,
and it applies to every column alike.

The last column, sim/plain, is simulate over the uncompensated twin of the same
method (for a compensated solver: what Kahan summation and the loop cost together).

    python -m benchmarks.solver_overhead [--steps N] [--batch B] [--repeats R] [--saves N]
"""

import argparse
import statistics
import time

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

import lagjax as lj
from lagjax._core.cpu_loops import fast_cpu_loops_requested
from lagjax._integrate.fixed_step_loop import (
    integrate_fixed_steps,
    integrate_fixed_steps_saving,
)
from lagjax.solvers.compensated import compensated_add, zero_compensation
from lagjax.solvers.splitting import StormerVerlet, Yoshida4

jax.config.update("jax_enable_x64", True)

KEPLER_Q0, KEPLER_P0 = np.array([0.4, 0.0]), np.array([0.0, 2.0])


def kepler_force(q):
    r_squared = jnp.sum(q * q, axis=-1, keepdims=True)
    return -q / (r_squared * jnp.sqrt(r_squared))


# The hand-written terms (dq/dt = p, dp/dt = F(q)) for diffrax's splitting solvers.
KEPLER_TERMS = (
    diffrax.ODETerm(lambda t, p, args: p),
    diffrax.ODETerm(lambda t, q, args: kepler_force(q)),
)


def save_times(steps, dt, saves):
    """`saves` + 1 times on the step grid, t = 0 included (None: final state only)."""
    return None if saves is None else jnp.linspace(0.0, steps * dt, saves + 1)


def diffrax_run(solver, steps, dt, saves=None):
    ts = save_times(steps, dt, saves)
    saveat = diffrax.SaveAt(t1=True) if ts is None else diffrax.SaveAt(ts=ts)

    def run(q0, p0):
        sol = diffrax.diffeqsolve(
            KEPLER_TERMS,
            solver,
            0.0,
            steps * dt,
            dt,
            (q0, p0),
            saveat=saveat,
            stepsize_controller=diffrax.ConstantStepSize(),
            max_steps=steps,
        )
        assert sol.ys is not None
        return sol.ys

    return run


KEPLER = lj.SeparableHamiltonian(
    lambda p: 0.5 * jnp.sum(p * p), lambda q: -1.0 / jnp.sqrt(jnp.sum(q * q))
)


def fixed_step_run(solver, steps, dt, saves=None):
    """lagjax's fixed-step scan path with the hand-written terms: loop overhead only."""

    def run(q0, p0):
        if saves is None:
            y, _, _ = integrate_fixed_steps(
                KEPLER_TERMS, solver, 0.0, steps * dt, dt, (q0, p0), None
            )
        else:
            grid = (0, steps // saves, saves + 1)
            y, *_ = integrate_fixed_steps_saving(
                KEPLER_TERMS, solver, 0.0, dt, grid, (q0, p0), None
            )
        return y

    return run


def simulate_run(solver, steps, dt, saves=None):
    ts = save_times(steps, dt, saves)

    def run(q0, p0):
        trajectory = lj.simulate(
            KEPLER, (q0, p0), t1=steps * dt, dt=dt, solver=solver, ts=ts
        )
        return trajectory.ys

    return run


def scan_run(solver, steps, dt, saves=None):
    """The hand-written twin: kick, (drift, kick)… with the force carried over;
    with `saves`, a nested scan that saves (q, p) every `steps // saves` steps.

    For a compensated solver the twin is compensated too (same method): it sums
    the step's increments and adds them to the state with Kahan's sum.
    """
    kicks, drifts = solver.kick_coefficients, solver.drift_coefficients

    def increments(q, p, force):
        dp = kicks[0] * dt * force
        dq = 0.0
        for drift, kick in zip(drifts, kicks[1:], strict=True):
            dq = dq + drift * dt * (p + dp)
            force = kepler_force(q + dq)
            dp = dp + kick * dt * force
        return dq, dp, force

    def plain_step(carry, _):
        q, p, force = carry
        p = p + kicks[0] * dt * force
        for drift, kick in zip(drifts, kicks[1:], strict=True):
            q = q + drift * dt * p
            force = kepler_force(q)
            p = p + kick * dt * force
        return (q, p, force), None

    def compensated_step(carry, _):
        q, p, force, compensation = carry
        dq, dp, force = increments(q, p, force)
        (q, p), compensation = compensated_add((q, p), (dq, dp), compensation)
        return (q, p, force, compensation), None

    step = compensated_step if solver.compensated else plain_step

    def run(q0, p0):
        start = (q0, p0, kepler_force(q0))
        if solver.compensated:
            start = (*start, zero_compensation((q0, p0)))
        if saves is None:
            (q, p, *_), _ = jax.lax.scan(step, start, None, length=steps)
            return q, p

        def interval(carry, _):
            carry, _ = jax.lax.scan(step, carry, None, length=steps // saves)
            return carry, carry[:2]

        _, (qs, ps) = jax.lax.scan(interval, start, None, length=saves)
        return jnp.concatenate([q0[None], qs]), jnp.concatenate([p0[None], ps])

    return run


def compile_timed(function, arguments):
    """(compiled function, seconds spent compiling)."""
    start = time.perf_counter()
    compiled = jax.jit(function).lower(*arguments).compile()
    return compiled, time.perf_counter() - start


CLOCKS = {"wall": time.perf_counter, "cpu": time.process_time}
clock = CLOCKS["wall"]


def run_seconds(compiled, arguments):
    """Seconds of one run by `clock`: wall time, or this process's CPU time (all
    its threads), which a machine shared with other jobs disturbs far less."""
    start = clock()
    jax.block_until_ready(compiled(*arguments))
    return clock() - start


def initial_states(batch):
    if batch is None:
        return jnp.asarray(KEPLER_Q0), jnp.asarray(KEPLER_P0)
    # Slightly different eccentricities, so no two lanes are identical.
    speeds = 2.0 * (1 + 0.01 * jnp.linspace(-1, 1, batch))
    q0 = jnp.tile(jnp.asarray(KEPLER_Q0), (batch, 1))
    p0 = jnp.stack([jnp.zeros(batch), speeds], axis=-1)
    return q0, p0


def compare(solver, steps, batch, repeats, saves=None):
    """{name: (compile seconds, median run seconds)} for simulate, the fixed-step
    loop, diffeqsolve, the twin of the same method and the uncompensated ("plain")
    twin. All are run alternately, so a busy machine slows them alike.
    """
    dt = 2 * np.pi / 100
    arguments = initial_states(batch)
    compiled, compile_seconds = {}, {}
    plain = type(solver)(compensated=False)
    makers = (
        ("simulate", simulate_run, solver),
        ("fixed", fixed_step_run, solver),
        ("diffrax", diffrax_run, solver),
        ("scan", scan_run, solver),
        ("plain scan", scan_run, plain),
    )
    for name, make, method in makers:
        function = make(method, steps, dt, saves)
        if batch is not None:
            function = jax.vmap(function)
        compiled[name], compile_seconds[name] = compile_timed(function, arguments)
        run_seconds(compiled[name], arguments)  # warm-up
    runs = {name: [] for name in compiled}
    for _ in range(repeats):
        for name in compiled:
            runs[name].append(run_seconds(compiled[name], arguments))
    return {
        name: (compile_seconds[name], statistics.median(runs[name]))
        for name in compiled
    }


def main():
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--steps", type=int, default=100_000)
    parser.add_argument("--batch", type=int, default=1024, help="0: single only")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument(
        "--saves",
        type=int,
        default=None,
        help="save this many states on the step grid (default: final state only)",
    )
    parser.add_argument("--clock", choices=sorted(CLOCKS), default="wall")
    options = parser.parse_args()
    global clock
    clock = CLOCKS[options.clock]
    if options.saves is not None and options.steps % options.saves:
        parser.error("--steps must be a multiple of --saves")
    solvers = {
        "StormerVerlet": StormerVerlet(),
        "StormerVerlet(compensated=False)": StormerVerlet(compensated=False),
        "Yoshida4": Yoshida4(),
        "Yoshida4(compensated=False)": Yoshida4(compensated=False),
    }
    saving = "final state" if options.saves is None else f"{options.saves} saves"
    print(
        f"{options.steps} steps, {saving}, Kepler e = 0.6, device {jax.devices()[0]}, "
        f"fast CPU loops {fast_cpu_loops_requested()}, {options.clock} clock"
    )
    header = f"{'solver':34s} {'batch':>6s} {'compile sim/dfx/scan [s]':>25s}"
    print(
        f"{header} {'simulate':>10s} {'diffeqsolve':>12s} {'scan':>10s} "
        f"{'sim/scan':>8s} {'dfx/scan':>8s} {'fixed/scan':>10s} {'sim/plain':>9s}"
    )
    for batch in (None, options.batch) if options.batch else (None,):
        for label, solver in solvers.items():
            rows = compare(solver, options.steps, batch, options.repeats, options.saves)
            (c_sim, r_sim), (c_d, r_d), (c_s, r_s) = (
                rows["simulate"],
                rows["diffrax"],
                rows["scan"],
            )
            compiles = f"{c_sim:.2f}/{c_d:.2f}/{c_s:.2f}"
            print(
                f"{label:34s} {batch or 1:6d} {compiles:>25s} {r_sim * 1e3:8.1f}ms "
                f"{r_d * 1e3:10.1f}ms {r_s * 1e3:8.1f}ms {r_sim / r_s:8.2f} "
                f"{r_d / r_s:8.2f} {rows['fixed'][1] / r_s:10.2f} "
                f"{r_sim / rows['plain scan'][1]:9.2f}"
            )


if __name__ == "__main__":
    main()
