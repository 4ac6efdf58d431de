"""The blocked fixed-step loop gives what a loop tracked at every step gives.

Long runs (`BLOCKED_MIN_STEPS` or more) test the state once per block and search a
failed block again after the loop (`lagjax/blocked_loop.py`). The reference is the
tracked loop, the specification of a failed run: the last good state, the steps up
to it and the first failure. Störmer–Verlet on q̈ = −kq with k = 10⁴ and h = 1/32
(ωh = 3.1 > 2, HLW §I.5) multiplies the state by about 9 per step, so the starting
amplitude sets the step at which it overflows: in the first steps, mid-block, or
never (a stable k). h = 1/32 keeps every grid time exact.
"""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lagjax._integrate.blocked_loop import BLOCKED_MIN_STEPS, block_length
from lagjax._integrate.fixed_step_loop import (
    integrate_every_step,
    integrate_fixed_steps,
    integrate_fixed_steps_saving,
)
from lagjax._integrate.scan_body import (
    initial_tracking_carry,
    tracking_scan,
    tracking_step_function,
)
from lagjax.solvers.splitting import StormerVerlet

TERMS = (
    diffrax.ODETerm(lambda t, p, k: p),
    diffrax.ODETerm(lambda t, q, k: -k * q),
)
DT = 1 / 32
# A prime number of steps: a remainder block of 17 steps, then blocks of 256.
PRIME_STEPS = 8209
# (stiffness, amplitude): overflow within the remainder block, at the first step
# of the first whole block, in later blocks at both step parities, and a stable run.
MEMBERS = [
    (1e4, 1e300),
    (1e4, 1e289),
    (1e4, 1e-300),
    (1e4, 1.0),
    (1e4, 1e10),
    (1.0, 1.0),
]


def tracked(solver, y0, k, steps):
    """The tracked loop's (last good state, result, steps up to it)."""
    one_step = tracking_step_function(
        TERMS, solver, 0.0, DT, k, float, steps - 1, steps * DT
    )
    initial = initial_tracking_carry(TERMS, solver, 0.0, DT, y0, k, float)
    final, _ = tracking_scan(one_step, initial, steps, solver)
    return final.last_good, final.result, final.taken


def batch():
    stiffness = jnp.asarray([k for k, _ in MEMBERS])
    q0 = jnp.asarray([a for _, a in MEMBERS])
    return (q0, jnp.zeros_like(q0)), stiffness


def test_the_runs_below_are_long_enough_to_be_blocked():
    assert PRIME_STEPS >= BLOCKED_MIN_STEPS
    assert block_length(PRIME_STEPS) == 256 and PRIME_STEPS % 256 == 17
    assert block_length(4000) == 250  # a divisor: no remainder block


@pytest.mark.parametrize("compensated", [True, False])
def test_batched_failures_match_the_tracked_loop_bit_for_bit(compensated):
    solver = StormerVerlet(compensated=compensated)
    y0, k = batch()
    t1 = PRIME_STEPS * DT

    def blocked(y0, k):
        return integrate_fixed_steps(TERMS, solver, 0.0, t1, DT, y0, k)

    (q, p), result, taken = jax.jit(jax.vmap(blocked))(y0, k)
    (q_ref, p_ref), result_ref, taken_ref = jax.jit(
        jax.vmap(lambda y0, k: tracked(solver, y0, k, PRIME_STEPS))
    )(y0, k)
    taken = np.asarray(taken)
    # The members fail at different steps, in different blocks, or not at all.
    assert taken[0] < 17 and taken[1] == 17
    assert 256 < taken[4] < taken[3] < taken[2] < PRIME_STEPS
    assert taken[3] % 2 != taken[4] % 2
    assert taken[-1] == PRIME_STEPS and len(set(taken.tolist())) == len(MEMBERS)
    np.testing.assert_array_equal(taken, np.asarray(taken_ref))
    np.testing.assert_array_equal(np.asarray(result._value), result_ref._value)
    np.testing.assert_array_equal(np.asarray(q), np.asarray(q_ref))
    np.testing.assert_array_equal(np.asarray(p), np.asarray(p_ref))
    assert np.all(np.isfinite(np.asarray(q)))
    expected = [diffrax.RESULTS.nonfinite] * 5 + [diffrax.RESULTS.successful]
    np.testing.assert_array_equal(
        np.asarray(result._value), [int(want._value) for want in expected]
    )


def test_saved_states_after_a_failure_hold_the_last_good_state():
    solver = StormerVerlet()
    y0, k = batch()
    lead, every, saves = 3, 300, 30
    steps = lead + every * (saves - 1)  # 8703: blocked

    def saving(y0, k):
        grid = (lead, every, saves)
        return integrate_fixed_steps_saving(TERMS, solver, 0.0, DT, grid, y0, k)

    def every_state(y0, k):
        # The tracked loop keeping every step (the last good state from a failure on).
        _, (qs, _), _, result, taken = integrate_every_step(
            TERMS, solver, 0.0, steps * DT, DT, y0, k
        )
        return jnp.concatenate([y0[0][None], qs]), taken, result

    (qs, _), result, taken, saved = jax.jit(jax.vmap(saving))(y0, k)
    q_ref, taken_ref, result_ref = jax.jit(jax.vmap(every_state))(y0, k)
    save_steps = lead + every * np.arange(saves)
    # saved: the save's step was reached; the others hold the last good state.
    np.testing.assert_array_equal(
        np.asarray(saved), save_steps[None, :] <= np.asarray(taken_ref)[:, None]
    )
    np.testing.assert_array_equal(np.asarray(qs), np.asarray(q_ref)[:, save_steps])
    np.testing.assert_array_equal(np.asarray(taken), np.asarray(taken_ref))
    np.testing.assert_array_equal(np.asarray(result._value), result_ref._value)
    assert np.any(~np.asarray(saved)) and np.any(np.asarray(saved)[:, 1:])


def test_gradients_through_the_blocked_loop_match_the_tracked_loop():
    # A stable run: d q(T) / d (q0, p0) and d q(T) / dk, reverse mode.
    solver = StormerVerlet()
    steps = 2 * BLOCKED_MIN_STEPS + 7

    def final_q(y0, k, loop):
        if loop == "blocked":
            (q, _), *_ = integrate_fixed_steps(
                TERMS, solver, 0.0, steps * DT, DT, y0, k
            )
        else:
            (q, _), *_ = tracked(solver, y0, k, steps)
        return q

    y0, k = (jnp.asarray(0.3), jnp.asarray(-0.2)), jnp.asarray(2.0)
    blocked = jax.grad(final_q, argnums=(0, 1))(y0, k, "blocked")
    reference = jax.grad(final_q, argnums=(0, 1))(y0, k, "tracked")
    for got, want in zip(jax.tree.leaves(blocked), jax.tree.leaves(reference)):
        np.testing.assert_allclose(float(got), float(want), rtol=1e-12)
        assert float(got) != 0.0
