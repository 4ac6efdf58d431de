"""Implicit solvers in the fixed-step loop: failures are detected in the step without a
run-time branch, and reported after the loop.

A branch (`eqx.error_if`, a `lax.cond`) inside the step splits the loop body that
XLA would otherwise compile as one kernel; in RATTLE it cost 14× a hand-written loop
(`benchmarks/implicit_overhead.py`). The rule is "detect cheaply, diagnose late": a
failure poisons the state or sets the step's `RESULTS`, and `simulate` names it.
"""

import re

import diffrax
import jax
import jax.numpy as jnp
import pytest

import lagjax as lj
from lagjax.step_bodies import steps_per_trip

GRAVITY = 9.81


def pendulum(q, qdot):
    return 0.5 * qdot[0] ** 2 + GRAVITY * jnp.cos(q[0])


def particle(q, qdot):
    return 0.5 * jnp.sum(qdot**2) - GRAVITY * q[1]


def on_circle(q):
    return jnp.sum(q**2) - 1.0


def twice_on_circle(q):
    # The same constraint twice: G has rank 1 < 2 everywhere, G M⁻¹ Gᵀ is singular.
    return jnp.stack([on_circle(q), 2.0 * on_circle(q)])


PENDULUM_START = (jnp.array([1.0]), jnp.array([0.5]))
CIRCLE_START = (jnp.array([1.0, 0.0]), jnp.array([0.0, 0.5]))


def _computations(hlo: str) -> dict[str, str]:
    return {
        match.group(1): match.group(0)
        for match in re.finditer(r"\n(%[\w.\-]+) \([^\n]*\{\n.*?\n\}", hlo, re.S)
    }


def _reachable(
    name: str, computations: dict[str, str], *, into_loops: bool = True
) -> set[str]:
    """Computations called from `name`; with `into_loops=False` not those of
    nested loops (an iterative solve's own loop is one unit of the step)."""
    seen, todo = set(), [name]
    while todo:
        current = todo.pop()
        if current in seen or current not in computations:
            continue
        seen.add(current)
        text = computations[current]
        nested = set()
        if not into_loops:
            nested = set(re.findall(r"(?:body|condition)=(%[\w.\-]+)", text))
        todo += [c for c in re.findall(r"(%[\w.\-]+)", text) if c not in nested]
    return seen & computations.keys()


STEPS = 7  # t1 = 0.07 at dt = 0.01: a trip count no other loop here has


def _branches_in_step_loop(run, start, solver) -> tuple[int, int]:
    """In the fixed-step loop (of STEPS steps, `steps_per_trip` of them per trip,
    the rest after the loop): (conditionals outside nested loops, error checks
    anywhere). A branch steering a nested iteration (lineax's conjugate gradients
    inside Newton's loop) splits nothing the nested loop has not split already."""
    hlo = jax.jit(run).lower(start).compile().as_text()
    computations = _computations(hlo)
    trips = rf'known_trip_count":{{"n":"{STEPS // steps_per_trip(solver)}"}}'
    loops = re.findall(rf"while\([^\n]*body=(%[\w.\-]+)[^\n]*{trips}", hlo)
    assert loops, "no fixed-step loop found"

    def inside(into_loops):
        return set().union(
            *(_reachable(body, computations, into_loops=into_loops) for body in loops)
        )

    branches = sum(computations[c].count(" conditional(") for c in inside(False))
    error_checks = sum(
        len(re.findall(r" conditional\([^\n]*error_if", computations[c]))
        for c in inside(True)
    )
    return branches, error_checks


@pytest.mark.parametrize(
    ("system", "start", "solver"),
    [
        (lj.Lagrangian(pendulum), PENDULUM_START, lj.GaussLegendre(stages=2)),
        (lj.Lagrangian(pendulum), PENDULUM_START, lj.ImplicitMidpoint()),
        (lj.Lagrangian(pendulum), PENDULUM_START, lj.VariationalMidpoint()),
        (lj.Lagrangian(particle, constraints=on_circle), CIRCLE_START, lj.Rattle()),
    ],
)
def test_step_loop_has_no_run_time_branch(system, start, solver):
    def run(state):
        return lj.simulate(system, state, t1=STEPS * 0.01, dt=0.01, solver=solver).ys

    assert _branches_in_step_loop(run, start, solver) == (0, 0)


def test_rattle_on_redundant_constraints_reports_a_failed_run():
    # Not a silent finite trajectory: the run stops, says it failed and why
    # (non-finite state; with the default throw=True, simulate raises).
    lag = lj.Lagrangian(particle, constraints=twice_on_circle)

    @jax.jit
    def verdict(start):
        run = lj.simulate(lag, start, t1=0.1, dt=0.01, solver=lj.Rattle(), throw=False)
        return run.stats["finite"], run.result != diffrax.RESULTS.successful

    finite, failed = verdict(CIRCLE_START)
    assert not bool(finite)
    assert bool(failed)
