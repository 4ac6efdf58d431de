r"""`ReversibleAdjoint`: gradients through a long fixed-step run in constant memory.

Chosen as `lj.simulate(..., dt=h, solver=<reversible solver>,
adjoint=lj.ReversibleAdjoint())`. Reverse mode then stores no trajectory: the
backward pass walks the run back by steps of −h (`reversible_loop`), which a
symmetric method allows exactly up to round-off. The run's own output is that of
the plain fixed-step scan (the same steps, in the blocked loop's lean step body:
equal to the last bits where XLA fuses both alike); only how it is differentiated
changes.

| | plain scan (default) | `RecursiveCheckpointAdjoint` | `ReversibleAdjoint` |
|---|---|---|---|
| memory | one state per step | O(log n) checkpoints | the saved states (+ checkpoints) |
| extra work | none | recomputation, 2–8× | one step back per step |
| exact | yes | yes | up to round-off |

Measured in `benchmarks/adjoints.py`.

Which runs: fixed steps (`dt`), the final state or `ts` — on the step grid
(multiples of dt at a uniform spacing) or anywhere in [t0, t1], increasing
(`reversible_off_grid`: the continuous extension over the step each time falls
in, from a state the run keeps there); the cotangents enter at the saved times.
Dense output (`dense=True`): every step's state is a mark (the output keeps
them anyway) and the Hermite extension's slopes are evaluated from them after
the run, so their cotangents enter the walk at every step; the memory is the
output's, not the plain scan's stage points and residuals.
Which solvers: the symmetric ones, `lagjax._core.solver_kinds.
AbstractTimeReversible` — the palindromic splittings (and `lj.BitReversible`, the
same on an integer lattice), Gauss–Legendre and the implicit midpoint rule, the
variational midpoint, RATTLE and the Lie–Poisson rigid-body splittings. Anything else is refused by name, at trace time.

Round-off. The states walked back differ from the forward run's by the round-off
of the steps between. For a compensated solver (the default) the step back is
compensated too, starting from the forward run's compensation; the derivative is
that of the plain sum (the compensation's is zero). In float64 the gradients
agree with the plain scan's to ~1e-14 relative at 10³ steps
(`tests/test_reversible_adjoint.py`). Checkpoints — the state kept every K steps
(the saved states are kept anyway), the walk back restarted from each — bound the
error at that of K steps, for n/K states of memory. Kepler over 10⁶ float64
steps, against a long-double reference of the same map
(`benchmarks/adjoint_round_off.py`): 1.6e-9 (Störmer–Verlet) and 5.9e-9
(Yoshida4) relative without checkpoints, 1.8e-10 and 1.3e-9 with K = 10⁴,
2.2e-11 with K = 1000, where reverse mode through the stored scan is itself
2.8e-10 and 1.2e-10 off. In float32 (uncompensated Störmer–Verlet on Kepler,
2·10⁴ steps) 6.7e-3 relative to the plain scan's float32 gradient without
checkpoints, 5.8e-4 with K = 10, where the plain scan is itself 1.7e-3 from
float64.

The default spacing. For a floating-point solver the targets at 10⁶ steps —
gradients within 1e-10 and peak temporary memory within 2× the forward-only
run's — cannot both hold: the forward run's temporaries are a few KiB (7 KiB for
Kepler, the reversible walk without checkpoints 1.9× that), so 2× leaves no room
for a checkpoint every 1000 steps (147 KiB), and without them the walk back is
1.6e-9–5.9e-9 off. `lj.BitReversible` removes the conflict: its steps are undone
to the last bit on an integer lattice (`reversible_lattice`), so it keeps no
checkpoint by default — Kepler over 10⁶ steps: 1.4× the forward run's
temporaries, the gradient 9.8e-12 from a long-double reference (Störmer–Verlet).
For the floating-point solvers the memory the default spends is a budget instead, `checkpoint_bytes` = 1 MiB: a
checkpoint every max(1000, ⌈n·b/budget⌉) steps, b the bytes of one — K = 1000 up
to n = 2²⁰·1000/b steps (13·10⁶ for Kepler's 80 bytes), wider beyond, so the
memory stays within the budget however long the run; below 1000 steps, none. At
10⁶ steps that is 147 KiB of temporaries (21× the forward run's, 1/900 of the
plain scan's 134 MiB) and 2.2e-11.
`checkpoints=K` sets the spacing; `checkpoint_bytes=0` keeps none.

A failed run (non-finite state, failed implicit solve) reports its failure as the
plain scan does, but its final state is the last good *mark* (checkpoint or save),
not the last good step.

References: Gomez, Ren, Urtasun & Grosse, "The reversible residual network:
backpropagation without storing activations", NeurIPS 2017; Hairer, Lubich &
Wanner, *Geometric Numerical Integration*, 2nd ed. (2006), §V.1; diffrax issue
#685 and pull request #727 (reversible solvers, open there).
"""

