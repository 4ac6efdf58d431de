"""Fixed steps in blocks: one failure test per block, the failing step found
after the loop.

Detect cheaply, diagnose late. `tracking_step_function` keeps the last good state
beside the running one at every step; for one trajectory that is free (off the
path from step to step, hidden behind its latency), but under `vmap` the step is
throughput-bound and the per-member finiteness test and selects cost in proportion
(compensated Störmer–Verlet on Kepler ×64: 1.45× a hand-written scan with them,
1.07× without; `benchmarks/solver_overhead.py`). Here the loop runs blocks of
`fast_step_function` steps, which carry only the state, the solver's state, its
first reported failure and the step index, and judges the state once at each
block's end: a good block moves the last good state (and the solver's state beside
it) up to its end; the first failed block leaves them at its start.

After the loop, only when some trajectory failed, `locate_failure` runs that block
again from its start with the tracking body, which finds the failing step, the last
good state and the steps up to it — the same arithmetic, so the same values bit for
bit as a run tracked at every step (tested). Its `lax.cond` is on `any_in_batch`,
so under `vmap` it stays a branch that a run without failures never takes, and it
sits outside the loop, so reverse-mode differentiation keeps residuals of one block
for it, not of every block.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import diffrax
import jax
import jax.numpy as jnp

from lagjax._core.batch_branch import any_in_batch
from lagjax._integrate.scan_body import (
    TrackingCarry,
    all_finite,
    first_failure,
    steps_per_trip,
    tree_select,
)

# Steps per block. The verdict at a block's end costs about one tracked step, so
# it is 0.4 % of a block's work; a failure is searched again over one block.
BLOCK_STEPS = 256

# Runs with fewer steps keep the tracked loop. The blocked loop compiles the step
# once more (the search; 0.13 s of 0.5 s for Yoshida4 on Kepler) and gains run time
# only under vmap (a quarter of it, Kepler ×64), which for a short run is far less
# than that compilation.
BLOCKED_MIN_STEPS = 32 * BLOCK_STEPS


class BlockCarry(NamedTuple):
    """What the blocked loop carries from block to block."""

    # The running state; its `last_good` and `taken` as of the last good block end.
    steps: TrackingCarry
    # The solver's state beside `last_good` (a compensated sum's error term), to
    # search a failed block from where it began.
    good_solver_state: Any


def start_blocks(initial: TrackingCarry) -> BlockCarry:
    return BlockCarry(initial, initial.solver_state)


def fast_block(
    one_fast_step, carry: BlockCarry, length: int, unroll: int
) -> BlockCarry:
    """`length` steps of `one_fast_step` (`unroll` per loop trip), then the
    block's verdict: the first failure of a trajectory good until now (the
    solver's, or `nonfinite`) is recorded; a good block moves the last good state
    to its end."""
    steps, _ = jax.lax.scan(
        one_fast_step, carry.steps, None, length=length, unroll=unroll
    )
    was_good = carry.steps.result == diffrax.RESULTS.successful
    verdict = diffrax.RESULTS.where(
        all_finite(steps.y),
        steps.result,
        diffrax.RESULTS.nonfinite,  # pyright: ignore[reportArgumentType]
    )
    good = was_good & (verdict == diffrax.RESULTS.successful)

    steps = steps._replace(
        result=first_failure(carry.steps.result, verdict),
        last_good=tree_select(good, steps.y, carry.steps.last_good),
        taken=jnp.where(good, steps.k, carry.steps.taken),
    )
    good_solver_state = tree_select(good, steps.solver_state, carry.good_solver_state)
    return BlockCarry(steps, good_solver_state)


def blocked_scan(
    one_fast_step,
    one_tracked_step,
    initial: TrackingCarry,
    steps: int,
    solver: diffrax.AbstractSolver,
) -> TrackingCarry:
    """`steps` steps from `initial` in blocks of `block_length(steps)` (a
    remainder first), failures located after the loop; the result of a tracked
    scan."""
    length = block_length(steps)
    blocks, remainder = divmod(steps, length)
    carry = start_blocks(initial)
    if remainder:
        # Fewer than one block's steps: not unrolled, to compile a smaller body.
        carry = fast_block(one_fast_step, carry, remainder, unroll=1)

    def block(carry, _):
        return fast_block(one_fast_step, carry, length, steps_per_trip(solver)), None

    carry, _ = jax.lax.scan(block, carry, None, length=blocks)
    return locate_failure(one_tracked_step, carry, length)


def block_length(steps: int) -> int:
    """The divisor of `steps` nearest `BLOCK_STEPS` within a factor of two of it,
    so that no remainder block is compiled; `BLOCK_STEPS` if there is none."""
    divisors = [
        length
        for length in range(BLOCK_STEPS // 2, 2 * BLOCK_STEPS + 1)
        if steps % length == 0
    ]
    return min(divisors, key=lambda d: abs(d - BLOCK_STEPS), default=BLOCK_STEPS)


def locate_failure(one_tracked_step, carry: BlockCarry, length: int) -> TrackingCarry:
    """The loop's final `TrackingCarry`, with each failed trajectory's failing
    step found: its failed block (at most `length` steps) run again from its start
    with the tracking body. Runs only when some trajectory failed."""
    failed = carry.steps.result != diffrax.RESULTS.successful

    def search(steps: TrackingCarry) -> TrackingCarry:
        start = TrackingCarry(
            steps.last_good,
            carry.good_solver_state,
            diffrax.RESULTS.successful,
            steps.taken,
            steps.last_good,
            steps.taken,
        )
        found, _ = jax.lax.scan(one_tracked_step, start, None, length=length)
        # Steps past the failed block cannot matter: the first failure is kept.
        located = failed & (found.result != diffrax.RESULTS.successful)

        return steps._replace(
            result=diffrax.RESULTS.where(located, found.result, steps.result),
            last_good=tree_select(located, found.last_good, steps.last_good),
            taken=jnp.where(located, found.taken, steps.taken),
        )

    return jax.lax.cond(any_in_batch(failed), search, lambda steps: steps, carry.steps)
