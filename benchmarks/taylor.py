r"""The JAX-native Taylor integrator (`lagjax.taylor`) on the double pendulum.

Issue 28's cases, one core pinned, medians of repeated runs with compilation
timed apart, every figure in one run, times in the process's CPU time:

- one trajectory, m = l = 1, g = 9.81, θ = (0.5, 0.3), θ̇ = 0, to t = 100 at
  tolerances 1e-12 and 1e-15: run time, steps, error against a reference (heyoka
  in long double when installed, else this integrator at order 26, tol 1e-16);
- diffrax Dopri8 through `lj.simulate` at rtol = atol = 1e-14 beside it;
- heyoka's `taylor_adaptive` at the same tolerances, when installed;
- 1024 trajectories (θ₁ ∈ [0.1, 1], θ₂ = 0.3) to t = 10 under `jax.vmap` of the
  one-trajectory loop, by the batch-native loop
  (`lagjax.taylor.batch.taylor_integrate_batch`: the scalar graph, the batch on
  the minor axis, one order, a step per member), and as users write it,
  `jax.jit(jax.vmap(simulate(..., solver=lj.Taylor())))` (which runs the batch
  loop, `lagjax.taylor.vmap_rule`), also at a higher order than the tolerance's,
  beside heyoka's batch mode at its SIMD width at tol and 5 tol when installed,
  timed in turn;
- the compiled program's size: HLO instructions and fusions (XLA CPU kernels).

`--quick` runs a reduced version (compilation dominates: about half a minute) (t = 10, one tolerance, 8 members).
Run from the repository root: `python -m benchmarks.taylor [--quick]`.

References: Jorba & Zou, Experimental Mathematics 14 (2005); Biscani & Izzo,
MNRAS 504 (2021).
"""

from __future__ import annotations

import argparse
import os
import re
import time
from collections.abc import Callable

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

import lagjax as lj
from lagjax._core.cpu_loops import enable_fast_cpu_loops
from lagjax.taylor import taylor_integrate
from lagjax.taylor.batch import taylor_integrate_batch

G = 9.81
Q0 = (0.5, 0.3)
# CPU time of this process, not wall time: on the shared 2-core machine another
# process's load or a preemption then does not enter the figures (the process is
# pinned to one core, so its threads' time is the core's).
clock = time.process_time


def _lagrangian(q, qdot, t, args):
    (a, b), (wa, wb) = q, qdot
    kinetic = wa**2 + 0.5 * wb**2 + wa * wb * jnp.cos(a - b)
    return kinetic + 2 * G * jnp.cos(a) + G * jnp.cos(b)


LAGRANGIAN = lj.Lagrangian(_lagrangian)


def vector_field(t, y, args):
    q, qdot = y[:2], y[2:]
    return jnp.concatenate([qdot, LAGRANGIAN.acceleration(q, qdot, t, args)])


def timed(run: Callable, *inputs, repeats: int) -> tuple[float, float, object]:
    """(first call s, median later call s, result)."""
    start = clock()
    out = jax.block_until_ready(run(*inputs))
    first = clock() - start
    times = []
    for _ in range(repeats):
        start = clock()
        out = jax.block_until_ready(run(*inputs))
        times.append(clock() - start)
    return first, float(np.median(times)), out


def kernel_census(run: Callable, *inputs) -> tuple[int, int]:
    """(HLO instructions, fusions) of the compiled program."""
    text = run.lower(*inputs).compile().as_text()
    instructions = len(re.findall(r"^\s+(?:ROOT )?%\S+ = ", text, flags=re.M))
    fusions = len(re.findall(r"= \S+ fusion\(", text))
    return instructions, fusions


def heyoka_runs(t1: float, tolerances, repeats: int):
    """{tol: (median s, final state)} and a long-double reference, or None."""
    try:
        import heyoka as hy
    except ImportError:
        return None, None
    a, b, wa, wb = hy.make_vars("a", "b", "wa", "wb")
    lagrangian = wa**2 + 0.5 * wb**2 + wa * wb * hy.cos(a - b)
    lagrangian += 2 * G * hy.cos(a) + G * hy.cos(b)
    system = hy.lagrangian(lagrangian, [a, b], [wa, wb])
    start = [*Q0, 0.0, 0.0]
    reference = hy.taylor_adaptive(
        system,
        np.array(start, np.longdouble),
        fp_type=np.longdouble,
        tol=np.longdouble(1e-19),
    )
    reference.propagate_until(np.longdouble(t1))
    runs = {}
    for tol in tolerances:
        integrator = hy.taylor_adaptive(system, start, tol=tol)
        times = []
        for _ in range(repeats):
            integrator.time, integrator.state[:] = 0.0, start
            begin = clock()
            integrator.propagate_until(t1)
            times.append(clock() - begin)
        runs[tol] = (float(np.median(times)), np.array(integrator.state))
    return runs, np.array(reference.state, dtype=np.float64)


