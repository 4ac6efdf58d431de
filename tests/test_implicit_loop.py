"""Implicit solvers in the fixed-step loop: failures are detected in the step without a
run-time branch, and reported after the loop.

A branch (`eqx.error_if`, a `lax.cond`) inside the step splits the loop body that
XLA would otherwise compile as one kernel; in RATTLE it cost 14× a hand-written loop
(`benchmarks/implicit_overhead.py`), and so does a LAPACK call (a custom call) in
the step's Newton iteration. The rule is "detect cheaply, diagnose late": a
failure poisons the state or sets the step's `RESULTS`, and `simulate` names it.
"""

import re

import diffrax
import jax
import jax.numpy as jnp
import pytest

import lagjax as lj
from lagjax._integrate.scan_body import steps_per_trip

GRAVITY = 9.81


def pendulum(q, qdot):
    return 0.5 * qdot[0] ** 2 + GRAVITY * jnp.cos(q[0])


def particle(q, qdot):
    return 0.5 * jnp.sum(qdot**2) - GRAVITY * q[1]


def particle_chain(q, qdot):
    return 0.5 * jnp.sum(qdot**2) - GRAVITY * jnp.sum(q[1::2])


def on_circle(q):
    return jnp.sum(q**2) - 1.0


def twice_on_circle(q):
    # The same constraint twice: G has rank 1 < 2 everywhere, G M⁻¹ Gᵀ is singular.
    return jnp.stack([on_circle(q), 2.0 * on_circle(q)])


def rods_of_a_hanging_chain(q):
    # Unit rods from the origin through the particles (x_i, y_i) in turn.
    joints = jnp.concatenate([jnp.zeros(2), q]).reshape(-1, 2)
    return jnp.sum(jnp.diff(joints, axis=0) ** 2, axis=1) - 1.0


def hanging_chain_start(particles):
    # Hanging straight down and swinging: every velocity horizontal, so each rod's
    # length is stationary.
    q = jnp.stack([jnp.zeros(particles), -jnp.arange(1.0, particles + 1)], axis=1)
    qdot = jnp.stack([0.3 * jnp.arange(1.0, particles + 1), jnp.zeros(particles)], 1)
    return q.ravel(), qdot.ravel()


PENDULUM_START = (jnp.array([1.0]), jnp.array([0.5]))
CIRCLE_START = (jnp.array([1.0, 0.0]), jnp.array([0.0, 0.5]))
CHAIN = lj.Lagrangian(particle_chain, constraints=rods_of_a_hanging_chain)


def _computations(hlo: str) -> dict[str, str]:
    return {
        match.group(1): match.group(0)
        for match in re.finditer(r"\n(%[\w.\-]+) \([^\n]*\{\n.*?\n\}", hlo, re.S)
    }


def _reachable(name: str, computations: dict[str, str]) -> set[str]:
    """Computations called from `name`, nested loops' bodies included."""
    seen, todo = set(), [name]
    while todo:
        current = todo.pop()
        if current in seen or current not in computations:
            continue
        seen.add(current)
        todo += re.findall(r"(%[\w.\-]+)", computations[current])
    return seen & computations.keys()


STEPS = 7  # t1 = 0.07 at dt = 0.01: a trip count no other loop here has


def _splitters_in_step_loop(run, start, solver) -> tuple[int, int]:
    """In the fixed-step loop (of STEPS steps, `steps_per_trip` of them per trip,
    the rest after the loop), nested solver loops included: (conditionals,
    custom calls). Either keeps XLA on CPU from compiling the body as one kernel:
    a branch, and a LAPACK routine (lineax's default LU in Newton's loop cost
    `VariationalMidpoint` 9× its hand-written twin)."""
    hlo = jax.jit(run).lower(start).compile().as_text()
    computations = _computations(hlo)
    trips = rf'known_trip_count":{{"n":"{STEPS // steps_per_trip(solver)}"}}'
    loops = re.findall(rf"while\([^\n]*body=(%[\w.\-]+)[^\n]*{trips}", hlo)
    assert loops, "no fixed-step loop found"
    inside = set().union(*(_reachable(body, computations) for body in loops))
    branches = sum(computations[c].count(" conditional(") for c in inside)
    # A GPU compiles a matrix product to a cuBLAS custom call: no factorization,
    # and no kernel boundary a CPU would pay for (4 of them in RATTLE's 4-constraint
    # step on an H200). Factorizations (LAPACK, cuSOLVER) are what this counts.
    custom_calls = sum(
        1
        for c in inside
        for line in computations[c].splitlines()
        if " custom-call(" in line and not re.search(r"gemm|matmul", line)
    )
    return branches, custom_calls


@pytest.mark.parametrize(
    ("system", "start", "solver"),
    [
        (lj.Lagrangian(pendulum), PENDULUM_START, lj.GaussLegendre(stages=2)),
        (lj.Lagrangian(pendulum), PENDULUM_START, lj.ImplicitMidpoint()),
        (lj.Lagrangian(pendulum), PENDULUM_START, lj.VariationalMidpoint()),
        (lj.Lagrangian(particle, constraints=on_circle), CIRCLE_START, lj.Rattle()),
        # Two and four constraints: SHAKE's Newton solves a 2 × 2 and a 4 × 4
        # system (lineax's default LU called LAPACK there), and the momentum
        # projection above 3 constraints a 4 × 4 one.
        (CHAIN, hanging_chain_start(2), lj.Rattle()),
        (CHAIN, hanging_chain_start(4), lj.Rattle()),
    ],
)
def test_step_loop_has_no_branch_and_no_lapack_call(system, start, solver):
    def run(state):
        return lj.simulate(system, state, t1=STEPS * 0.01, dt=0.01, solver=solver).ys

    assert _splitters_in_step_loop(run, start, solver) == (0, 0)


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
