r"""Long-horizon work-precision of a free asymmetric rigid body: Lie–Poisson vs RK.

The torque-free body with $I = (1, 2, 3)$ spun near its intermediate axis
(`TorqueFreeBody`, flipping over every half period, $T \approx 55$ s) is run to
$t_1 = 10^4$ s, $10^5$ steps of the coarsest Lie–Poisson step $h = 0.1$, by

- `RigidBodyVerlet` and `RigidBodyYoshida4` over a sweep of $h$: their default
  symmetric-top split (Touma & Wisdom 1994), with and without Kahan's compensated
  update, and McLachlan's split into rotations about the three body axes
  (`free_body="axes"`). Every rotation keeps $|\boldsymbol\Pi|$ and the space
  $\mathbf L = R\boldsymbol\Pi$, so their errors are round-off, while the energy
  error is $O(h^p)$ and bounded;
- `QuaternionProjection(Dopri8)` and `(Tsit5)` over a sweep of rtol = atol, whose
  $|\mathbf L|$ and energy errors drift with the accumulated local error.

Per point: compile time apart; run time the median of warm, blocked final-state
runs; from an untimed run saved at every step (the methods' own states) the largest
relative errors of $|\mathbf L| = |\boldsymbol\Pi|$, of $R\boldsymbol\Pi$ and of
the energy; $\|R^TR - I\|_F$ at the end, $R$ built as if $|q| = 1$; the error of the
final $(R, \boldsymbol\omega)$ against Dopri8 at rtol $10^{-14}$ (floor: its distance
from rtol $10^{-13}$). A hand-written twin, `RigidBodyVerlet` in a plain
`jax.lax.scan` (axes split), gives the overhead of the solver inside `lj.simulate`.

    python -m benchmarks.rigid_long_horizon [--quick] [--out DIR]

Writes `rigid_long_horizon.{csv,json,png,md}` to `--out` (default
`benchmarks/results/`).

References: McLachlan, *Explicit Lie–Poisson integration and the Euler equations*,
Phys. Rev. Lett. 71, 3043 (1993); Touma & Wisdom, Astron. J. 107, 1189 (1994); Hairer, Lubich & Wanner, *Geometric Numerical
Integration*, 2nd ed. (2006), §VII.5 (rigid body, splitting into exact rotations)
and §VIII.5 (round-off, compensated summation); Hairer, Nørsett & Wanner, *Solving
ODEs I*, §II.10 (work-precision diagrams).
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax

jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import lagjax as lj  # noqa: E402
from benchmarks.rigid_long_horizon_report import LIE_POISSON, point_table, write  # noqa: E402
from lagjax import diagnostics  # noqa: E402
from lagjax.rigid import quaternion_to_matrix, skew  # noqa: E402
from lagjax.scenes.rigid import TorqueFreeBody  # noqa: E402
from lagjax.solvers.lie_poisson import (  # noqa: E402
    QuaternionProjection,
    RigidBodyVerlet,
    RigidBodyYoshida4,
)

# fmt: off
# t1 = 10⁵ (full) or 10⁴ (quick) steps of h = 0.1, the coarsest sensible step.
MODES = {
    "full": dict(t1=1e4, verlet=(0.2, 0.1, 0.05, 0.025, 0.0125),
                 yoshida=(0.4, 0.2, 0.1, 0.05, 0.025, 0.0125), uncompensated=True,
                 dopri8=tuple(10.0**-k for k in range(6, 14)),
                 tsit5=tuple(10.0**-k for k in range(6, 14)), repeats=5,
                 axes_points=None),
    # Every point is two compilations: quick keeps the coarsest step of the axes
    # splits and leaves the Tsit5 line to the full run.
    "quick": dict(t1=1e3, verlet=(0.1,), yoshida=(0.2, 0.1), uncompensated=False,
                  dopri8=(1e-6, 1e-9, 1e-12), tsit5=(), repeats=3, axes_points=1),
}
# fmt: on
REFERENCE_RTOL = (1e-14, 1e-13)
MAX_ADAPTIVE_STEPS = 10**7
SCENE = TorqueFreeBody()  # I = (1, 2, 3), ω₀ = (10⁻³, 1, 10⁻³): near the middle axis
MOMENTS = np.asarray(SCENE.moments)


def methods(mode: dict) -> list[tuple[str, str, object, str, tuple[float, ...]]]:
    """(label, family, solver, parameter, values) for every line of the diagram."""
    lines = []
    for cls, steps in ((RigidBodyVerlet, "verlet"), (RigidBodyYoshida4, "yoshida")):
        for compensated in (True, False) if mode["uncompensated"] else (True,):
            label = cls.__name__ + ("" if compensated else " (no compensation)")
            solver = cls(compensated=compensated)
            lines.append((label, LIE_POISSON, solver, "h", mode[steps]))
        # McLachlan's split into the three body axes, for comparison.
        solver = cls(free_body="axes")
        lines.append((f"{cls.__name__} (axes split)", LIE_POISSON, solver, "h",
                      mode[steps][: mode["axes_points"]]))  # fmt: skip
    for name in ("Dopri8", "Tsit5"):
        solver = QuaternionProjection(getattr(diffrax, name)())
        label = f"QuaternionProjection({name})"
        lines.append((label, name, solver, "rtol", mode[name.lower()]))
    return lines


def simulate(solver, parameter, value, t1, y0, max_steps=None, **kwargs):
    """`lj.simulate` of the free body with a step h or with rtol = atol."""
    if parameter == "h":
        kwargs.update(dt=value)
    else:
        kwargs.update(rtol=value, atol=value)
        max_steps = max_steps or MAX_ADAPTIVE_STEPS
    body = SCENE.rigid_body()
    return lj.simulate(body, y0, t1=t1, solver=solver, max_steps=max_steps, **kwargs)


def final_state(solver, parameter, value, t1):
    """The timed function: final (q, Π) and the step count."""

    def run(q0, p0):
        trajectory = simulate(solver, parameter, value, t1, (q0, p0))
        final = jax.tree_util.tree_map(lambda x: x[-1], trajectory.ys)
        return final, trajectory.stats["num_steps"]

    return run


def comparable(q: np.ndarray, p: np.ndarray) -> np.ndarray:
    """(R, ω) as one vector, the state compared with the reference."""
    rotation = np.asarray(quaternion_to_matrix(jnp.asarray(q))).ravel()
    return np.concatenate([rotation, p / MOMENTS])


def invariant_errors(q: np.ndarray, p: np.ndarray) -> dict:
    """Maximum relative errors of |L|, of L in space and of the energy, and the
    orthonormality defect of R(q) at the end, along the saved states."""
    norm = np.linalg.norm(p, axis=-1)
    energy = 0.5 * np.sum(p**2 / MOMENTS, axis=-1)
    space = np.asarray(jax.vmap(jnp.matmul)(quaternion_to_matrix(jnp.asarray(q)), p))
    w, v = q[-1, 0], q[-1, 1:]
    # (w² − |v|²) I + 2 v vᵀ + 2 w [v]×: R(q) without the division by |q|², which is
    # |q|² times a rotation, so the defect shows how far q has left the unit sphere.
    rotation = (
        (w * w - v @ v) * np.eye(3)
        + 2 * np.outer(v, v)
        + 2 * w * np.asarray(skew(jnp.asarray(v)))
    )
    return dict(
        momentum_error=float(np.max(np.abs(norm / norm[0] - 1))),
        space_momentum_error=float(
            np.max(np.linalg.norm(space - space[0], axis=-1)) / norm[0]
        ),
        energy_error=float(np.max(np.abs(energy / energy[0] - 1))),
        orthonormality=float(np.linalg.norm(rotation.T @ rotation - np.eye(3))),
    )


def measure(line, value, t1, y0, reference, repeats) -> dict:
    """One point: timing of the final-state run, errors from an every-step run."""
    label, family, solver, parameter, _ = line
    timing = diagnostics.time_run(
        final_state(solver, parameter, value, t1), *y0, repeats=repeats
    )
    (q1, p1), steps = jax.tree_util.tree_map(np.asarray, timing.output)
    saved = simulate(
        solver, parameter, value, t1, y0, max_steps=int(steps) + 2,
        saveat=diffrax.SaveAt(t0=True, steps=True),
    )  # fmt: skip
    used = np.isfinite(np.asarray(saved.ts))  # unused slots of SaveAt(steps) are inf
    q, p = (np.asarray(x)[used] for x in saved.ys)
    final = comparable(q1, p1)
    return dict(
        method=label, family=family, parameter=parameter, value=value,
        steps=int(steps), compile_s=timing.compile_seconds,
        run_s=timing.run_seconds, repeats=len(timing.runs),
        **invariant_errors(q, p),
        final_error=diagnostics.final_state_error(final, reference),
    )  # fmt: skip


def reference_state(t1, y0) -> tuple[np.ndarray, float]:
    """Dopri8 at the tightest rtol, and its distance from the next one."""
    solver, finals = QuaternionProjection(diffrax.Dopri8()), []
    for rtol in REFERENCE_RTOL:
        run = jax.jit(final_state(solver, "rtol", rtol, t1))
        (q, p), _ = jax.tree_util.tree_map(np.asarray, run(*y0))
        finals.append(comparable(q, p))
    return finals[0], diagnostics.final_state_error(finals[1], finals[0])


def twin(steps: int, h: float):
    """`RigidBodyVerlet` by hand: a plain `lax.scan` whose step turns Π (by −α) and
    q (q ⊗ e^{α/2}) in place about the axes 1, 2, 3, 2, 1, for h/2, h/2, h, h/2, h/2."""

    def step(carry, _):
        (w, *v), p, moments = list(carry[0]), list(carry[1]), carry[2]
        for axis, fraction in ((0, 0.5), (1, 0.5), (2, 1.0), (1, 0.5), (0, 0.5)):
            j, k = (axis + 1) % 3, (axis + 2) % 3
            angle = fraction * h * p[axis] / moments[axis]
            c, s = jnp.cos(angle), jnp.sin(angle)
            p[j], p[k] = c * p[j] + s * p[k], c * p[k] - s * p[j]
            ch, sh = jnp.cos(0.5 * angle), jnp.sin(0.5 * angle)
            w, v[axis], v[j], v[k] = (
                ch * w - sh * v[axis], ch * v[axis] + sh * w,
                ch * v[j] + sh * v[k], ch * v[k] - sh * v[j],
            )  # fmt: skip
        return (jnp.stack([w, *v]), jnp.stack(p), moments), None

    def run(q0, p0, moments):
        (q, p, _), _ = jax.lax.scan(step, (q0, p0, moments), None, length=steps)
        return q, p

    return run


def twin_ratios(steps: int, h: float, y0, repeats: int) -> dict:
    """lj.simulate with RigidBodyVerlet, compensated or not, against the twin.

    Run alternately, so that a busy machine slows all alike; medians after a warm-up.
    """
    args = (*y0, SCENE.moments)
    functions: dict[str, Callable] = {"twin": twin(steps, h)}
    for compensated in (False, True):
        # The twin is McLachlan's axes split, written out by hand.
        solver = RigidBodyVerlet(compensated=compensated, free_body="axes")
        run = final_state(solver, "h", h, steps * h)
        name = "compensated" if compensated else "plain"
        functions[name] = lambda q, p, m, run=run: run(q, p)[0]
    compiled = {key: jax.jit(f).lower(*args).compile() for key, f in functions.items()}
    runs = {key: [] for key in compiled}
    for _ in range(repeats + 1):  # the first round warms up
        for key, call in compiled.items():
            start = time.perf_counter()
            jax.block_until_ready(call(*args))
            runs[key].append(time.perf_counter() - start)
    median = {key: statistics.median(times[1:]) for key, times in runs.items()}
    twin_state = jnp.concatenate(compiled["twin"](*args))
    result: dict[str, Any] = dict(steps=steps, h=h, twin_s=median["twin"])
    for name in ("plain", "compensated"):
        difference = jnp.concatenate(compiled[name](*args)) - twin_state
        result[name] = dict(lagjax_s=median[name], ratio=median[name] / median["twin"],
                            final_difference=float(jnp.linalg.norm(difference)))  # fmt: skip
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="CI size: 10⁴ steps")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    options = parser.parse_args()
    name = "quick" if options.quick else "full"
    mode, started = MODES[name], time.perf_counter()
    t1, y0 = mode["t1"], SCENE.initial_body_state()
    reference, floor = reference_state(t1, y0)
    records = []
    for line in methods(mode):
        for value in line[4]:
            record = measure(line, value, t1, y0, reference, mode["repeats"])
            records.append(record)
            print(point_table([record])[-1], flush=True)
    twin_result = twin_ratios(round(t1 / 0.1), 0.1, y0, mode["repeats"])
    print(json.dumps(twin_result, indent=1))
    title = (f"Free asymmetric body, I = (1, 2, 3), t = {t1:.0e} s "
             f"({round(t1 / 0.1):.0e} steps of h = 0.1)")  # fmt: skip
    meta = dict(mode=name, title=title, t1=t1, reference_floor=floor,
                device=str(jax.devices()[0]), jax=jax.__version__,
                seconds=time.perf_counter() - started)  # fmt: skip
    options.out.mkdir(parents=True, exist_ok=True)
    write(options.out, records, meta, twin_result)
    print(f"wrote {options.out} in {time.perf_counter() - started:.0f} s")


if __name__ == "__main__":
    main()
