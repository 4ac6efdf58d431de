"""Backward runs (t1 < t0) read states between steps as forward runs do.

diffrax integrates t1 < t0 in reversed time τ = −t, with the sign in the terms'
`contr` and not in `vf`; the Hermite extension's slopes must be dy/dτ. Oracle: the
harmonic oscillator's q = cos t at save times off the step grid, through
diffeqsolve's loop (forced by a step-size controller) and through the scan, for the
cubic (Yoshida4) and the quintic (Yoshida6) extension.
"""

import diffrax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj

OSCILLATOR = lj.SeparableHamiltonian(lambda p: 0.5 * p**2, lambda q: 0.5 * q**2)
SAVE_TIMES = jnp.concatenate([jnp.zeros(1), jnp.linspace(-0.0031, -1.9031, 6)])


@pytest.mark.parametrize(
    "solver, bound",
    [(lj.Yoshida4(), 1e-8), (lj.Yoshida6(), 1e-13)],
    ids=["cubic", "quintic"],
)
@pytest.mark.parametrize("route", ["diffeqsolve", "scan"])
def test_backward_run_between_steps_follows_the_exact_solution(solver, bound, route):
    controller = diffrax.ConstantStepSize() if route == "diffeqsolve" else None
    trajectory = lj.simulate(
        OSCILLATOR,
        (jnp.array(1.0), jnp.array(0.0)),
        t0=0.0,
        t1=-2.0,
        dt=-0.01,
        solver=solver,
        ts=SAVE_TIMES,
        stepsize_controller=controller,
    )
    error = np.max(np.abs(np.asarray(trajectory.q) - np.cos(np.asarray(SAVE_TIMES))))
    # Before the fix the diffeqsolve route was off by 1.5e-3 (cubic), 2.5e-3 (quintic).
    assert error < bound, error
