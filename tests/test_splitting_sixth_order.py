"""Physics tests of Blanes and Moan's sixth-order splitting `BlanesMoan6`.

The oracles are those of `test_splitting.py`: the log–log convergence slope on a
driven (time-dependent) pendulum and time reversibility (symplecticity is the
shared engine's, tested there on the other tables) — plus the reason the method
exists: a smaller energy error on an eccentric Kepler orbit than Yoshida's
sixth-order composition at the same number of force evaluations.
"""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lagjax.solvers.splitting import BlanesMoan6, Yoshida6
from tests.helpers import tree_allclose

SOLVERS = [BlanesMoan6()]
SOLVER_IDS = [type(solver).__name__ for solver in SOLVERS]


def drift(t, p, args):
    return p


def driven_pendulum_terms():
    """V(q, t) = −cos q − 0.1 q cos(0.7 t): nonlinear and time-dependent."""

    def kick(t, q, args):
        return -jnp.sin(q) + 0.1 * jnp.cos(0.7 * t)

    return diffrax.ODETerm(drift), diffrax.ODETerm(kick)


def kepler_terms():
    def kick(t, q, args):
        r_squared = jnp.sum(q * q)
        return -q / (r_squared * jnp.sqrt(r_squared))

    return diffrax.ODETerm(drift), diffrax.ODETerm(kick)


def one_step(solver, terms, y, t0, dt):
    state = solver.init(terms, t0, t0 + dt, y, None)
    y1, *_ = solver.step(terms, t0, t0 + dt, y, None, state, False)
    return y1


def final_states(solver, terms, y0, t1, step_counts):
    """Final states for each step count: one compiled loop, vmapped over counts."""

    @jax.jit
    @jax.vmap
    def final_state(steps):
        dt = t1 / steps

        def body(k, y):
            return one_step(solver, terms, y, k * dt, dt)

        return jax.lax.fori_loop(0, steps, body, y0)

    return final_state(jnp.asarray(step_counts, dtype=int))


PENDULUM_T = 50.0
PENDULUM_Y0 = (jnp.array(0.5), jnp.array(0.0))


@pytest.mark.parametrize("solver", SOLVERS, ids=SOLVER_IDS)
def test_sixth_order_on_driven_pendulum(solver):
    # Errors against the same method at a 4× finer step (its error is 4⁶ times
    # smaller); the range h = 0.5 … 0.29 keeps them between 1e-6 and 1e-10.
    step_counts = np.round(PENDULUM_T / (0.5 * 1.2 ** -np.arange(4)))
    all_counts = np.concatenate([step_counts, 4 * step_counts])
    q, p = final_states(
        solver, driven_pendulum_terms(), PENDULUM_Y0, PENDULUM_T, all_counts
    )
    errors = np.maximum(np.abs(q[:4] - q[4:]), np.abs(p[:4] - p[4:]))
    assert np.all(errors > 1e-12), "step range reaches round-off; slope meaningless"
    slope = np.polyfit(np.log(PENDULUM_T / step_counts), np.log(errors), 1)[0]
    assert abs(slope - 6) <= 0.2, f"slope {slope:.3f}, nominal 6"


@pytest.mark.parametrize("solver", SOLVERS, ids=SOLVER_IDS)
def test_one_step_is_reversible(solver):
    # Symplecticity is the shared engine's (a product of exact kick and drift
    # flows), checked on the other tables in test_splitting.py.
    terms = kepler_terms()
    y0 = (jnp.array([0.7, 0.2]), jnp.array([-0.3, 1.1]))

    @jax.jit
    def step(y):
        return one_step(solver, terms, y, 0.0, 0.3)

    forward = step(y0)
    back = step((forward[0], -forward[1]))
    assert tree_allclose((back[0], -back[1]), y0, rtol=0, atol=1e-13)


def test_smaller_error_than_yoshida6_at_equal_cost():
    """Kepler e = 0.6 over 10 periods at 700 force evaluations per period: the
    optimised method's largest energy error is 10× below Yoshida6's (measured
    12.5×)."""
    y0 = (jnp.array([0.4, 0.0]), jnp.array([0.0, 2.0]))

    def energy(q, p):
        return 0.5 * jnp.sum(p * p, axis=-1) - 1 / jnp.linalg.norm(q, axis=-1)

    def largest_energy_error(solver, stages):
        steps_per_period = 700 // stages
        dt = 2 * np.pi / steps_per_period

        @jax.jit
        def energies():
            def body(y, k):
                y = one_step(solver, kepler_terms(), y, k * dt, dt)
                return y, energy(*y)

            _, values = jax.lax.scan(body, y0, jnp.arange(10 * steps_per_period))
            return values

        return float(jnp.max(jnp.abs(energies() - energy(*y0))))

    reference = largest_energy_error(Yoshida6(), 7)
    assert largest_energy_error(BlanesMoan6(), 10) < reference / 10
