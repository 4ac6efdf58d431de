"""Physics tests of the explicit symplectic splitting solvers.

Each test uses physics as the oracle: convergence order on a driven nonlinear pendulum,
the symplectic condition MᵀJM = J on the one-step Jacobian, time reversibility,
bounded energy error and exact angular-momentum conservation on a Kepler orbit,
and Brouwer's law for round-off with compensated summation.
"""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lagjax.mechanics.canonical import symplectic_defect
from lagjax.solvers.splitting import (
    BlanesMoan4,
    KahanLi8,
    SofSpa10,
    StormerVerlet,
    Yoshida4,
    Yoshida6,
)
from tests.helpers import tree_allclose

SOLVERS = [StormerVerlet(), Yoshida4(), BlanesMoan4(), Yoshida6(), KahanLi8()]
SOLVERS += [SofSpa10()]
SOLVER_IDS = [type(solver).__name__ for solver in SOLVERS]


def drift(t, p, args):
    return p


def separable_terms(force):
    return diffrax.ODETerm(drift), diffrax.ODETerm(lambda t, q, args: force(q))


def henon_heiles_force(q):
    x, y = q[..., 0], q[..., 1]
    return -jnp.stack([x + 2 * x * y, y + x**2 - y**2], axis=-1)


def kepler_force(q):
    r_squared = jnp.sum(q * q, axis=-1, keepdims=True)
    return -q / (r_squared * jnp.sqrt(r_squared))


# Measurements after a run are made in numpy: run eagerly in JAX, each of their
# small operations would compile on its own.
def kepler_energy(q, p):
    q, p = np.asarray(q), np.asarray(p)
    return 0.5 * np.sum(p * p, axis=-1) - 1 / np.linalg.norm(q, axis=-1)


def angular_momentum(q, p):
    q, p = np.asarray(q), np.asarray(p)
    return q[..., 0] * p[..., 1] - q[..., 1] * p[..., 0]


KEPLER_Y0 = (jnp.array([0.4, 0.0]), jnp.array([0.0, 2.0]))  # e = 0.6, period 2π


def solve(terms, solver, t1, dt, y0, saveat, max_steps, controller=None):
    return diffrax.diffeqsolve(
        terms,
        solver,
        0.0,
        t1,
        dt,
        y0,
        saveat=saveat,
        stepsize_controller=controller or diffrax.ConstantStepSize(),
        max_steps=max_steps,
    )


# --- Convergence order -----------------------------------------------------------
# Driven pendulum V(q, t) = −cos q − 0.1 q cos(0.7 t) released from 0.5 rad, final
# state at T = 100. The drive makes V time-dependent, so kicks evaluated at wrong
# sub-step times would lower the order too. The long horizon lifts the (phase)
# error well above round-off, which the order-10 method needs.
PENDULUM_T = 100.0
PENDULUM_Y0 = (jnp.array(0.5), jnp.array(0.0))


def driven_pendulum_terms():
    def kick(t, q, args):
        return -jnp.sin(q) + 0.1 * jnp.cos(0.7 * t)

    return diffrax.ODETerm(drift), diffrax.ODETerm(kick)


# Coarsest step of each solver's asymptotic range (error 1e-4 … 1e-13).
COARSEST_STEP = {
    StormerVerlet: 0.1,
    Yoshida4: 0.3,
    BlanesMoan4: 0.75,
    Yoshida6: 0.5,
    KahanLi8: 0.6,
    SofSpa10: 0.62,
}


def pendulum_final_states(solver, step_counts):
    """Final (q, p) for each step count, one compiled solve vmapped over dt."""

    @jax.jit
    @jax.vmap
    def final_state(dt):
        sol = solve(
            driven_pendulum_terms(),
            solver,
            PENDULUM_T,
            dt,
            PENDULUM_Y0,
            diffrax.SaveAt(t1=True),
            max_steps=4096,
        )
        return sol.ys[0][-1], sol.ys[1][-1]

    return final_state(PENDULUM_T / jnp.asarray(step_counts, dtype=float))


def order_step_counts(solver):
    """Four step counts, h from the solver's coarsest asymptotic step down by 1.2⁻ᵏ."""
    coarsest = COARSEST_STEP[type(solver)]
    return np.round(PENDULUM_T / (coarsest * 1.2 ** -np.arange(4)))


