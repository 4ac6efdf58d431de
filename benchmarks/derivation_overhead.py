"""Cost of deriving the equations of motion by autodiff, against hand-written ones.

Double pendulum (m = l = 1, g = 9.81), 10⁴ fixed RK4 steps inside `jax.lax.scan`,
single trajectory and vmapped over a batch of initial states. The right-hand side is
(a) the hand-written equations of motion, or (b) `lj.Lagrangian(L).acceleration` for
L written two ways a user would write it: with indexing (`q[0]`, `q[1]`) and in
matrix form (`qd @ M(q) @ qd`), with `check=False` as integration loops call it,
with the default (under a trace a singular mass matrix makes q̈ NaN, one select),
and with `check=True` (a run-time singular-mass-matrix branch per call). Compile
time is reported apart from run time; run time is the median of repeats after a
warm-up, with `block_until_ready`.

n-link pendulum (unit masses and rods), L written vector-style with `jnp.cumsum`
over the link velocities, 2·10³ RK4 steps, single and vmapped over 64 states: the
default `Lagrangian(L).acceleration` (scalar formulation up to 6 coordinates —
cofactor solve up to 3, unrolled LDLᵀ beyond —, dense beyond 6 with a Cholesky
solve; both fall back to LU only for an indefinite or singular M) against
hand-written twins with the closed-form mass matrix
M_ij = (n − max(i, j)) cos(θ_i − θ_j) solved by Cholesky (`cho_factor`/`cho_solve`)
or by LU (`jnp.linalg.solve`); the ratio is to the faster twin, and a closing
table lists it per size (single and batched) with the twin that was faster.

First call (trace + compile + run, each in a fresh process, variants alternated):
`simulate` with Tsit5 / Dopri8 on the derived double pendulum against
`diffeqsolve` on the hand-written equations with the same solver, and, to say where
the time goes, `diffeqsolve` on the derived acceleration (the derivation's share).

Run: `python -m benchmarks.derivation_overhead [--steps N] [--batch B] [--repeats R]
[--links 2 4 6 12 24 32] [--first-call-repeats R] [--skip-double-pendulum]
[--clock cpu] [--link-batch B]` (`--links` / repeats 0 skip a part; `--clock cpu`
times the n-link rows in process CPU time, robust on a loaded machine;
`--link-batch 0` runs the n-link rows for one trajectory only: from n ≈ 32 the
batched Cholesky twin can hang jaxlib 0.10.2's LAPACK thread pool, see the README).
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time
from functools import partial

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import jax.scipy.linalg as jsl  # noqa: E402
import numpy as np  # noqa: E402

import lagjax as lj  # noqa: E402
from benchmarks.kepler_saved import CLOCKS  # noqa: E402

# The demo's L, written with indexing (`q[0]`, `q[1]`), and the textbook closed form
# of its equations of motion (m = l = 1, g = G = 9.81).
from lagjax.cli.demo import G, handwritten_acceleration  # noqa: E402
from lagjax.cli.demo import double_pendulum as lagrangian_indexed  # noqa: E402


def lagrangian_matrix(q, qd):
    c = jnp.cos(q[0] - q[1])
    mass = jnp.array([[2.0, c], [c, 1.0]])
    potential = -G * (2.0 * jnp.cos(q[0]) + jnp.cos(q[1]))
    return 0.5 * qd @ mass @ qd - potential


def rk4_integrator(acceleration, steps: int, dt: float):
    def rhs(y):
        q, qd = y
        return qd, acceleration(q, qd)

    def step(y, _):
        k1 = rhs(y)
        k2 = rhs(jax.tree_util.tree_map(lambda a, b: a + 0.5 * dt * b, y, k1))
        k3 = rhs(jax.tree_util.tree_map(lambda a, b: a + 0.5 * dt * b, y, k2))
        k4 = rhs(jax.tree_util.tree_map(lambda a, b: a + dt * b, y, k3))
        y = jax.tree_util.tree_map(
            lambda a, b1, b2, b3, b4: a + dt / 6 * (b1 + 2 * b2 + 2 * b3 + b4),
            y,
            k1,
            k2,
            k3,
            k4,
        )
        return y, None

    def integrate(q0, qd0):
        return jax.lax.scan(step, (q0, qd0), None, length=steps)[0]

    return integrate


def measure(fn, *inputs, repeats: int) -> tuple[float, float]:
    """(compile seconds, median run seconds)."""
    start = time.perf_counter()
    compiled = jax.jit(fn).lower(*inputs).compile()
    compile_time = time.perf_counter() - start
    jax.block_until_ready(compiled(*inputs))
    runs = []
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(compiled(*inputs))
        runs.append(time.perf_counter() - start)
    return compile_time, statistics.median(runs)


def n_link_lagrangian(q, qd):
    """n unit masses on unit rods, written as a user would: cumulative sums."""
    vx, vy = jnp.cumsum(jnp.cos(q) * qd), jnp.cumsum(jnp.sin(q) * qd)
    return 0.5 * jnp.sum(vx**2 + vy**2) + G * jnp.sum(jnp.cumsum(jnp.cos(q)))


def n_link_system(q, qd):
    """Closed-form M and right-hand side: M_ij = (n − max(i, j)) cos(θ_i − θ_j),
    M q̈ = −Σ_j (n − max(i, j)) sin(θ_i − θ_j) θ̇_j² − g (n − i) sin θ_i."""
    n = q.shape[-1]
    index = np.arange(n)
    weight = (n - np.maximum(index[:, None], index[None, :])).astype(float)
    difference = q[:, None] - q[None, :]
    rhs = -(weight * jnp.sin(difference)) @ qd**2 - G * (n - index) * jnp.sin(q)
    return weight * jnp.cos(difference), rhs


def n_link_cholesky(q, qd):
    mass, rhs = n_link_system(q, qd)
    return jsl.cho_solve(jsl.cho_factor(mass), rhs)


def n_link_lu(q, qd):
    mass, rhs = n_link_system(q, qd)
    return jnp.linalg.solve(mass, rhs)


def alternating_runs(
    functions: dict, inputs, repeats: int, clock=time.perf_counter
) -> dict:
    """{name: (compile s, median run s)}, the variants run alternately."""
    compiled, compile_times = {}, {}
    for name, fn in functions.items():
        start = time.perf_counter()
        compiled[name] = jax.jit(fn).lower(*inputs).compile()
        compile_times[name] = time.perf_counter() - start
        jax.block_until_ready(compiled[name](*inputs))
    runs: dict[str, list[float]] = {name: [] for name in functions}
    for _ in range(repeats):
        for name, fn in compiled.items():
            start = clock()
            jax.block_until_ready(fn(*inputs))
            runs[name].append(clock() - start)
    return {name: (compile_times[name], statistics.median(runs[name])) for name in runs}


def n_link_rows(
    links: list[int], steps: int, batch: int, repeats: int, clock=time.perf_counter
) -> None:
    print(f"\nn-link pendulum, {steps} RK4 steps, vmapped batch {batch}")
    print(f"{'n':>3s} {'right-hand side':22s} {'mode':8s} {'compile s':>9s} "
          f"{'us/step':>9s} {'ratio':>6s}")  # fmt: skip
    candidates = {
        "closed form, Cholesky": n_link_cholesky,
        "closed form, LU": n_link_lu,
        "lagjax, default": lj.Lagrangian(n_link_lagrangian).acceleration,
    }
    table = []
    for n in links:
        q0, qd0 = jnp.linspace(0.3, 1.0, n), jnp.zeros(n)
        noise = 0.1 * jax.random.normal(jax.random.PRNGKey(n), (batch, n))
        batched_inputs = (q0 + noise, jnp.zeros((batch, n)))
        row: list = [n]
        modes = [("single", (q0, qd0)), ("batched", batched_inputs)][: 1 + (batch > 0)]
        for mode, inputs in modes:
            functions = {}
            for name, acceleration in candidates.items():
                single = rk4_integrator(acceleration, steps, 1e-3)
                functions[name] = single if mode == "single" else jax.vmap(single)
            results = alternating_runs(functions, inputs, repeats, clock)
            twin, best = min(
                ((name, t) for name, (_, t) in results.items() if "closed" in name),
                key=lambda item: item[1],
            )
            for name, (compile_time, run_time) in results.items():
                print(f"{n:3d} {name:22s} {mode:8s} {compile_time:9.2f} "
                      f"{1e6 * run_time / steps:9.2f} {run_time / best:6.2f}")  # fmt: skip
            ratio = results["lagjax, default"][1] / best
            row += [ratio, twin.split(", ")[1]]
        table.append(row + [float("nan"), "not run"] * (batch == 0))
    print(f"\nn-link ratios, lagjax default / faster closed-form twin (batch {batch})")
    print(f"{'n':>3s} {'single':>7s} {'twin':9s} {'batched':>8s} {'twin':9s}")
    for n, single_ratio, single_twin, batched_ratio, batched_twin in table:
        print(f"{n:3d} {single_ratio:7.2f} {single_twin:9s} {batched_ratio:8.2f} "
              f"{batched_twin:9s}")  # fmt: skip


_FIRST_CALL = """
import time
start = time.perf_counter()
import jax
jax.config.update("jax_enable_x64", True)
import diffrax, jax.numpy as jnp
import lagjax as lj
from lagjax.cli.demo import double_pendulum, handwritten_acceleration
solver = diffrax.{solver}()
q0, qd0 = jnp.array([1.2, -0.4]), jnp.array([0.3, 0.1])
lag = lj.Lagrangian(double_pendulum)
def field(acceleration):
    return diffrax.ODETerm(lambda t, y, args: (y[1], acceleration(y[0], y[1])))
