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

Which runs: fixed steps (`dt`), the final state or `ts` on the step grid
(multiples of dt at a uniform spacing: the cotangents enter at the saved times).
Which solvers: the symmetric ones, `lagjax._core.solver_kinds.
AbstractTimeReversible` — the palindromic splittings, Gauss–Legendre and the
implicit midpoint rule, the variational midpoint, RATTLE and the Lie–Poisson
rigid-body splittings. Anything else is refused by name, at trace time.

Round-off. The states walked back differ from the forward run's by the round-off
of the steps between. For a compensated solver (the default) the step back is
compensated too, starting from the forward run's compensation; the derivative is
that of the plain sum (the compensation's is zero). In float64 the gradients
agree with the plain scan's to ~1e-14 relative at 10³ steps
(`tests/test_reversible_adjoint.py`). `checkpoints=K` keeps the state every K
steps (the saved states are kept anyway) and restarts the walk back from each, so
the error is that of at most K steps, for n/K states of memory. Kepler over 10⁶
float64 steps, against a long-double reference of the same map
(`benchmarks/adjoint_round_off.py`): 1.6e-9 (Störmer–Verlet) and 5.9e-9
(Yoshida4) relative without checkpoints, 2.2e-11 with K = 1000 (147 KiB of
temporaries instead of 7), where reverse mode through the stored scan is itself
2.8e-10 and 1.2e-10 off; use K ≈ 1000 for runs of 10⁵ steps and more, and in float32
(uncompensated Störmer–Verlet on Kepler, 2·10⁴ steps: 6.7e-3 relative to the
plain scan's float32 gradient without checkpoints, 5.8e-4 with K = 10, where
the plain scan is itself 1.7e-3 from float64) or for very long runs. A failed
run (non-finite state, failed implicit solve) reports its failure as the plain
scan does, but its final state is the last good *mark* (checkpoint or save), not
the last good step.

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

from lagjax._core.solver_kinds import AbstractTimeReversible
from lagjax._integrate.fixed_step_loop import fixed_step_count
from lagjax._integrate.reversible_loop import (
    Clock,
    Marks,
    finite_marks,
    reversible_run,
)


class ReversibleAdjoint(eqx.Module):
    """Reverse mode by time reversibility: states recomputed backward by steps of
    −h, nothing stored per step (module docstring).

    **Arguments:**

    - `checkpoints`: keep the state every this many steps, to restart the walk
      back from (bounds its round-off at that many steps); None keeps only the
      final and saved states.
    """

    checkpoints: int | None = eqx.field(default=None, static=True)

    def __check_init__(self):
        if self.checkpoints is not None and self.checkpoints < 1:
            raise ValueError(
                f"checkpoints must be a positive number of steps, got {self.checkpoints}"
            )

    def fixed_steps(self, terms, solver, t0, t1, dt, y0, args, dtype=float):
        """As `fixed_step_loop.integrate_fixed_steps`: `(y1, result, steps)`."""
        steps = fixed_step_count(t0, t1, dt)
        dt = math.copysign(abs(dt), t1 - t0)
        marks = self._marks(steps, steps, 1)
        clock = Clock(t0, dt, dtype, steps - 1, t1)
        states, results = reversible_run((y0, terms, args), solver, clock, marks)
        reached = finite_marks(states, results)
        last = _last_good(reached)
        y1 = jax.tree_util.tree_map(lambda x: x[last], states)
        taken = jnp.where(reached[0], marks.lead + last * marks.every, 0)
        return y1, _run_result(results, states, reached), taken

    def fixed_steps_saving(self, terms, solver, t0, dt, grid, y0, args, dtype=float):
        """As `fixed_step_loop.integrate_fixed_steps_saving`:
        `(ys, result, steps, saved)` for `grid = (lead, every, saves)`."""
        lead, every, saves = grid
        marks = self._marks(lead, every, saves)
        first = lead // marks.every if self.checkpoints else 0
        stride = max(1, every // marks.every)
        clock = Clock(t0, dt, dtype)
        states, results = reversible_run((y0, terms, args), solver, clock, marks)
        reached = finite_marks(states, results)
        pick = slice(first, None, stride)
        ys = jax.tree_util.tree_map(lambda x: x[pick], states)
        saved = reached[pick]
        last = _last_good(reached)
        good = jax.tree_util.tree_map(lambda x: x[last], states)
        ys = jax.tree_util.tree_map(
            lambda y, g: jnp.where(_column(saved, y), y, g), ys, good
        )
        taken = jnp.where(reached[0], marks.lead + last * marks.every, 0)
        return ys, _run_result(results, states, reached), taken, saved

    def _marks(self, lead: int, every: int, saves: int) -> Marks:
        """The marks of a run whose saves lie `lead` steps in and then every
        `every` steps: the saves, with checkpoints between (at a divisor of
        `every`, so the saves stay marks) and in the lead."""
        if self.checkpoints is None:
            return Marks(lead, every, saves)
        spacing = every if saves > 1 else self.checkpoints
        spacing = max(d for d in range(1, spacing + 1) if spacing % d == 0
                      and d <= self.checkpoints)  # fmt: skip
        before, lead = divmod(lead, spacing)
        return Marks(lead, spacing, before + (saves - 1) * (every // spacing) + 1)


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


def check_reversible_run(
    adjoint: Any, solver: diffrax.AbstractSolver, fits_scan: bool, dt: Any
) -> None:
    """Refuse, at trace time, a `ReversibleAdjoint` run it cannot differentiate:
    a solver that is not symmetric (named, with the ones that are), adaptive
    steps, or a saving other than the final state and `ts` on the step grid."""
    if not isinstance(adjoint, ReversibleAdjoint):
        return
    if not (isinstance(solver, AbstractTimeReversible) and solver.is_time_reversible()):
        raise ValueError(
            f"ReversibleAdjoint needs a time-reversible (symmetric) solver; "
            f"{type(solver).__name__} is not. The reversible ones: "
            f"{', '.join(reversible_solver_names())}. For other solvers use the "
            "default adjoint or diffrax.RecursiveCheckpointAdjoint()."
        )
    if dt is None or not fits_scan:
        raise ValueError(
            "ReversibleAdjoint works on fixed-step runs (dt given) that save the "
            "final state or ts on the step grid (multiples of dt at a uniform "
            "spacing), without a progress meter, step-size controller or event; "
            "for other runs use diffrax.RecursiveCheckpointAdjoint()."
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
