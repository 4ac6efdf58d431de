"""Measuring a work-precision case: its reference, its energy, its timed points.

Every point is measured the same way (`lagjax.diagnostics`): compile time apart,
run time the median of warm runs ended by `block_until_ready`, the relative error
of the final comparable state against the exact solution or a float64 reference
(Dopri8 at rtol = 10⁻¹⁴; its difference from rtol = 10⁻¹³ is reported as the
reference's floor), and the maximum relative energy error along the run. A point
that fails is recorded with its reason, not raised.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

import lagjax as lj
from benchmarks.wp_cases import Case
from benchmarks.wp_methods import Method, all_methods, lagjax_method
from lagjax import diagnostics

REFERENCE_RTOL = (1e-13, 1e-14)


def reference_state(case: Case) -> tuple[np.ndarray, float]:
    """(final comparable state, its estimated relative accuracy)."""
    if case.exact is not None:
        return case.exact, 0.0
    method = lagjax_method(case, "Dopri8", diffrax.Dopri8(), False, REFERENCE_RTOL)
    finals = []
    for rtol in REFERENCE_RTOL:
        runner = method.runner(rtol)
        finals.append(np.asarray(jax.jit(runner.fn)(*runner.args)[0])[-1])
    return finals[1], diagnostics.final_state_error(finals[0], finals[1])


def case_energy(case: Case) -> Callable[[np.ndarray], np.ndarray]:
    """Energies of comparable states: H or the Jacobi integral (½Σ Iω² for a body)."""
    if case.key == "rigid":
        moments = np.asarray(case.scene.moments)
        return lambda states: 0.5 * np.sum(moments * np.asarray(states)[:, 9:] ** 2, -1)
    q0 = jnp.asarray(case.start()[0])
    system = case.scene.system()
    lag = system if isinstance(system, lj.Lagrangian) else system.to_lagrangian()

    def one(state):
        q, v = state[: q0.size].reshape(q0.shape), state[q0.size :].reshape(q0.shape)
        return lag.energy(q, v, 0.0, case.scene)

    energies = jax.jit(jax.vmap(one))
    return lambda states: np.asarray(energies(jnp.asarray(states)))


def measure_point(case, method, value, reference, energy, timing) -> dict:
    record: dict[str, Any] = dict(
        scene=case.key, method=method.label, family=method.family,
        parameter=method.parameter, value=value, compile_s=math.nan, setup_s=0.0,
        run_s=math.nan, repeats=0, steps=-1, error=math.nan, energy_error=math.nan,
        outcome="ok", reason="",
    )  # fmt: skip
    try:
        runner = method.runner(value)
        measured = diagnostics.time_run(
            runner.fn, *runner.args, jit=runner.jit, warmup=int(runner.jit), **timing
        )
        final, series, steps = runner.finish(measured.output)
        record.update(
            compile_s=measured.compile_seconds, setup_s=runner.setup_seconds,
            run_s=measured.run_seconds, repeats=len(measured.runs), steps=steps,
            error=diagnostics.final_state_error(final, reference),
            energy_error=float(diagnostics.energy_error(energy(series))),
        )  # fmt: skip
    except Exception as error:  # a refused point is a result, not a crash
        record.update(outcome="failed", reason=diagnostics.failure_reason(error))
    if not math.isfinite(record["error"]) and record["outcome"] == "ok":
        record.update(outcome="failed", reason="non-finite final state")
    return record


def _progress_line(method: Method, value: float, record: dict) -> str:
    failure = f"  FAILED: {record['reason'][:90]}" if record["reason"] else ""
    return (
        f"  {method.label:42s} {method.parameter} {value:<8.2g} run "
        f"{record['run_s']:8.2e} s, compile {record['compile_s']:5.2f} s, "
        f"error {record['error']:7.1e}, energy {record['energy_error']:7.1e}" + failure
    )


def run_case(case: Case, quick: bool, timing: dict) -> tuple[list[dict], float]:
    """Every point of every method on `case`: (records, the reference's floor)."""
    started = time.perf_counter()
    reference, floor = reference_state(case)
    energy = case_energy(case)
    records = []
    for method in all_methods(case, quick):
        for value in method.values:
            record = measure_point(case, method, value, reference, energy, timing)
            records.append(record)
            print(_progress_line(method, value, record), flush=True)
    seconds = time.perf_counter() - started
    print(f"  ({seconds:.0f} s; the reference's relative accuracy {floor:.0e})")
    return records, floor
