"""`simulate` compiles like a hand-written jitted `diffeqsolve`: once per configuration.

Counted, not timed: XLA compilations are jax's `backend_compile` events. All the
numeric work of a run is one compiled call (`lagjax._integrate.simulate._compiled_run`), so a
first call compiles no more often than `diffeqsolve` on hand-written equations of
the same system and solver, and a second call with a new `y0` (or new parameters)
of the same shapes compiles nothing. The runs are checked against the exact
solution of the harmonic oscillator, q = q0 cos t + q̇0 sin t.
"""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from tests.helpers import counted_compilations

OSCILLATOR = lj.Lagrangian(lambda q, qd: 0.5 * qd**2 - 0.5 * q**2)
KEPLER = lj.SeparableHamiltonian(
    lambda p: 0.5 * jnp.sum(p * p), lambda q: -1.0 / jnp.sqrt(jnp.sum(q * q))
)


def exact(q0, qd0, t):
    return q0 * np.cos(t) + qd0 * np.sin(t)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_first_call_compiles_no_more_than_diffeqsolve():
    solver = diffrax.Tsit5()
    controller = diffrax.PIDController(rtol=1e-10, atol=1e-10)
    term = diffrax.ODETerm(lambda t, y, args: (y[1], -y[0]))
    hand = jax.jit(
        lambda y0: (
            diffrax.diffeqsolve(
                term, solver, 0.0, 3.0, None, y0, stepsize_controller=controller
            ).ys
        )
    )
    y0 = (np.float64(0.7), np.float64(-0.2))
    jax.clear_caches()
    with counted_compilations() as by_hand:
        jax.block_until_ready(hand(y0))
    jax.clear_caches()
    with counted_compilations() as by_simulate:
        run = lj.simulate(
            OSCILLATOR, y0, 0.0, 3.0, solver=solver, rtol=1e-10, atol=1e-10
        )
        jax.block_until_ready(run.ys)
    assert 1 <= len(by_simulate) <= len(by_hand)
    np.testing.assert_allclose(run.q[-1], exact(0.7, -0.2, 3.0), rtol=1e-8)


def test_second_call_with_new_start_compiles_nothing():
    def final_q(y0):
        run = lj.simulate(OSCILLATOR, y0, 0.0, 2.0, solver=diffrax.Dopri5())
        return run.q[-1], run.stats["finite"]

    final_q((jnp.asarray(1.0), jnp.asarray(0.0)))
    with counted_compilations() as compiled:
        q1, finite = final_q((jnp.asarray(0.3), jnp.asarray(0.5)))
        jax.block_until_ready(q1)
    assert compiled == []
    assert bool(finite)
    np.testing.assert_allclose(q1, exact(0.3, 0.5, 2.0), rtol=1e-6)


def test_scan_path_with_saves_reuses_its_compilation():
    """Fixed steps saving on the step grid (nested scans): the save times are part
    of the configuration, the start is not. Kepler's energy is kept to the
    splitting's order."""
    ts = np.linspace(0.0, 2.0, 11)

    def energies(y0):
        run = lj.simulate(KEPLER, y0, 0.0, 2.0, dt=0.01, solver=lj.Yoshida4(), ts=ts)
        return run.energy()

    energies((jnp.array([1.0, 0.0]), jnp.array([0.0, 1.0])))
    start = (jnp.array([0.5, 0.0]), jnp.array([0.0, 1.6]))
    with counted_compilations() as compiled:
        energy = jax.block_until_ready(energies(start))
    assert compiled == []
    # Yoshida4 keeps H to O(h⁴) = 1e-8 times a constant of this eccentric orbit.
    np.testing.assert_allclose(energy, KEPLER(*start), rtol=1e-6)
    # The same run inside a user's jit: the save times still reach the scans as
    # values (a traced copy would send the run down diffeqsolve's loop).
    traced = jax.jit(energies)(start)
    np.testing.assert_allclose(traced, KEPLER(*start), rtol=1e-6)