def single(t1: float, tolerances, repeats: int) -> None:
    y0 = jnp.array([*Q0, 0.0, 0.0])
    peers, reference = heyoka_runs(t1, tolerances, repeats)
    if reference is None:
        reference = taylor_integrate(
            vector_field, y0, 0.0, t1, rtol=1e-16, atol=1e-16, order=26
        ).ys[-1]
    print(
        f"one trajectory to t = {t1}; reference: {'heyoka long double' if peers else 'Taylor p=26'}"
    )
    for tol in tolerances:
        run = jax.jit(
            lambda y, tol=tol: taylor_integrate(
                vector_field, y, 0.0, t1, rtol=tol, atol=tol
            )
        )
        first, median, solution = timed(run, y0, repeats=repeats)
        error = float(jnp.max(jnp.abs(solution.ys[-1] - reference)))
        instructions, fusions = kernel_census(run, y0)
        line = (
            f"  Taylor tol {tol:.0e}: p = {solution.order}, {int(solution.num_steps)} steps, "
            f"{median * 1e3:.2f} ms (first call {first:.1f} s), error {error:.1e}; "
            f"HLO {instructions} instructions, {fusions} fusions"
        )
        if peers:
            seconds, state = peers[tol]
            heyoka_error = float(np.max(np.abs(state - reference)))
            line += f"; heyoka {seconds * 1e3:.2f} ms, error {heyoka_error:.1e} (ratio {median / seconds:.2f})"
        print(line)
    dopri = jax.jit(
        lambda y: lj.simulate(
            LAGRANGIAN,
            (y[:2], y[2:]),
            t1=t1,
            solver=diffrax.Dopri8(),
            rtol=1e-14,
            atol=1e-14,
            max_steps=1_000_000,
        )
    )
    first, median, trajectory = timed(dopri, y0, repeats=repeats)
    state = jnp.concatenate([trajectory.q[-1], trajectory.qdot[-1]])
    error = float(jnp.max(jnp.abs(state - reference)))
    print(
        f"  Dopri8 1e-14 (lj.simulate): {median * 1e3:.2f} ms (first call {first:.1f} s), error {error:.1e}"
    )


def heyoka_batch(y0s: np.ndarray, t1: float, tol: float) -> Callable | None:
    """heyoka's batch mode at its SIMD width: a call returning the final states,
    or None without heyoka."""
    try:
        import heyoka as hy
    except ImportError:
        return None
    a, b, wa, wb = hy.make_vars("a", "b", "wa", "wb")
    lagrangian = wa**2 + 0.5 * wb**2 + wa * wb * hy.cos(a - b)
    lagrangian += 2 * G * hy.cos(a) + G * hy.cos(b)
    width = hy.recommended_simd_size()
    integrator = hy.taylor_adaptive_batch(
        hy.lagrangian(lagrangian, [a, b], [wa, wb]),
        np.repeat(y0s[0][:, None], width, axis=1),
        tol=tol,
    )

    return in_blocks(integrator, y0s, t1, width)


def in_blocks(integrator, y0s: np.ndarray, t1: float, width: int) -> Callable:
    """A call that runs the members `y0s` (B, n) to `t1` through a heyoka batch
    integrator, a block of `width` at a time, and returns the final states."""

    def run():
        out = np.empty_like(y0s)
        for start in range(0, len(y0s), width):
            integrator.set_time(np.zeros(width))
            integrator.state[:] = y0s[start : start + width].T
            integrator.propagate_until(t1)
            out[start : start + width] = integrator.state.T
        return out

    return run


def interleaved_medians(calls: list[Callable], repeats: int) -> list[float]:
    """Medians of warm calls taken in turn, so that a change in the machine's
    load falls on every route alike (their ratios are the figures)."""
    times: list[list[float]] = [[] for _ in calls]
    for _ in range(repeats):
        for call, row in zip(calls, times):
            start = clock()
            jax.block_until_ready(call())
            row.append(clock() - start)
    return [float(np.median(row)) for row in times]