@pytest.fixture(scope="module")
def sofspa10_pendulum():
    """SofSpa10's final states at h = 0.05 (the reference: truncation error far below
    round-off) and at its own four order-test steps, from one compiled solve."""
    step_counts = [2000, *order_step_counts(SofSpa10())]
    q, p = pendulum_final_states(SofSpa10(), step_counts)
    return (q[0], p[0]), (q[1:], p[1:])


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
@pytest.mark.parametrize("solver", SOLVERS, ids=SOLVER_IDS)
def test_convergence_order_on_driven_pendulum(solver, sofspa10_pendulum):
    step_counts = order_step_counts(solver)
    (q_ref, p_ref), sofspa10_states = sofspa10_pendulum
    if isinstance(solver, SofSpa10):
        q, p = sofspa10_states  # already solved with the reference
    else:
        q, p = pendulum_final_states(solver, step_counts)
    errors = np.maximum(np.abs(q - q_ref), np.abs(p - p_ref))
    assert np.all(errors > 1e-13), "step range reaches round-off; slope meaningless"
    slope = np.polyfit(np.log(PENDULUM_T / step_counts), np.log(errors), 1)[0]
    nominal = solver.order(driven_pendulum_terms())
    assert abs(slope - nominal) <= 0.2, f"slope {slope:.3f}, nominal {nominal}"


# --- Symplecticity and reversibility ------------------------------------------------
HH_Q0, HH_P0 = jnp.array([0.1, -0.2]), jnp.array([0.3, 0.25])
HH_STEP = 0.2


def one_step_map(solver, terms, h):
    """(q, p) -> one step of `solver`, starting from its freshly initialised state."""

    def phase_map(q, p):
        state = solver.init(terms, 0.0, h, (q, p), None)
        y1, *_ = solver.step(terms, 0.0, h, (q, p), None, state, False)
        return y1

    return phase_map


@pytest.mark.parametrize("solver", SOLVERS, ids=SOLVER_IDS)
def test_one_step_is_symplectic_on_henon_heiles(solver):
    phase_map = one_step_map(solver, separable_terms(henon_heiles_force), HH_STEP)
    assert symplectic_defect(phase_map, HH_Q0, HH_P0) <= 1e-12


def test_tsit5_step_is_not_symplectic_on_henon_heiles():
    """Sanity check that the defect test can fail: Tsit5 is not symplectic."""

    def vector_field(t, y, args):
        q, p = y
        return p, henon_heiles_force(q)

    term = diffrax.ODETerm(vector_field)
    solver = diffrax.Tsit5(scan_kind="lax")  # the default loop is not jvp-able

    def phase_map(q, p):
        state = solver.init(term, 0.0, HH_STEP, (q, p), None)
        y1, *_ = solver.step(term, 0.0, HH_STEP, (q, p), None, state, False)
        return y1

    assert symplectic_defect(phase_map, HH_Q0, HH_P0) > 1e-9


@pytest.mark.parametrize("solver", SOLVERS, ids=SOLVER_IDS)
def test_step_then_reverse_step_returns_to_start(solver):
    terms = separable_terms(henon_heiles_force)
    h = 0.3

    # Eager, not jitted: two steps are a few hundred small operations, and
    # compiling them (3.6 s for SofSpa10) costs far more than dispatching them.
    def there_and_back(y0):
        state = solver.init(terms, 0.0, h, y0, None)
        y1, _, _, state, _ = solver.step(terms, 0.0, h, y0, None, state, False)
        y2, *_ = solver.step(terms, h, 0.0, y1, None, state, False)
        return y1, y2

    y1, y2 = there_and_back((HH_Q0, HH_P0))
    assert not tree_allclose(y1, (HH_Q0, HH_P0), rtol=0, atol=1e-3)
    assert tree_allclose(y2, (HH_Q0, HH_P0), rtol=0, atol=1e-13)


# --- Long-time behaviour on the Kepler problem --------------------------------------
KEPLER_PERIODS = 10_000
KEPLER_T1 = 2 * np.pi * KEPLER_PERIODS
KEPLER_STEPS = 2**20  # ≈ 105 steps per period