from __future__ import annotations

import math
from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from lagjax._core.solver_kinds import AbstractTimeReversible
from lagjax._integrate.fixed_step_loop import fixed_step_count
from lagjax._integrate.reversible_loop import (
    Clock,
    Marks,
    finite_marks,
    reversible_run,
)
from lagjax._integrate.reversible_off_grid import reversible_off_grid

# Checkpoints no further apart than this by default: Kepler over 10⁶ float64 steps
# has the reversible gradient 2.2e-11 from a long-double reference with K = 1000
# (Störmer–Verlet and Yoshida4), 1.8e-10 and 1.3e-9 with K = 10⁴
# (`benchmarks/adjoint_round_off.py`): the target is 1e-10.
ROUND_OFF_SPACING = 1000


class ReversibleAdjoint(eqx.Module):
    """Reverse mode by time reversibility: states recomputed backward by steps of
    −h, nothing stored per step (module docstring).

    **Arguments:**

    - `checkpoints`: keep the state every this many steps, to restart the walk
      back from (bounds its round-off at that many steps); overrides
      `checkpoint_bytes`.
    - `checkpoint_bytes`: the memory the checkpoints may take when `checkpoints`
      is None (default 1 MiB): a checkpoint every max(1000, ⌈n·b/budget⌉) of the
      n steps, b the bytes of one (the state and the solver's state), none when
      that is the whole run; 0 keeps none (only the final and saved states).
    """

    checkpoints: int | None = eqx.field(default=None, static=True)
    checkpoint_bytes: int = eqx.field(default=2**20, static=True)

    def __check_init__(self):
        if self.checkpoints is not None and self.checkpoints < 1:
            raise ValueError(
                f"checkpoints must be a positive number of steps, got {self.checkpoints}"
            )
        if self.checkpoint_bytes < 0:
            raise ValueError(
                f"checkpoint_bytes must be a number of bytes >= 0, got "
                f"{self.checkpoint_bytes}"
            )

    def spacing(self, steps: int, mark_bytes: int, exact: bool = False) -> int | None:
        """Steps between checkpoints in a run of `steps` steps whose state and
        solver state take `mark_bytes`; None for no checkpoints. `exact`: the
        solver walks back to the last bit (`lj.BitReversible`), so checkpoints
        bound no round-off and the default keeps none."""
        if self.checkpoints is not None:
            return self.checkpoints
        if self.checkpoint_bytes == 0 or exact:
            return None
        by_budget = math.ceil(steps * mark_bytes / self.checkpoint_bytes)
        spacing = max(ROUND_OFF_SPACING, by_budget)
        return spacing if spacing < steps else None

    def fixed_steps(self, terms, solver, t0, t1, dt, y0, args, dtype=float):
        """As `fixed_step_loop.integrate_fixed_steps`: `(y1, result, steps)`."""
        steps = fixed_step_count(t0, t1, dt)
        dt = math.copysign(abs(dt), t1 - t0)
        clock = Clock(t0, dt, dtype, steps - 1, t1)
        spacing = self.spacing(
            steps, _mark_bytes(solver, terms, clock, y0, args), _exact(solver)
        )
        marks = _marks([steps], spacing)
        states, results, _ = reversible_run((y0, terms, args), solver, clock, marks)
        reached = finite_marks(states, results)
        last = _last_good(reached)
        y1 = jax.tree_util.tree_map(lambda x: x[last], states)
        taken = jnp.where(reached[0], jnp.asarray(marks.positions())[last], 0)
        return y1, _run_result(results, states, reached), taken

    def fixed_steps_saving(self, terms, solver, t0, dt, grid, y0, args, dtype=float):
        """As `fixed_step_loop.integrate_fixed_steps_saving`:
        `(ys, result, steps, saved)` for `grid = (lead, every, saves)`."""
        lead, every, saves = grid
        save_steps = [lead + i * every for i in range(saves)]
        clock = Clock(t0, dt, dtype)
        mark_bytes = _mark_bytes(solver, terms, clock, y0, args)
        spacing = self.spacing(save_steps[-1], mark_bytes, _exact(solver))
        marks = _marks(save_steps, spacing)
        positions = marks.positions()
        states, results, _ = reversible_run((y0, terms, args), solver, clock, marks)
        reached = finite_marks(states, results)
        pick = np.searchsorted(positions, save_steps)
        ys = jax.tree_util.tree_map(lambda x: x[pick], states)
        saved = reached[pick]
        last = _last_good(reached)
        good = jax.tree_util.tree_map(lambda x: x[last], states)
        ys = jax.tree_util.tree_map(
            lambda y, g: jnp.where(_column(saved, y), y, g), ys, good
        )
        taken = jnp.where(reached[0], jnp.asarray(positions)[last], 0)
        return ys, _run_result(results, states, reached), taken, saved

    def every_step(self, terms, solver, t0, t1, dt, y0, args, dtype=float,
                   states=True, dense=False):  # fmt: skip
        """As `fixed_step_loop.integrate_every_step`: `(y1, ys, dense_infos,
        result, steps_taken)`, each step's state a mark (the output keeps them
        anyway), the dense information computed from them
        (`HermiteDenseOutput.dense_information`): its cotangents enter the walk
        back at every step."""
        inner = solver.solver if dense else solver
        steps = fixed_step_count(t0, t1, dt)
        dt = math.copysign(abs(dt), t1 - t0)
        clock = Clock(t0, dt, dtype, steps - 1, t1)
        marks = Marks(0, 1, steps + 1)
        kept, results, _ = reversible_run((y0, terms, args), inner, clock, marks)
        reached = finite_marks(kept, results)
        last = _last_good(reached)
        good = jax.tree_util.tree_map(lambda x: x[last], kept)
        held = jax.tree_util.tree_map(
            lambda y, g: jnp.where(_column(reached, y), y, g), kept, good
        )
        infos = None
        if dense:
            starts = jax.vmap(lambda k: clock.times(k)[0])(jnp.arange(steps))
            times = jnp.concatenate([starts, jnp.asarray([t1], dtype)])
            infos = solver.dense_information(terms, times, held, args)
        ys = jax.tree_util.tree_map(lambda x: x[1:], held) if states else None
        return good, ys, infos, _run_result(results, kept, reached), last

    def off_grid_saves(self, terms, solver, dense_solver, t0, t1, dt, brackets,
                       most, ts, y0, args, dtype=float):  # fmt: skip
        """As `off_grid_saves.integrate_off_grid`: `(ys, result, steps, saved)`
        (`reversible_off_grid`)."""
        del most  # the loops between marks take traced lengths instead
        clock = Clock(t0, dt, dtype)
        mark_bytes = _mark_bytes(solver, terms, clock, y0, args)
        spacing = self.spacing(int(brackets[-1]) + 1, mark_bytes, _exact(solver))
        return reversible_off_grid(terms, solver, dense_solver, (t0, t1, dt),
                                   brackets, ts, y0, args, dtype, spacing)  # fmt: skip