def batch(t1: float, size: int, tol: float, repeats: int, tuned_order: int) -> None:
    """The batch: heyoka's batch mode at `tol` and at 5 tol (its error is about
    tol); `taylor_integrate_batch` and `jax.jit(jax.vmap(simulate))` at `tol` with
    the order from the tolerance, and the latter at `tuned_order` (the batch
    loop's cost per order has a large fixed part, so a higher order with fewer
    steps costs less at equal accuracy); all timed in turn, ratios in one run.
    `vmap(taylor_integrate)` (the one-trajectory loop batched by XLA) is timed
    apart, once."""
    y0s = jnp.stack(
        [
            jnp.linspace(0.1, 1.0, size),
            jnp.full(size, Q0[1]),
            jnp.zeros(size),
            jnp.zeros(size),
        ],
        1,
    )
    reference = jax.jit(
        jax.vmap(
            lambda y: taylor_integrate(
                vector_field, y, 0.0, t1, rtol=1e-16, atol=1e-16, order=26
            ).ys[-1]
        )
    )(y0s)
    print(f"batch of {size} to t = {t1}, tol {tol:.0e} (reference: Taylor p=26)")

    def simulated(order):
        def final(y):
            solver = lj.Taylor(rtol=tol, atol=tol, order=order)
            run = lj.simulate(LAGRANGIAN, (y[:2], y[2:]), t1=t1, solver=solver)
            return jnp.concatenate([run.q[-1], run.qdot[-1]])

        return jax.jit(jax.vmap(final))

    routes = {
        "taylor_integrate_batch": jax.jit(
            lambda y: taylor_integrate_batch(
                vector_field, y, 0.0, t1, rtol=tol, atol=tol
            ).ys[:, -1]
        ),
        "jit(vmap(simulate(Taylor)))": simulated(None),
        f"jit(vmap(simulate(Taylor(order={tuned_order}))))": simulated(tuned_order),
    }
    names, calls, notes = [], [], []
    peers = 0
    for peer_tol in (tol, 5 * tol):
        peer = heyoka_batch(np.asarray(y0s), t1, peer_tol)
        if peer is not None:
            names.append(f"heyoka batch mode tol {peer_tol:.0e}")
            calls.append(peer)
            notes.append("")
            peers += 1
    for name, run in routes.items():
        start = clock()
        jax.block_until_ready(run(y0s))
        first = clock() - start
        _, fusions = kernel_census(run, y0s)
        names.append(name)
        calls.append(lambda run=run: run(y0s))
        notes.append(f", first call {first:.1f} s, {fusions} fusions")
    medians = interleaved_medians(calls, repeats)
    for name, call, seconds, note in zip(names, calls, medians, notes):
        error = float(np.max(np.abs(np.asarray(call()) - np.asarray(reference))))
        ratio = f" ({seconds / medians[0]:.2f}x heyoka at tol)" if peers else ""
        print(
            f"  {name}: {seconds * 1e3:.1f} ms{ratio}, "
            f"{seconds / size * 1e6:.1f} µs per member, error {error:.1e}{note}"
        )
    plain = jax.jit(
        jax.vmap(
            lambda y: taylor_integrate(vector_field, y, 0.0, t1, rtol=tol, atol=tol).ys[
                -1
            ]
        )
    )
    first, seconds, final = timed(plain, y0s, repeats=1)
    error = float(jnp.max(jnp.abs(final - reference)))
    print(
        f"  vmap(taylor_integrate), apart: {seconds * 1e3:.1f} ms, error {error:.1e}, "
        f"first call {first:.1f} s"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a few seconds' version")
    options = parser.parse_args()
    enable_fast_cpu_loops()  # before the first JAX computation (2x on these loops)
    # one core, as the peers (Linux): the one `taskset` gave, else the first
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    jax.config.update("jax_enable_x64", True)
    whole_loops = "xla_cpu_small_while_loop_byte_threshold" in os.environ.get(
        "XLA_FLAGS", ""
    )
    print(f"XLA whole-loop CPU option: {whole_loops}")
    if options.quick:
        single(10.0, (1e-12,), repeats=2)
        batch(1.0, 8, 1e-12, repeats=2, tuned_order=19)
    else:
        single(100.0, (1e-12, 1e-15), repeats=7)
        batch(10.0, 1024, 1e-12, repeats=5, tuned_order=19)


if __name__ == "__main__":
    main()