def step_aligned_saveat(t1, steps, intervals):
    """Save times that are exactly step times, so nothing saved is interpolated.

    diffrax places step k at t1·(k/steps); with power-of-two counts both that and
    t1·(j/intervals) are exact fractions, so the products agree bit for bit.
    """
    assert steps % intervals == 0
    return diffrax.SaveAt(ts=t1 * (jnp.arange(intervals + 1) / intervals))


KEPLER_SAVEAT = step_aligned_saveat(KEPLER_T1, KEPLER_STEPS, 256)


def halves_of_energy_error(q, p):
    """max |ΔH| over the first and over the second half of the saved points."""
    error = np.abs(kepler_energy(q, p) - kepler_energy(*KEPLER_Y0))
    middle = len(error) // 2
    return error[: middle + 1].max(), error[middle:].max()


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_kepler_energy_bounded_for_yoshida4_but_drifts_for_tsit5():
    yoshida = solve(
        separable_terms(kepler_force),
        Yoshida4(),
        KEPLER_T1,
        KEPLER_T1 / KEPLER_STEPS,
        KEPLER_Y0,
        KEPLER_SAVEAT,
        max_steps=KEPLER_STEPS,
    )
    yoshida_force_evaluations = 3 * KEPLER_STEPS

    def vector_field(t, y, args):
        q, p = y
        return p, kepler_force(q)

    tsit5 = solve(
        diffrax.ODETerm(vector_field),
        diffrax.Tsit5(),
        KEPLER_T1,
        0.01,
        KEPLER_Y0,
        KEPLER_SAVEAT,
        max_steps=KEPLER_STEPS,
        controller=diffrax.PIDController(rtol=1e-6, atol=1e-6),
    )
    tsit5_evaluations = 6 * int(tsit5.stats["num_steps"])
    assert 0.5 < tsit5_evaluations / yoshida_force_evaluations < 1.5

    yoshida_first, yoshida_second = halves_of_energy_error(*yoshida.ys)
    tsit5_first, tsit5_second = halves_of_energy_error(*tsit5.ys)
    assert yoshida_second <= 2 * yoshida_first
    assert tsit5_second >= 1.5 * tsit5_first

    q, p = yoshida.ys
    initial = angular_momentum(*KEPLER_Y0)
    assert np.max(np.abs(angular_momentum(q, p) / initial - 1)) <= 1e-12


# 100 periods at ≈ 82 steps each, saved at 129 step times: one compiled program per solver.
ORBIT_T1, ORBIT_STEPS = 2 * np.pi * 100, 2**13
ORBIT_SAVEAT = step_aligned_saveat(ORBIT_T1, ORBIT_STEPS, 128)


@eqx.filter_jit
def kepler_orbit(solver, q0, p0):
    """(q, p) at the saved times of a 100-period Kepler run from (q0, p0)."""
    sol = solve(
        separable_terms(kepler_force),
        solver,
        ORBIT_T1,
        ORBIT_T1 / ORBIT_STEPS,
        (q0, p0),
        ORBIT_SAVEAT,
        max_steps=ORBIT_STEPS,
    )
    return sol.ys


@pytest.mark.parametrize("solver", SOLVERS, ids=SOLVER_IDS)
def test_angular_momentum_conserved_to_round_off(solver):
    """Drifts and central kicks both leave q × p unchanged, so only round-off remains."""
    q, p = kepler_orbit(solver, *KEPLER_Y0)
    assert np.abs(kepler_energy(q, p) - kepler_energy(*KEPLER_Y0)).max() > 0
    initial = angular_momentum(*KEPLER_Y0)
    assert np.max(np.abs(angular_momentum(q, p) / initial - 1)) <= 1e-12


