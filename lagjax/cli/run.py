"""The run behind `lagjax run`: a scene integrated in chunks that Ctrl-C can stop.

The save times are spaced by the scene's own time scale, its `default_dt` — fine
enough to show each swing, since a scene's default step resolves its fastest motion
(≥ 20 steps per shortest period, except the Fermi–Pasta–Ulam chain, stepped at
hω ≈ 1 on purpose) — on the step grid for fixed steps, and at most
`MAX_SAVED_POINTS` (fewer for a batch, whose every copy is saved). They are cut
into chunks of at most `CHUNK_STEPS` fixed steps (`ADAPTIVE_CHUNKS` for adaptive
runs); each chunk is one call of the same compiled `simulate`, started from the
last state of the one before. Python answers Ctrl-C between chunks, so an
interrupted run keeps every chunk it finished (`Outcome.interrupted`). Errors
found while tracing (a solver that cannot integrate the scene, say) are the
caller's to fix and come back as `UsageError`.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import time
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

from lagjax._integrate.checks.run_verdict import energy_drift
from lagjax._integrate.simulate import simulate
from lagjax.solvers.projection import project_onto_constraints

# Saved states per run at most: every step of a scene's default run up to 2·10⁴
# steps (each swing drawn with ≥ 20 points), every k-th beyond.
MAX_SAVED_POINTS = 20_001
# A batch saves every copy: it keeps at most this many states per copy.
MAX_SAVED_POINTS_BATCHED = 2001
# Fixed steps per chunk of a long run: Ctrl-C is answered between chunks.
CHUNK_STEPS = 200_000
ADAPTIVE_CHUNKS = 8


class UsageError(Exception):
    """A bad command-line argument: reported in one line, exit status 2."""


def first_line(error: Any) -> str:
    """The first non-empty line of an error message."""
    lines = [line.strip() for line in str(error).splitlines() if line.strip()]
    return lines[0] if lines else type(error).__name__


def _perturbed_batch(state, batch: int):
    """`batch` copies of a state, each scaled by 1 + 1e-3·(k − batch/2)/batch."""
    factors = 1.0 + 1e-3 * (jnp.arange(batch) - batch / 2) / batch

    def spread(leaf):
        leaf = jnp.asarray(leaf)
        return factors.reshape((batch,) + (1,) * leaf.ndim) * leaf

    return jax.tree_util.tree_map(spread, state)


def _onto_constraints(scene, states):
    """A constrained scene's perturbed copies moved back onto its constraints:
    scaling q and q̇ stretches a pendulum's string, and every copy would be
    refused as a start that violates them."""
    system, args = scene.resolve(None)

    def project(q, qdot):
        return project_onto_constraints(system, q, qdot, 0.0, args)[0]

    return jax.vmap(project)(*states)


def _save_times(t1: float, dt: float | None, spacing: float, points: int) -> np.ndarray:
    """Times from 0 to t1 about `spacing` apart, at most `points` of them.

    On the step grid for fixed steps (every k-th step, k ≥ 1), so the saved states
    are the solver's own, not interpolated between steps.
    """
    wanted = int(min(points, np.ceil(abs(t1) / spacing - 1e-9) + 1))
    wanted = max(wanted, 2)
    if dt is None:
        return np.linspace(0.0, t1, wanted)
    steps = int(np.floor(abs(t1 / dt) + 1e-9))
    stride = max(1, math.ceil(steps / (wanted - 1)))
    grid = np.arange(0, steps + 1, stride) * dt
    # k·dt can land an ulp past t1 (1000 · 1e-9 = 1.0000000000000002e-6): such a
    # time is t1 itself, and no save may lie outside the run.
    grid = grid[np.abs(grid) < abs(t1) * (1 - 1e-12)]
    return np.append(grid, t1)


def _pieces(times: np.ndarray, dt: float | None) -> list[np.ndarray]:
    """The save times cut into chunks that share their end points."""
    steps = abs(times[-1] / dt) if dt else 0.0
    chunks = ADAPTIVE_CHUNKS if dt is None else math.ceil(steps / CHUNK_STEPS)
    chunks = max(1, min(chunks, (times.size - 1) // 2))
    bounds = np.linspace(0, times.size - 1, chunks + 1).round().astype(int)
    return [times[a : b + 1] for a, b in itertools.pairwise(bounds)]


@dataclasses.dataclass
class Outcome:
    """What a run produced: the trajectory so far and whether it was cut short."""

    trajectory: Any
    steps: int
    compile_time: float
    run_time: float
    interrupted: bool


def run_scene(scene, t1: float, dt: float | None, solver, batch: int | None) -> Outcome:
    points = MAX_SAVED_POINTS if batch is None else MAX_SAVED_POINTS_BATCHED
    pieces = _pieces(_save_times(t1, dt, scene.default_dt, points), dt)
    longest = max(abs(p[-1] - p[0]) for p in pieces)
    max_steps = None if dt is None else int(longest / abs(dt)) + 3

    # One chunk (the usual run) keeps its times concrete, as a direct simulate call
    # would; chunks share one compilation, so theirs are traced.
    single = len(pieces) == 1

    def segment(state, ts):
        t0, t_end = (0.0, float(t1)) if single else (ts[0], ts[-1])
        return simulate(scene, state, t0=t0, t1=t_end, dt=dt, solver=solver, ts=ts,
                        max_steps=max_steps)  # fmt: skip

    function = segment if batch is None else jax.vmap(segment, in_axes=(0, None))
    state = scene.initial_state()
    if batch is not None:
        state = _perturbed_batch(state, batch)
        if scene.keeps_constraints():
            state = _onto_constraints(scene, state)
    compiled: dict[int, Any] = {}
    done, steps, compile_time, run_time = [], 0, 0.0, 0.0
    try:
        for times in pieces:
            if times.size not in compiled:
                start = time.perf_counter()
                compiled[times.size] = _compile(function, state, times)
                compile_time += time.perf_counter() - start
            start = time.perf_counter()
            piece = _advance(compiled[times.size], state, jnp.asarray(times))
            run_time += time.perf_counter() - start
            done.append(piece)
            steps += int(np.max(np.asarray(piece.stats["num_steps"])))
            state = _last_state(scene, piece, batch)
    except KeyboardInterrupt:
        if not done:
            raise
        return Outcome(_joined(done, batch), steps, compile_time, run_time, True)
    return Outcome(_joined(done, batch), steps, compile_time, run_time, False)


def _compile(function, state, times: np.ndarray):
    """Trace and compile; an error found while tracing is the user's to fix."""
    try:
        return jax.jit(function).lower(state, jnp.asarray(times)).compile()
    except (ValueError, TypeError) as error:
        raise UsageError(first_line(error)) from None