def solve(term):
    controller = diffrax.PIDController(rtol=1e-8, atol=1e-8)
    return diffrax.diffeqsolve(term, solver, 0.0, 10.0, None, (q0, qd0),
                               stepsize_controller=controller, max_steps=100_000).ys
imported = time.perf_counter()
if "{variant}" == "simulate":
    ys = lj.simulate(lag, (q0, qd0), 0.0, 10.0, solver=solver).ys
elif "{variant}" == "derived":
    derived = field(lambda q, qd: lag.acceleration(q, qd, check=False))
    ys = jax.jit(lambda: solve(derived))()
else:
    ys = jax.jit(lambda: solve(field(handwritten_acceleration)))()
jax.block_until_ready(ys)
print(time.perf_counter() - imported)
"""


def first_call_rows(repeats: int) -> None:
    print("\nfirst call (trace + compile + run, fresh process, import excluded),")
    print("double pendulum to t = 10, adaptive, rtol = atol = 1e-8")
    print(f"{'solver':8s} {'variant':44s} {'s':>6s} {'ratio':>6s}")
    variants = {
        "hand": "diffeqsolve, hand-written equations",
        "derived": "diffeqsolve, Lagrangian(L).acceleration",
        "simulate": "lj.simulate(Lagrangian(L), ...)",
    }
    for solver in ("Tsit5", "Dopri8"):
        times: dict[str, list[float]] = {name: [] for name in variants}
        for _ in range(repeats):
            for variant in variants:
                code = _FIRST_CALL.format(solver=solver, variant=variant)
                output = subprocess.run(
                    [sys.executable, "-c", code], capture_output=True, text=True
                )
                if output.returncode:
                    raise RuntimeError(output.stderr)
                times[variant].append(float(output.stdout.split()[-1]))
        base = statistics.median(times["hand"])
        for variant, label in variants.items():
            median = statistics.median(times[variant])
            print(f"{solver:8s} {label:44s} {median:6.2f} {median / base:6.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--steps", type=int, default=10_000)
    parser.add_argument("--batch", type=int, default=1024)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--links", type=int, nargs="*", default=[2, 4, 6, 12, 24, 32])
    parser.add_argument("--link-steps", type=int, default=2_000)
    parser.add_argument("--link-batch", type=int, default=64)
    parser.add_argument("--first-call-repeats", type=int, default=3)
    parser.add_argument("--skip-double-pendulum", action="store_true")
    parser.add_argument(
        "--clock",
        choices=sorted(CLOCKS),
        default="wall",
        help="cpu: process CPU time, robust on a loaded machine (n-link rows)",
    )
    options = parser.parse_args()
    if not options.skip_double_pendulum:
        double_pendulum_rows(options)
    if options.links:
        n_link_rows(
            options.links,
            options.link_steps,
            options.link_batch,
            options.repeats,
            CLOCKS[options.clock],
        )
    if options.first_call_repeats:
        first_call_rows(options.first_call_repeats)


def double_pendulum_rows(options) -> None:

    dt = 1e-3
    q0 = jnp.array([1.2, -0.4])
    qd0 = jnp.array([0.3, 0.1])
    key = jax.random.PRNGKey(0)
    q0s = q0 + 0.1 * jax.random.normal(key, (options.batch, 2))
    qd0s = jnp.broadcast_to(qd0, (options.batch, 2))

    indexed = lj.Lagrangian(lagrangian_indexed)
    matrix = lj.Lagrangian(lagrangian_matrix)
    candidates = {
        "hand-written": handwritten_acceleration,
        "L with q[0] indexing": partial(indexed.acceleration, check=False),
        "L as qd @ M(q) @ qd": partial(matrix.acceleration, check=False),
        "q[0] indexing, default": indexed.acceleration,
        "q[0] indexing, check=True": partial(indexed.acceleration, check=True),
    }
    reference_state = None
    baseline: dict[str, float] = {}
    print(f"double pendulum, {options.steps} RK4 steps, batch {options.batch}")
    print(
        f"{'right-hand side':32s} {'mode':8s} {'compile s':>9s} {'run ms':>10s} {'ratio':>6s}"
    )
    for name, acceleration in candidates.items():
        single = rk4_integrator(acceleration, options.steps, dt)
        batched = jax.vmap(single)
        for mode, fn, inputs in (
            ("single", single, (q0, qd0)),
            ("batched", batched, (q0s, qd0s)),
        ):
            compile_time, run_time = measure(fn, *inputs, repeats=options.repeats)
            baseline.setdefault(mode, run_time)
            ratio = run_time / baseline[mode]
            print(
                f"{name:32s} {mode:8s} {compile_time:9.2f} {1e3 * run_time:10.2f} "
                f"{ratio:6.2f}"
            )
        final = single(q0, qd0)
        if reference_state is None:
            reference_state = final
        difference = max(
            float(jnp.max(jnp.abs(a - b)))
            for a, b in zip(
                jax.tree_util.tree_leaves(final),
                jax.tree_util.tree_leaves(reference_state),
            )
        )
        print(
            f"{'':32s} max |state - hand-written state| after the run: {difference:.1e}"
        )


if __name__ == "__main__":
    main()
