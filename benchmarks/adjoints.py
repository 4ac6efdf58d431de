r"""Adjoint choices for a gradient through `lj.simulate`: memory and time per gradient.

The loss is $q(t_1)^2$ of an anharmonic oscillator
$H = \tfrac12 p^2 + \tfrac12 k q^2 + a q^4$ (k = 2, a = 0.1, q0 = 0.7), and the
gradient is taken with respect to the two weights (k, a) of the potential, an
equinox Module (a pytree child of the system, so the gradient reaches it). The
number of fixed steps (dt = 0.01) is varied. Variants:

- `scan`: Yoshida4 with the default adjoint: the fixed-step path is a plain
  `lax.scan` (`_Run.fits_scan`), differentiated by JAX's own reverse mode, which
  stores every step's state (memory ∝ steps).
- `checkpoint`: Yoshida4 with `diffrax.RecursiveCheckpointAdjoint()` passed
  explicitly: diffrax's loop with binomial (treeverse) checkpointing — memory
  ∝ log(steps) checkpoints at the price of recomputation.
- `checkpoint-Tsit5`, `backsolve-Tsit5`: the same with Tsit5 at the same fixed
  step; `diffrax.BacksolveAdjoint()` solves the adjoint ODE backwards (memory
  independent of steps; the gradient is that of the continuous problem, not exactly
  of the discrete one). diffrax refuses it for the splitting methods, which take
  two terms (T and V).
- `forward-Yoshida4`, `forward-Tsit5`: `diffrax.ForwardMode()` with `jax.jacfwd`:
  one tangent per parameter (cheap here, two parameters; a network's thousands of
  weights would need as many passes).
- `reversible`: Yoshida4 with `lj.ReversibleAdjoint()`: no state stored per step;
  the backward pass walks the run back by steps of −h.

`--kepler` adds the issue's case (`kepler_rows`): Kepler (e = 0.4, μ = 1) with
Störmer–Verlet or Yoshida4, a loss on the final state and 10 saved states, the
gradient with respect to y0 and μ, for `forward-only` (the loss alone, no
gradient: the reference for memory and time), `scan`, `checkpoint`,
`reversible` (the default checkpoint budget: every 1000 steps from 10³ to
1.3·10⁷ steps) and `reversible-0` (`checkpoint_bytes=0`: no checkpoints);
`--variants` picks some. Its gap column is relative to the first gradient of the
row group (`scan`).

Measured (2 shared cores, load ≈ 6, minima of 3–5): at 10⁶ steps the reversible
adjoint's temporaries are 6.9 KiB (Störmer–Verlet) and 7.2 KiB (Yoshida4),
1.9× and 1.8× the forward-only run's, against 134 MiB and 386 MiB for the
scan; its gradient takes 3.9× and 3.6× the forward run (2.8–3.8× with
checkpoints every 1000 steps), the scan's 9–10×, diffrax's checkpointing 7–18×;
its relative gap to the scan's gradient is 6.7e-9 and 1.5e-9 (2.8e-10, 3.0e-10
with checkpoints; diffrax's checkpointed loop differs from the scan by 4e-7 at
10⁶ steps, its times rounded otherwise). At 10⁴ steps it takes 0.95× (SV) and
0.33× (Yoshida4) the scan's gradient time.

On an idle core (the device machine's CPU, JAX 0.11.2, one pinned core, minima
of 9) at 10⁶ steps the reversible gradient takes 2.96× the forward run
(Störmer–Verlet, 28 ms forward) and 3.19× (Yoshida4, 73 ms), 2.90× and 3.14×
with checkpoints every 1000 steps (147 KiB of temporaries); the stage-by-stage
walk of the splittings measured the same as the generic step-back-then-vjp walk
(3.03×, 3.17×) there. For the gap column at 10⁶ steps mind that the scan's own
reverse-mode gradient is 1–3e-10 from a long-double reference
(`benchmarks/adjoint_round_off.py`).

Issue 32, second pass (this machine: 2 cores loaded by other work, JAX 0.10.2;
time as the process's CPU time on one pinned core, which waiting for the core
does not inflate (the clock `--cpu-time` selects); minima of 15, Kepler at 10⁵
steps, variants alternated):
the reversible gradient takes 2.5–3.0× the forward run for Störmer–Verlet (the
same compiled program measured 2.47× and 2.96× in two processes: the spread
between processes) and 2.5–2.6× for Yoshida4, with the default checkpoints
(18.5 KiB of temporaries at 10⁵ steps, 5.2 KiB without) no slower. A walk back
that summed each block of 4–8 steps' cotangent increments plainly and
compensated once per block cut XLA's kernels per Störmer–Verlet step from 16.8
to 14.1, but the fused kernels recomputed shared values (+47% elementwise
operations): 4.5×, so it was dropped; unrolling the walk back 2× or 4× more
than the forward loop gained nothing either (Yoshida4 2.51× → 2.81×, 2.53×;
Störmer–Verlet 2.69× → 2.72×, 2.71×, in one process). The backward step is one force and one
transposed force per stage (Kepler: 37.5 kernels per Yoshida4 step back, 18.5
forward); the rest is bookkeeping.

`--bit-reversible` runs the Kepler rows with `lj.BitReversible(solver)`, the
splitting on an integer lattice that the walk undoes to the last bit (no
checkpoints by default). Issue 32, fourth pass (2 cores loaded by two other jobs,
CPU time on one pinned core, minima of 5, 10⁶ steps): Störmer–Verlet 5.3 KiB of
temporaries against the forward run's 3.7 KiB (1.4×) and the scan's 135 MiB,
the gradient in 2.66× the forward run (157.6 against 59.2 ms), 8.6e-11 from the
scan's gradient; Yoshida4 5.8 KiB against 3.9 KiB (1.5×) and 387 MiB, 2.54×
(404.6 against 159.6 ms), 6.5e-11. The lattice run's forward costs 1.97× and
1.88× the floating-point splitting's (30.0 and 84.7 ms in the same session), so
against the floating-point forward run the gradient takes 5.2× and 4.8×. At 10⁴
steps the reversible gradient takes 0.96× (Störmer–Verlet) and 0.92× (Yoshida4)
the scan's.

Memory is XLA's temporary buffer size of the compiled gradient
(`memory_analysis().temp_size_in_bytes`); time is the median and the minimum of
repeats, variants alternated in rotating order (on a shared machine the minimum is
the steadier figure; ratios use it). Every gradient is checked against the first of its solver (`scan` for
Yoshida4, `checkpoint-Tsit5` for Tsit5): the gap column.

References: P. Kidger, *On Neural Differential Equations* (2021), §5.1 (adjoint
methods); A. Griewank, A. Walther, "Algorithm 799: revolve", ACM TOMS 26 (2000).

Run: `python -m benchmarks.adjoints [--steps 100 1000 10000] [--repeats R]`.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import jax

jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import lagjax as lj  # noqa: E402

DT = 0.01
WEIGHTS = jnp.array([2.0, 0.1])


class AnharmonicPotential(eqx.Module):
    """V(q) = ½ k q² + a q⁴ with trainable k and a."""

    stiffness: jax.Array
    anharmonicity: jax.Array

    def __call__(self, q):
        return 0.5 * self.stiffness * q**2 + self.anharmonicity * q**4


def _kinetic(p):
    return 0.5 * p**2


def final_state_loss(weights, steps: int, solver, adjoint):
    potential = AnharmonicPotential(weights[0], weights[1])
    system = lj.SeparableHamiltonian(_kinetic, potential)
    start = (jnp.asarray(0.7), jnp.asarray(0.0))
    run = lj.simulate(
        system, start, t1=steps * DT, dt=DT, solver=solver, adjoint=adjoint
    )
    return run.q[-1] ** 2


VARIANTS = {
    "scan": (lj.Yoshida4, None, jax.grad),
    "checkpoint": (lj.Yoshida4, diffrax.RecursiveCheckpointAdjoint, jax.grad),
    "checkpoint-Tsit5": (diffrax.Tsit5, diffrax.RecursiveCheckpointAdjoint, jax.grad),
    "backsolve-Tsit5": (diffrax.Tsit5, diffrax.BacksolveAdjoint, jax.grad),
    "forward-Yoshida4": (lj.Yoshida4, diffrax.ForwardMode, jax.jacfwd),
    "forward-Tsit5": (diffrax.Tsit5, diffrax.ForwardMode, jax.jacfwd),
    "reversible": (lj.Yoshida4, lj.ReversibleAdjoint, jax.grad),
}


def gradient_function(name: str, steps: int):
    solver, adjoint, differentiate = VARIANTS[name]
    adjoint_instance = None if adjoint is None else adjoint()
    return jax.jit(
        differentiate(lambda w: final_state_loss(w, steps, solver(), adjoint_instance))
    )


CLOCK = time.perf_counter  # `--cpu-time`: time.process_time


def measure(functions: dict, argument, steps: int, repeats: int, group) -> list[dict]:
    """Compile each jitted function of `functions` at `argument`, record XLA's
    temporary memory and its result's gap to the first of its `group(name)`, then
    time them alternated, the order rotated (the machine is shared and noisy)."""
    rows, compiled, reference = [], {}, {}
    for name, function in functions.items():
        start = time.perf_counter()
        compiled[name] = function.lower(argument).compile()
        compile_s = time.perf_counter() - start
        value = compiled[name](argument)
        first = reference.setdefault(group(name), value)
        gap = max(
            float(jnp.max(jnp.abs(a - b)) / jnp.max(jnp.abs(b)))
            for a, b in zip(
                jax.tree_util.tree_leaves(value), jax.tree_util.tree_leaves(first)
            )
        )
        memory = compiled[name].memory_analysis()
        rows.append(
            dict(
                steps=steps,
                variant=name,
                compile_s=compile_s,
                temp_bytes=getattr(memory, "temp_size_in_bytes", float("nan")),
                gap=gap,
                times=[],
            )
        )
    for repeat in range(repeats):
        shift = repeat % len(rows)
        for row in rows[shift:] + rows[:shift]:
            start = CLOCK()
            jax.block_until_ready(compiled[row["variant"]](argument))
            row["times"].append(CLOCK() - start)
    for row in rows:
        times = row.pop("times")
        row["median_s"], row["min_s"] = statistics.median(times), min(times)
    return rows


def run(steps_list, repeats: int) -> list[dict]:
    rows = []
    for steps in steps_list:
        functions = {name: gradient_function(name, steps) for name in VARIANTS}
        # Each solver is its own discretization: compare within a solver.
        rows += measure(functions, WEIGHTS, steps, repeats, lambda n: VARIANTS[n][0])
    return rows


KEPLER_START = jnp.array([1.0, 0.0, 0.0, jnp.sqrt(1.4)])  # q, p: e = 0.4, μ = 1
KEPLER_DT = 0.01


def _kepler_potential(q, t, mu):
    return -mu / jnp.sqrt(jnp.sum(q**2))


KEPLER = lj.SeparableHamiltonian(lambda p: 0.5 * jnp.sum(p**2), _kepler_potential)


def kepler_loss(start_and_mu, steps: int, solver, adjoint):
    """Loss on the final state and 10 saved states of a Kepler run."""
    y0 = (start_and_mu[:2], start_and_mu[2:4])
    ts = np.linspace(steps * KEPLER_DT / 10, steps * KEPLER_DT, 10)  # static
    run = lj.simulate(KEPLER, y0, t1=steps * KEPLER_DT, dt=KEPLER_DT, ts=ts,
                      solver=solver, args=start_and_mu[4], adjoint=adjoint)  # fmt: skip
    return jnp.sum(run.ys[0][:, 0]) + run.ys[0][-1, 1] ** 2 + 0.1 * jnp.sum(run.ys[1])


def kepler_functions(steps: int, solver, with_scan: bool, variants=None) -> dict:
    """The Kepler variants at `steps`: jitted functions of (q0, p0, μ)."""
    adjoints = {
        "scan": None,
        "checkpoint": diffrax.RecursiveCheckpointAdjoint(),
        "reversible": lj.ReversibleAdjoint(),
        "reversible-0": lj.ReversibleAdjoint(checkpoint_bytes=0),
    }
    if not with_scan:
        del adjoints["scan"]
    adjoints = {k: v for k, v in adjoints.items() if variants is None or k in variants}
    functions = {"forward-only": jax.jit(lambda x: kepler_loss(x, steps, solver, None))}
    for name, adjoint in adjoints.items():
        functions[name] = jax.jit(
            jax.grad(lambda x, a=adjoint: kepler_loss(x, steps, solver, a))
        )
    return functions


def kepler_rows(
    steps_list, repeats: int, solver_name: str, variants=None, bit_reversible=False
) -> list[dict]:
    solver = getattr(lj, solver_name)()
    if bit_reversible:
        solver = lj.BitReversible(solver)
    argument = jnp.concatenate([KEPLER_START, jnp.array([1.0])])
    rows = []
    for steps in steps_list:
        functions = kepler_functions(steps, solver, True, variants)
        rows += measure(
            functions, argument, steps, repeats,
            lambda n: "value" if n == "forward-only" else "gradient",
        )  # fmt: skip
    return rows


def print_rows(rows: list[dict], baseline: str) -> None:
    print(
        f"{'steps':>8s} {'variant':18s} {'temp KiB':>10s} {'ms/grad':>9s} "
        f"{'min ms':>8s} {'min vs ' + baseline:>18s} {'gradient gap':>13s}"
    )
    base = {}
    for row in rows:
        if row["variant"] == baseline:
            base[row["steps"]] = row["min_s"]
        ratio = row["min_s"] / base[row["steps"]] if row["steps"] in base else math.nan
        print(
            f"{row['steps']:8d} {row['variant']:18s} {row['temp_bytes'] / 1024:10.1f} "
            f"{1e3 * row['median_s']:9.3f} "
            f"{1e3 * row['min_s']:8.3f} "
            f"{ratio:17.2f}x {row['gap']:13.1e}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, nargs="*", default=[100, 1000, 10000])
    parser.add_argument("--repeats", type=int, default=11)
    parser.add_argument("--kepler", type=int, nargs="*", default=None,
                        help="Kepler step counts (default 10^3 10^4 10^5)")  # fmt: skip
    parser.add_argument("--solver", default="StormerVerlet")
    parser.add_argument("--variants", nargs="*", default=None,
                        help="Kepler gradients to run (default: all of scan, "
                        "checkpoint, reversible, reversible-0)")  # fmt: skip
    parser.add_argument("--bit-reversible", action="store_true",
                        help="Kepler rows with lj.BitReversible(solver): the "
                        "integer-lattice run, walked back exactly")  # fmt: skip
    parser.add_argument("--quick", action="store_true", help="CI size: seconds")
    parser.add_argument("--cpu-time", action="store_true",
                        help="time by the process's CPU time (a loaded machine, "
                        "one pinned core: waiting for the core is not counted)")  # fmt: skip
    options = parser.parse_args()
    if options.cpu_time:
        global CLOCK
        CLOCK = time.process_time
    if options.quick:
        options.steps, options.repeats = [], 2
        options.kepler = [1000] if options.kepler is None else options.kepler
    platform = jax.devices()[0].platform
    if options.steps:
        rows = run(options.steps, options.repeats)
        print(f"gradient of q(t1)^2 w.r.t. (k, a), dt = {DT}, {platform}")
        print_rows(rows, "scan")
    if options.kepler is not None:
        steps = options.kepler or [10**3, 10**4, 10**5]
        rows = kepler_rows(steps, options.repeats, options.solver, options.variants,
                           options.bit_reversible)  # fmt: skip
        print(
            f"\nKepler e = 0.4, {options.solver}, dt = {KEPLER_DT}: loss on the final "
            f"and 10 saved states, gradient w.r.t. (q0, p0, mu), {platform}; "
            "ratios to the forward-only run"
        )
        print_rows(rows, "forward-only")
        # A mark of a compensated splitting on Kepler: q, p, their compensation
        # and the force, 10 float64 numbers.
        spacings = {n: lj.ReversibleAdjoint().spacing(n, 80) for n in steps}
        print(
            "reversible: the default checkpoint budget (checkpoint_bytes = 1 MiB, a "
            "checkpoint every max(1000, n*80 B/budget) steps; spacing by steps: "
            f"{spacings}); reversible-0: no checkpoints. The forward run's own "
            "temporaries are a few KiB, so its 2x bound holds only for reversible-0, "
            "whose round-off misses 1e-10 at 10^6 steps (benchmarks/adjoint_round_off.py)"
        )


if __name__ == "__main__":
    main()