def _advance(compiled, state, times: jax.Array):
    """Run one chunk (a seam the tests use to simulate Ctrl-C)."""
    return jax.block_until_ready(compiled(state, times))


def _last_state(scene, piece, batch: int | None):
    """The last saved state in the scene's own convention, (q, q̇) or (q, p)."""
    axis = 0 if batch is None else 1
    momentum = scene.state_kind == "momentum"
    user_state = (piece.q, piece.p if momentum else piece.qdot)
    return jax.tree_util.tree_map(lambda x: jnp.take(x, -1, axis=axis), user_state)


def _joined(pieces: list, batch: int | None):
    """One trajectory from chunks that share end points (each joint kept once)."""
    axis = 0 if batch is None else 1

    def along(parts):
        trimmed = [parts[0]] + [jnp.delete(p, 0, axis=axis) for p in parts[1:]]
        return jnp.concatenate(trimmed, axis=axis)

    ts = along([p.ts for p in pieces])
    ys = jax.tree_util.tree_map(
        lambda *parts: along(list(parts)), *[p.ys for p in pieces]
    )
    return eqx.tree_at(lambda t: (t.ts, t.ys), pieces[0], (ts, ys))


# -- scales float64 can carry --------------------------------------------------------

# A parameter beyond 1e±100 leaves float64's range (1e±308) once the equations
# multiply three of them or square a product (p = m l² θ̇, then p² in T): with
# mass = 1e-300 the pendulum's p² underflows to 0 and the energy report read 2.15.
PARAMETER_RANGE = (1e-100, 1e100)
# The energy scale |E0| + |p0·q̇0| at the start: squares of it must stay normal.
ENERGY_RANGE = (1e-150, 1e150)


