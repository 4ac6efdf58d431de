r"""The stability suite's engine: rows, outcomes, and final-state cases.

Every row of the suite has the same keys (`ROW_KEYS`), whatever produced it:

- `case`, `method`: the problem and the attempt (a solver at a setting);
- `outcome`: **accurate** (the judged number is within the case's bound),
  **degraded** (finished, finite, beyond the bound) or **refused** (lagjax or
  diffrax raised an error, or the result was not finite — never reported as a
  number; `reason` says which);
- `error`: the relative error the case measures (final state, a rate, an
  exponent's target quantity — each case's docstring says which);
- `energy_error`: max relative energy error along the run (NaN where not measured);
- `run_s`, `compile_s`: a warm run and the compilation (`diagnostics.time_run`);
- `steps`: the steps the solver took, rejected ones included (NaN where a study
  does not count them) — the work, free of the machine's load, that tests compare;
- `measure`: what was measured, in words and numbers, where a final-state error
  does not say it all (a rate, a growth exponent, a Lyapunov exponent);
- `reason`: why a run was refused.

A `Case` compares the final (q, q̇) of each attempt with an exact state or a tight
reference. Other studies (`stability_brouwer.py`, `stability_lyapunov.py`, the
Foucault pendulum) measure something else, but yield the same rows through
`judged_row`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any, NamedTuple, Protocol

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

import lagjax as lj
from lagjax import diagnostics

ROW_KEYS = ("case", "method", "outcome", "error", "energy_error", "run_s",
            "compile_s", "steps", "measure", "reason")  # fmt: skip
ENERGY_SAMPLES = 100  # stratified random save times (diagnostics.sample_times)


class Study(Protocol):
    """What the suite runs: a named problem that yields its rows."""

    name: str

    def rows(self, timing: dict) -> Iterator[dict]: ...


class Measured(NamedTuple):
    """What one attempt measured. `score` is what the tolerance judges (default:
    `error`), for studies whose verdict rests on another number, e.g. an exponent.
    """

    error: float
    run_s: float
    compile_s: float
    energy_error: float = math.nan
    measure: str = ""
    score: float | None = None
    steps: float = math.nan


def judged_row(
    case: str, method: str, tolerance: float, measure: Callable[[], Measured]
) -> dict:
    """Run `measure` and turn what it found (or why it failed) into a row."""
    row: dict[str, Any] = dict.fromkeys(ROW_KEYS, math.nan)
    row.update(case=case, method=method, outcome="refused", measure="", reason="")
    try:
        measured = measure()
    except Exception as failure:  # a refusal is an outcome of the suite
        row["reason"] = diagnostics.failure_reason(failure)
        return row
    row.update(measured._asdict())
    del row["score"]
    score = measured.error if measured.score is None else measured.score
    if not (math.isfinite(measured.error) and math.isfinite(score)):
        # A NaN or inf that escaped lagjax's own checks is not a measurement.
        row["reason"] = "non-finite result (inf/NaN); not reported as a number"
        row["error"] = math.nan
        return row
    row["outcome"] = "accurate" if score <= tolerance else "degraded"
    return row


@dataclass(frozen=True)
class Attempt:
    """One method on one case: `steps` fixed steps, or adaptive at `rtol` = atol."""

    label: str
    solver: Any
    steps: int | None = None
    rtol: float = 1e-8
    max_steps: int | None = None
    route: Callable[[], jax.Array] | None = None  # a final state by other means
    in_quick: bool = True  # part of the CI-sized subset


@dataclass
class Case:
    """A problem, the final state it must reach, and how close counts as accurate."""

    name: str
    system: Any
    y0: Any
    t1: float
    attempts: list[Attempt]
    tolerance: float
    expected: Any = None  # final comparable state (or a function giving it)
    args: Any = None
    comparable: Callable[[Any, Any], jax.Array] = field(
        default=lambda q, qdot: jnp.concatenate([jnp.ravel(q), jnp.ravel(qdot)])
    )
    conservative: bool = True
    measure_energy: bool = True  # an untimed second run, saved at ENERGY_SAMPLES

    def rows(self, timing: dict) -> Iterator[dict]:
        expected = reference(self)
        for attempt in self.attempts:
            yield judged_row(
                self.name, attempt.label, self.tolerance,
                lambda attempt=attempt: _measure(self, attempt, expected, timing),
            )  # fmt: skip


def _simulate(case: Case, attempt: Attempt, y0: Any, ts: Any = None):
    dt = None if attempt.steps is None else case.t1 / attempt.steps
    max_steps = attempt.max_steps
    if ts is not None and max_steps is None:
        max_steps = (attempt.steps or 10**5) + 2
    return lj.simulate(
        case.system, y0, t1=case.t1, dt=dt, solver=attempt.solver, args=case.args,
        rtol=attempt.rtol, atol=attempt.rtol, max_steps=max_steps, ts=ts,
    )  # fmt: skip


def reference(case: Case) -> np.ndarray:
    if callable(case.expected):
        return np.asarray(jax.jit(case.expected)())
    if case.expected is not None:
        return np.asarray(case.expected)
    tight = Attempt("reference", diffrax.Dopri8(), rtol=1e-12, max_steps=10**7)
    final, _ = jax.jit(lambda y0: _final_and_steps(case, tight, y0))(case.y0)
    return np.asarray(final)


def _final_and_steps(case: Case, attempt: Attempt, y0: Any):
    trajectory = _simulate(case, attempt, y0)
    final = case.comparable(trajectory.q[-1], trajectory.qdot[-1])
    return final, trajectory.stats["num_steps"]


def energy_error(case: Case, attempt: Attempt) -> float:
    """Max relative energy error along an untimed run saved on the step grid."""
    if not (case.conservative and case.measure_energy) or attempt.route is not None:
        return math.nan
    dt = None if attempt.steps is None else case.t1 / attempt.steps
    ts = diagnostics.sample_times(0.0, case.t1, ENERGY_SAMPLES, dt)
    trajectory = _simulate(case, attempt, case.y0, jnp.asarray(ts))
    return float(diagnostics.energy_error(trajectory))


def _measure(case: Case, attempt: Attempt, expected: np.ndarray, timing) -> Measured:
    if attempt.route is not None:
        timed = diagnostics.time_run(attempt.route, **timing)
        final, steps = timed.output, math.nan
    else:
        timed = diagnostics.time_run(
            lambda y0: _final_and_steps(case, attempt, y0), case.y0, **timing
        )
        final, steps = timed.output[0], float(timed.output[1])
    error = diagnostics.final_state_error(final, expected)
    return Measured(error, timed.run_seconds, timed.compile_seconds,
                    energy_error(case, attempt), steps=steps)  # fmt: skip
