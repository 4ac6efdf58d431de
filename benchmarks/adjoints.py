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
import statistics
import time

import jax

jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402

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
}


def gradient_function(name: str, steps: int):
    solver, adjoint, differentiate = VARIANTS[name]
    adjoint_instance = None if adjoint is None else adjoint()
    return jax.jit(
        differentiate(lambda w: final_state_loss(w, steps, solver(), adjoint_instance))
    )


def run(steps_list, repeats: int) -> list[dict]:
    rows = []
    for steps in steps_list:
        compiled, reference = {}, {}
        for name in VARIANTS:
            start = time.perf_counter()
            compiled[name] = gradient_function(name, steps).lower(WEIGHTS).compile()
            compile_s = time.perf_counter() - start
            gradient = compiled[name](WEIGHTS)
            # Each solver is its own discretization: compare within a solver.
            solver = VARIANTS[name][0]
            reference.setdefault(solver, gradient)
            memory = compiled[name].memory_analysis()
            rows.append(
                dict(
                    steps=steps,
                    variant=name,
                    compile_s=compile_s,
                    temp_bytes=getattr(memory, "temp_size_in_bytes", float("nan")),
                    gap=float(jnp.max(jnp.abs(gradient - reference[solver]))),
                    times=[],
                )
            )
        batch = rows[-len(VARIANTS) :]
        for repeat in range(repeats):
            # Alternated, the order rotated: the machine is shared and noisy.
            shift = repeat % len(batch)
            for row in batch[shift:] + batch[:shift]:
                start = time.perf_counter()
                jax.block_until_ready(compiled[row["variant"]](WEIGHTS))
                row["times"].append(time.perf_counter() - start)
    for row in rows:
        times = row.pop("times")
        row["median_s"], row["min_s"] = statistics.median(times), min(times)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, nargs="+", default=[100, 1000, 10000])
    parser.add_argument("--repeats", type=int, default=11)
    options = parser.parse_args()
    rows = run(options.steps, options.repeats)
    print(f"gradient of q(t1)^2 w.r.t. (k, a), dt = {DT}, {jax.devices()[0].platform}")
    print(
        f"{'steps':>6s} {'variant':18s} {'temp KiB':>10s} {'ms/grad':>9s} "
        f"{'min ms':>8s} {'min vs scan':>11s} {'gradient gap':>13s}"
    )
    scan_time = {}
    for row in rows:
        if row["variant"] == "scan":
            scan_time[row["steps"]] = row["min_s"]
        print(
            f"{row['steps']:6d} {row['variant']:18s} {row['temp_bytes'] / 1024:10.1f} "
            f"{1e3 * row['median_s']:9.3f} "
            f"{1e3 * row['min_s']:8.3f} "
            f"{row['min_s'] / scan_time[row['steps']]:10.2f}x {row['gap']:13.1e}"
        )


if __name__ == "__main__":
    main()