def check_scales(scene) -> None:
    """Refuse, before any run, parameters or a starting energy whose size float64
    cannot carry through the equations (`UsageError` naming them)."""
    low, high = PARAMETER_RANGE
    for field in dataclasses.fields(scene):
        value = getattr(scene, field.name)
        if not isinstance(value, (jax.Array, np.ndarray, float, int)):
            continue
        sizes = np.abs(np.asarray(value, dtype=float))
        sizes = sizes[sizes > 0]
        if sizes.size and (sizes.min() < low or sizes.max() > high):
            raise UsageError(
                f"--param {field.name}={_shown(value)}: outside {low:.0e}..{high:.0e} "
                "in size, float64 cannot carry it through the equations (products "
                "such as p² = (m l² θ̇)² underflow to 0 or overflow to inf, and the "
                "energy report would be meaningless); choose units in which the "
                "parameters are nearer 1"
            )
    q0, second0 = scene.initial_state()
    energy, scale = _start_energy(scene, q0, second0, 0.0, scene)
    low, high = ENERGY_RANGE
    if not np.isfinite(scale) or (scale > 0 and not low <= scale <= high):
        raise UsageError(
            f"the scene's energy scale at the start, |E0| + |p0·q̇0| = {scale:.3g} "
            f"(E0 = {energy:.3g}), is outside {low:.0e}..{high:.0e}: float64 cannot "
            "square it, so the run's energy report would be meaningless; choose "
            "units (parameters) in which the energy is nearer 1"
        )


def _shown(value) -> str:
    flat = np.ravel(np.asarray(value, dtype=float))
    return ",".join(f"{x:g}" for x in flat)


def _start_energy(system, q, second, t=0.0, args=None) -> tuple[float, float]:
    """(E0, |E0| + |p0·q̇0|) at a state (a scene is its own args)."""
    energy, scale = _energy_and_scale(system, q, second, t, args)
    return float(energy), float(scale)


@eqx.filter_jit
def _energy_and_scale(system, q, second, t, args):
    energy = system.state_energy(q, second, t, args)
    velocity = ravel_pytree(system.state_velocity(q, second, t, args))[0]
    momentum = ravel_pytree(system.state_momentum(q, second, t, args))[0]
    # p and q̇ unpaired (a rigid body: 3 momenta, 4 quaternion rates): |E0| alone
    rate = momentum @ velocity if velocity.shape == momentum.shape else 0.0
    return energy, jnp.abs(energy) + jnp.abs(rate)


@dataclasses.dataclass
class EnergyReport:
    """How the energy of a run behaved: `drift` = max |E − E0| / scale where the
    scene conserves it (NaN where it does not: forces, damping, a drive)."""

    change: float
    drift: float
    scale: float

    def line(self) -> str:
        if np.isfinite(self.drift):
            return f"energy    max relative error {self.drift:.2e}"
        return (
            f"energy    not conserved by this scene (forces, damping, constraints or "
            f"a drive): changed by {self.change:.2e} of its scale {self.scale:.3g}"
        )


def energy_report(trajectory) -> EnergyReport:
    """The energy figures of a single (unbatched) trajectory, relative to the
    scale |E0| + |p0·q̇0| (`lagjax._integrate.checks.run_verdict`), which stays
    meaningful where E0 is 0."""
    start = jax.tree_util.tree_map(lambda x: x[0], trajectory.ys)
    t0 = trajectory.ts[0]
    q0, second0 = start
    _, scale = _start_energy(trajectory.system, q0, second0, t0, trajectory.args)
    drift = _drift(trajectory.system, start, t0, trajectory.ts, trajectory.ys,
                   trajectory.args)  # fmt: skip
    energy = np.asarray(trajectory.energy())
    change = float(np.max(np.abs(energy - energy[0]))) / max(scale, 1e-300)
    return EnergyReport(change, float(drift), scale)


_drift = eqx.filter_jit(energy_drift)
