"""First-call time of `lj.simulate` against `diffrax.diffeqsolve` on hand-written equations.

A first call traces the run, compiles it with XLA and runs it; in a notebook or a
script that runs once, that is the whole cost. Each measurement is a fresh Python
process (imports and input arrays excluded from the time), the variants
alternated, the median reported. Three runs, each against `diffeqsolve` with the
same solver on hand-written equations, jitted as one function of `y0`:

| case | lagjax | hand-written twin |
|---|---|---|
| Tsit5, adaptive, rtol = atol = 1e-8, t ∈ [0, 10] | `simulate(Lagrangian(L))`, the demo's double pendulum | `diffeqsolve` on its textbook equations of motion |
| Dopri8, same | same | same |
| Yoshida4, 4000 fixed steps, 101 states saved on the step grid (`ts`) | `simulate(SeparableHamiltonian(T, V))`, Kepler e = 0.6 over 10 periods | `diffeqsolve` of the splitting on the hand-written drift p and kick −q/|q|³ |

(Yoshida4 needs a separable H, which the double pendulum is not.) For each the
number of XLA compilations (jax's `backend_compile` events) is counted, and a
second call with a new `y0` of the same shape is timed: it should compile nothing.

    python -m benchmarks.first_call [--repeats R] [--clock wall|cpu]

`--clock cpu` times process CPU time (all threads), robust on a loaded machine.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys

from benchmarks.kepler_saved import CLOCKS

# One measurement, run as `python -c` in a fresh process. Prints one JSON line.
_PROGRAM = """
import json
import jax
jax.config.update("jax_enable_x64", True)
import diffrax, jax.numpy as jnp, numpy as np
from jax._src import monitoring
import lagjax as lj
from benchmarks.kepler_saved import CLOCKS
from lagjax.cli.demo import double_pendulum, handwritten_acceleration

compiles = []
monitoring.register_event_duration_secs_listener(
    lambda name, seconds, **kw: compiles.append(name) if "backend_compile" in name else None
)
clock = CLOCKS["{clock}"]
case, variant = "{case}", "{variant}"
if case == "Yoshida4":
    solver, dt = lj.Yoshida4(), 20 * np.pi / 4000
    y0 = (np.array([0.4, 0.0]), np.array([0.0, 2.0]))
    ts = np.linspace(0.0, 20 * np.pi, 101)
    kepler = lj.SeparableHamiltonian(
        lambda p: 0.5 * jnp.sum(p * p), lambda q: -1.0 / jnp.sqrt(jnp.sum(q * q))
    )
    terms = (
        diffrax.ODETerm(lambda t, p, args: p),
        diffrax.ODETerm(lambda t, q, args: -q / jnp.sum(q * q) ** 1.5),
    )
    simulate = lambda y0: lj.simulate(kepler, y0, 0.0, 20 * np.pi, dt=dt, solver=solver, ts=ts).ys
    hand = jax.jit(lambda y0: diffrax.diffeqsolve(
        terms, solver, 0.0, 20 * np.pi, dt, y0, saveat=diffrax.SaveAt(ts=ts), max_steps=4001
    ).ys)
else:
    solver = getattr(diffrax, case)()
    y0 = (np.array([1.2, -0.4]), np.array([0.3, 0.1]))
    lagrangian = lj.Lagrangian(double_pendulum)
    term = diffrax.ODETerm(lambda t, y, args: (y[1], handwritten_acceleration(*y)))
    controller = diffrax.PIDController(rtol=1e-8, atol=1e-8)
    simulate = lambda y0: lj.simulate(lagrangian, y0, 0.0, 10.0, solver=solver).ys
    hand = jax.jit(lambda y0: diffrax.diffeqsolve(
        term, solver, 0.0, 10.0, None, y0, stepsize_controller=controller,
        max_steps=100_000
    ).ys)
run = simulate if variant == "simulate" else hand
row = {{}}
for call, start in (("first", y0), ("second", jax.tree.map(lambda x: x + 0.01, y0))):
    compiles.clear()
    begin = clock()
    jax.block_until_ready(run(start))
    row[call], row[call + "_compiles"] = clock() - begin, len(compiles)
print(json.dumps(row))
"""

CASES = ("Tsit5", "Dopri8", "Yoshida4")
VARIANTS = {"hand": "diffeqsolve, hand-written", "simulate": "lj.simulate, derived"}


def measure(case: str, variant: str, clock: str) -> dict:
    """One fresh-process measurement: first and second call seconds, compilations."""
    code = _PROGRAM.format(case=case, variant=variant, clock=clock)
    output = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True
    )
    if output.returncode:
        raise RuntimeError(output.stderr)
    return json.loads(output.stdout.splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--clock", choices=sorted(CLOCKS), default="wall")
    parser.add_argument("--cases", nargs="*", default=list(CASES), choices=CASES)
    options = parser.parse_args()
    rows = {(c, v): [] for c in options.cases for v in VARIANTS}
    for _ in range(options.repeats):
        for case in options.cases:
            for variant in VARIANTS:
                rows[case, variant].append(measure(case, variant, options.clock))
    print(f"first call (trace + compile + run), fresh process, {options.clock} clock,")
    print(f"median of {options.repeats}; second call: new y0 of the same shape")
    print(f"{'solver':9s} {'variant':26s} {'first s':>8s} {'ratio':>6s} "
          f"{'compiles':>8s} {'second ms':>9s} {'compiles':>8s}")  # fmt: skip
    for case in options.cases:
        base = statistics.median(r["first"] for r in rows[case, "hand"])
        for variant, label in VARIANTS.items():
            runs = rows[case, variant]
            first = statistics.median(r["first"] for r in runs)
            second = statistics.median(r["second"] for r in runs)
            print(f"{case:9s} {label:26s} {first:8.2f} {first / base:6.2f} "
                  f"{max(r['first_compiles'] for r in runs):8d} {1e3 * second:9.1f} "
                  f"{max(r['second_compiles'] for r in runs):8d}")  # fmt: skip


if __name__ == "__main__":
    main()