def test_compensated_summation_keeps_round_off_at_machine_precision():
    """2²⁰ ≈ 10⁶ Störmer–Verlet steps of the harmonic oscillator.

    Störmer–Verlet conserves H̃ = p²/2 + (1 − h²/4) q²/2 exactly, so every change
    in H̃ is round-off. Adding each step's increment directly lets round-off of the
    size ε|y| random-walk (≈ ε√n); compensated summation reduces it to ε h|y| per
    step.
    """
    h, steps = 2.0**-10, 2**20
    terms = separable_terms(lambda q: -q)
    y0 = (jnp.array(1.0), jnp.array(0.0))
    saveat = step_aligned_saveat(h * steps, steps, 256)

    def modified_energy(q, p):
        return 0.5 * p**2 + 0.5 * (1 - h**2 / 4) * q**2

    def modified_energy_error(solver):
        sol = solve(terms, solver, h * steps, h, y0, saveat, max_steps=steps)
        q, p = (np.asarray(leaf) for leaf in sol.ys)  # numpy: no small compilations
        start = modified_energy(*(np.asarray(leaf) for leaf in y0))
        return np.abs(modified_energy(q, p) - start).max()

    compensated = modified_energy_error(StormerVerlet())
    plain = modified_energy_error(StormerVerlet(compensated=False))
    assert compensated <= 1e-15  # a few ulps after 10⁶ steps
    assert plain >= 20 * max(compensated, np.finfo(float).eps / 2)


@pytest.mark.parametrize("solver_class", [StormerVerlet, Yoshida4])
def test_uncompensated_step_is_a_hand_written_loop_bit_for_bit(solver_class):
    """Without compensation the state is updated in place, stage by stage: kick,
    then (drift, kick) pairs, the last force carried to the next step. On a grid
    of exact times (h = 1/32) that is a hand-written loop's arithmetic exactly."""
    solver = solver_class(compensated=False)
    kicks, drifts = solver.kick_coefficients, solver.drift_coefficients
    h, steps = 1 / 32, 200

    def hand_written(carry, _):
        q, p, force = carry
        p = p + kicks[0] * h * force
        for drift_coefficient, kick in zip(drifts, kicks[1:], strict=True):
            q = q + drift_coefficient * h * p
            force = kepler_force(q)
            p = p + kick * h * force
        return (q, p, force), None

    q0, p0 = KEPLER_Y0
    (q, p, _), _ = jax.jit(
        lambda q0, p0: jax.lax.scan(
            hand_written, (q0, p0, kepler_force(q0)), None, length=steps
        )
    )(q0, p0)
    sol = solve(
        separable_terms(kepler_force),
        solver,
        h * steps,
        h,
        (q0, p0),
        diffrax.SaveAt(t1=True),
        max_steps=steps,
    )
    np.testing.assert_array_equal(np.asarray(sol.ys[0][-1]), np.asarray(q))
    np.testing.assert_array_equal(np.asarray(sol.ys[1][-1]), np.asarray(p))
    assert not np.array_equal(np.asarray(q), np.asarray(q0))


# --- jit and vmap ------------------------------------------------------------------
# The vmap rule is the shared engine's; SofSpa10's 35-stage batch (9 s of compile)
# runs under -m slow, the five other tables by default.
VMAP_CASES = [*SOLVERS[:-1], pytest.param(SOLVERS[-1], marks=pytest.mark.slow)]


@pytest.mark.parametrize("solver", VMAP_CASES, ids=SOLVER_IDS)
def test_vmapped_batch_matches_python_loop(solver):
    keys = jax.random.split(jax.random.key(0), 2)
    q0s = 0.2 * jax.random.normal(keys[0], (64, 2))
    p0s = 0.2 * jax.random.normal(keys[1], (64, 2))

    @jax.jit
    def final_state(q0, p0):
        sol = solve(
            separable_terms(henon_heiles_force),
            solver,
            5.0,
            0.1,
            (q0, p0),
            diffrax.SaveAt(t1=True),
            max_steps=64,
        )
        return sol.ys[0][-1], sol.ys[1][-1]

    batched = jax.jit(jax.vmap(final_state))(q0s, p0s)
    looped = [final_state(q0, p0) for q0, p0 in zip(q0s, p0s, strict=True)]
    stacked = jax.tree_util.tree_map(lambda *leaves: jnp.stack(leaves), *looped)
    assert not tree_allclose(batched, (q0s, p0s), rtol=0, atol=1e-3)
    assert tree_allclose(batched, stacked, rtol=1e-13, atol=1e-13)