def _exact(solver) -> bool:
    return isinstance(solver, AbstractTimeReversible) and solver.is_bit_reversible()


def _marks(save_steps: list[int], spacing: int | None) -> Marks:
    """The marks of a run saving after `save_steps` steps (evenly spaced), with
    a checkpoint every `spacing` steps: uniform at a divisor of the saves'
    spacing when one lies within a factor 2 of `spacing` (the unrolled loops),
    else at the saves and every `spacing` steps (irregular)."""
    lead, saves = save_steps[0], len(save_steps)
    every = save_steps[1] - lead if saves > 1 else lead
    if spacing is None:
        return Marks(lead, every or 1, saves)
    limit = min(spacing, every) if saves > 1 else spacing
    divisor = max(d for d in range(1, limit + 1) if saves == 1 or every % d == 0)
    if 2 * divisor >= limit:
        before, lead = divmod(lead, divisor)
        return Marks(lead, divisor, before + (saves - 1) * (every // divisor) + 1)
    return Marks.at(sorted(set(save_steps) | set(range(0, save_steps[-1], spacing))))


def _mark_bytes(solver, terms, clock: Clock, y0, args) -> int:
    """Bytes one mark keeps: the state and the solver's state."""
    state = eqx.filter_eval_shape(solver.init, terms, *clock.first_times(), y0, args)
    leaves = jax.tree_util.tree_leaves((y0, state))
    return sum(math.prod(x.shape) * jnp.dtype(x.dtype).itemsize for x in leaves)


def _last_good(reached: jax.Array) -> jax.Array:
    """Index of the last mark reached (0 when none was: the caller masks it)."""
    return jnp.maximum(jnp.sum(reached) - 1, 0)


def _column(flags: jax.Array, like: jax.Array) -> jax.Array:
    return flags.reshape(flags.shape + (1,) * (like.ndim - 1))


def _run_result(results, states, reached):
    """The run's first failure: the solver's, or `nonfinite` at the first mark
    whose state is not finite."""
    final = jax.tree_util.tree_map(lambda x: x[-1], results)
    return diffrax.RESULTS.where(
        (final == diffrax.RESULTS.successful) & ~reached[-1],
        diffrax.RESULTS.nonfinite,  # pyright: ignore[reportArgumentType]
        final,
    )


def check_reversible_run(adjoint: Any, solver: diffrax.AbstractSolver, plan: Any,
                         mode: Any) -> None:  # fmt: skip
    """Refuse, at trace time, a `ReversibleAdjoint` run it cannot differentiate:
    a solver that is not symmetric (named, with the ones that are), adaptive
    steps, dense output, or a saving other than the final state and `ts`
    (`plan` a `plan.RunPlan`, `mode` its `Saving`)."""
    if not isinstance(adjoint, ReversibleAdjoint):
        return
    if not (isinstance(solver, AbstractTimeReversible) and solver.is_time_reversible()):
        raise ValueError(
            f"ReversibleAdjoint needs a time-reversible (symmetric) solver; "
            f"{type(solver).__name__} is not. The reversible ones: "
            f"{', '.join(reversible_solver_names())}. For other solvers use the "
            "default adjoint or diffrax.RecursiveCheckpointAdjoint()."
        )
    saving = plan.saving() if mode.on_scan and not mode.on_step_grid else None
    off_grid_ts = (
        saving is not None
        and not saving.every
        and (
            saving.dense
            or (saving.schedule is not None and not (saving.t0 or saving.t1))
        )
    )
    if plan.dt is None or not (mode.on_step_grid or off_grid_ts):
        raise ValueError(
            "ReversibleAdjoint works on fixed-step runs (dt given) that save the "
            "final state or ts (increasing, within [t0, t1]), without a progress "
            "meter, step-size controller, event or SaveAt; for other runs use "
            "diffrax.RecursiveCheckpointAdjoint()."
        )


def reversible_solver_names() -> list[str]:
    """The concrete solvers that are time-reversible, by class name."""
    found, pending = [], list(AbstractTimeReversible.__subclasses__())
    while pending:
        kind = pending.pop()
        pending.extend(kind.__subclasses__())
        if not kind.__name__.startswith(("Abstract", "_")):
            found.append(kind.__name__)
    return sorted(set(found))
