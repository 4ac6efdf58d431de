"""Physics tests of Blanes and Moan's sixth-order splittings `BlanesMoan6` (S10)
and `BlanesMoanNystrom6` (SRKN_11^b, for T quadratic in p).

The oracles are those of `test_splitting.py`: the log–log convergence slope on a
driven (time-dependent) pendulum and time reversibility (symplecticity is the
shared engine's, tested there on the other tables) — plus the reason each method
exists: a smaller energy error on an eccentric Kepler orbit than the method before
it at the same number of force evaluations (S10 against Yoshida's sixth-order
composition, the Nyström method against S10).
"""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.solvers.splitting import BlanesMoan6, BlanesMoanNystrom6, Yoshida6
from tests.helpers import tree_allclose

SOLVERS = [BlanesMoan6(), BlanesMoanNystrom6()]
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


KEPLER_Y0 = (jnp.array([0.4, 0.0]), jnp.array([0.0, 2.0]))  # e = 0.6, T = 2π


def largest_kepler_energy_error(solver, evaluations_per_period):
    """Largest |H − H₀| over 10 periods of Kepler e = 0.6 (one value per step)."""

    def energy(q, p):
        return 0.5 * jnp.sum(p * p, axis=-1) - 1 / jnp.linalg.norm(q, axis=-1)

    steps_per_period = evaluations_per_period // (len(solver.kick_coefficients) - 1)
    dt = 2 * np.pi / steps_per_period

    @jax.jit
    def energies():
        def body(y, k):
            y = one_step(solver, kepler_terms(), y, k * dt, dt)
            return y, energy(*y)

        _, values = jax.lax.scan(body, KEPLER_Y0, jnp.arange(10 * steps_per_period))
        return values

    return float(jnp.max(jnp.abs(energies() - energy(*KEPLER_Y0))))


def test_smaller_error_than_yoshida6_at_equal_cost():
    """At 700 force evaluations per period S10's largest energy error is 10×
    below Yoshida6's (measured 12.5×)."""
    reference = largest_kepler_energy_error(Yoshida6(), 700)
    assert largest_kepler_energy_error(BlanesMoan6(), 700) < reference / 10


def test_nystrom_method_beats_s10_at_equal_cost_for_quadratic_kinetic_energy():
    """At 770 force evaluations per period (70 Nyström steps, 77 S10 steps) the
    Nyström method's largest energy error on Kepler is 10× below S10's (measured
    33×, and 24× at 550 evaluations)."""
    reference = largest_kepler_energy_error(BlanesMoan6(), 770)
    assert largest_kepler_energy_error(BlanesMoanNystrom6(), 770) < reference / 10


def test_nystrom_method_refuses_a_non_quadratic_kinetic_energy():
    relativistic = lj.SeparableHamiltonian(
        lambda p: jnp.sqrt(1 + p**2),
        lambda q: 0.5 * q**2,
        quadratic_in_momentum=False,
    )
    with pytest.raises(ValueError, match=r"not quadratic.*BlanesMoan6"):
        lj.simulate(
            relativistic, (0.1, 0.0), t1=1.0, dt=0.1, solver=BlanesMoanNystrom6()
        )
