"""Physics tests of the Gauss–Legendre (implicit symplectic Runge–Kutta) solvers.

The main subject is the double pendulum (unit masses, rods and gravity): its mass
matrix depends on q, so H(q, p) is not separable and only implicit symplectic
methods apply. Oracles: an independent Dopri8 reference (order), MᵀJM = J and finite
differences (one-step Jacobian), the exact inverse map (symmetry), bounded energy
error without drift (backward error analysis), exact conservation of a quadratic
invariant (angular momentum), and stage equations without a solution (failure).
"""

import functools

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest

from lagjax.mechanics.canonical import symplectic_defect
from lagjax.solvers.implicit import (
    AbstractGaussLegendre,
    GaussLegendre,
    ImplicitMidpoint,
)
from tests.helpers import tree_allclose

MAX_STEPS = 21_000
CHAOTIC_START = (jnp.array([2.0, 2.0]), jnp.array([0.0, 0.0]))
GENERIC_POINT = (jnp.array([1.2, -0.7]), jnp.array([0.8, -0.4]))


def double_pendulum_energy(q, p):
    """H(θ₁, θ₂, p₁, p₂) with angles from the downward vertical."""
    delta = q[0] - q[1]
    kinetic = (p[0] ** 2 + 2 * p[1] ** 2 - 2 * p[0] * p[1] * jnp.cos(delta)) / (
        2 * (1 + jnp.sin(delta) ** 2)
    )
    return kinetic - 2 * jnp.cos(q[0]) - jnp.cos(q[1])


def double_pendulum(t, y, args):
    q, p = y
    return (
        jax.grad(double_pendulum_energy, 1)(q, p),
        -jax.grad(double_pendulum_energy, 0)(q, p),
    )


SAVE_FINAL = diffrax.SaveAt(t1=True)


@eqx.filter_jit
def integrate(solver, y0, t0, t1, dt0, saveat=SAVE_FINAL):
    """Fixed-step run; times are arrays so one compilation serves every dt."""
    return diffrax.diffeqsolve(
        diffrax.ODETerm(double_pendulum),
        solver,
        t0,
        t1,
        dt0,
        y0,
        stepsize_controller=diffrax.ConstantStepSize(),
        saveat=saveat,
        max_steps=MAX_STEPS,
    )


def final_state(y0, t1, dt, solver, t0=0.0):
    # Strongly typed times: a Python float (weak) and a NumPy float (strong) would
    # otherwise be two cache entries, two compilations of the same run.
    times = tuple(jnp.asarray(t, dtype=float) for t in (t0, t1, dt))
    return jax.tree_util.tree_map(lambda x: x[-1], integrate(solver, y0, *times).ys)


def max_difference(x, y):
    leaves = jax.tree_util.tree_leaves(jax.tree_util.tree_map(lambda a, b: a - b, x, y))
    return max(float(jnp.max(jnp.abs(leaf))) for leaf in leaves)


# -- order --------------------------------------------------------------------------

ORDER_TIME = 2.0
ORDER_START = (jnp.array([1.0, -0.5]), jnp.array([0.3, 0.2]))


@pytest.fixture(scope="module")
def dopri8_reference():
    solution = diffrax.diffeqsolve(
        diffrax.ODETerm(double_pendulum),
        diffrax.Dopri8(),
        0.0,
        ORDER_TIME,
        0.01,
        ORDER_START,
        stepsize_controller=diffrax.PIDController(rtol=1e-13, atol=1e-13),
    )
    return jax.tree_util.tree_map(lambda x: x[-1], solution.ys)


# Step counts in the asymptotic range, with errors well above the reference's 1e-15.
@pytest.mark.parametrize(
    "stages, step_counts", [(1, (16, 32, 64)), (2, (16, 32, 64)), (3, (32, 64, 128))]
)
def test_convergence_order_on_double_pendulum(stages, step_counts, dopri8_reference):
    solver = GaussLegendre(stages=stages)
    step_sizes = ORDER_TIME / np.array(step_counts)
    errors = [
        max_difference(
            final_state(ORDER_START, ORDER_TIME, dt, solver), dopri8_reference
        )
        for dt in step_sizes
    ]
    slope = np.polyfit(np.log(step_sizes), np.log(errors), 1)[0]
    assert solver.order(None) == 2 * stages
    assert abs(slope - 2 * stages) < 0.2, (errors, slope)


def test_implicit_midpoint_is_the_one_stage_method():
    midpoint = final_state(GENERIC_POINT, 1.0, 0.05, ImplicitMidpoint())
    gauss = final_state(GENERIC_POINT, 1.0, 0.05, GaussLegendre(stages=1))
    assert isinstance(ImplicitMidpoint(), AbstractGaussLegendre)
    assert tree_allclose(midpoint, gauss, rtol=0, atol=0)


@pytest.mark.parametrize("stages", [0, 4])
def test_unsupported_stage_count_is_rejected(stages):
    with pytest.raises(ValueError, match="stages must be 1, 2 or 3"):
        GaussLegendre(stages=stages)


# -- geometry: symplecticity, Jacobian, symmetry, quadratic invariants --------------


def one_step_map(solver, dt):
    """(q, p) ↦ (q₁, p₁): one `solver.step` of size dt on the double pendulum."""
    term = diffrax.ODETerm(double_pendulum)

    def step(q, p):
        state = solver.init(term, 0.0, dt, (q, p), None)
        y1, *_ = solver.step(term, 0.0, dt, (q, p), None, state, False)
        return y1

    return step


def finite_difference_jacobian(function, z, eps=1e-6):
    """Central differences: truncation ~eps², round-off ~1e-16/eps ≈ 1e-10. The 2n
    shifted points go through `function` in one `lax.map` (one trace)."""
    shifts = eps * jnp.eye(z.size)
    values = jax.lax.map(function, jnp.concatenate([z + shifts, z - shifts]))
    forward, backward = jnp.split(values, 2)
    return ((forward - backward) / (2 * eps)).T


NEWTON = optx.Newton(rtol=1e-14, atol=1e-14)
SYMPLECTIC_SOLVERS = [GaussLegendre(stages=s) for s in (1, 2, 3)]
# Newton's implicitly differentiated stage solve compiles the slowest: the slow run.
SYMPLECTIC_SOLVERS += [
    pytest.param(GaussLegendre(stages=3, root_finder=NEWTON), marks=pytest.mark.slow)
]


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
@pytest.mark.parametrize(
    "solver", SYMPLECTIC_SOLVERS, ids=["s1", "s2", "s3", "s3-newton"]
)
def test_one_step_is_symplectic_for_non_separable_hamiltonian(solver):
    """MᵀJM = J for the implicitly differentiated Jacobian M, and M is the true
    Jacobian (a zero tangent through the stage solve would give the symplectic but
    wrong M = I)."""
    step = one_step_map(solver, dt=0.1)
    flat_step = lambda z: jnp.concatenate(step(z[:2], z[2:]))

    @jax.jit
    def defect_and_jacobians(z):  # one compilation for the three
        return (
            symplectic_defect(step, z[:2], z[2:]),
            jax.jacfwd(flat_step)(z),
            finite_difference_jacobian(flat_step, z),
        )

    defect, jacobian, expected = defect_and_jacobians(jnp.concatenate(GENERIC_POINT))
    assert defect <= 1e-12
    assert max_difference(jacobian, expected) < 1e-8


def test_symplecticity_check_rejects_a_non_symplectic_method():
    step = one_step_map(diffrax.Euler(), dt=0.1)
    defect = jax.jit(lambda q, p: symplectic_defect(step, q, p))(*GENERIC_POINT)
    assert defect > 1e-4


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_forward_mode_jacobian_through_diffeqsolve_matches_finite_differences():
    """The user's path: jacfwd of a whole solve (diffrax's ForwardMode adjoint), with
    optimistix differentiating the stage equations implicitly at every step."""
    flat_point = jnp.concatenate(GENERIC_POINT)

    def flat_step(z):
        solution = diffrax.diffeqsolve(
            diffrax.ODETerm(double_pendulum),
            GaussLegendre(stages=3),
            0.0,
            0.3,
            0.1,
            (z[:2], z[2:]),
            adjoint=diffrax.ForwardMode(),
        )
        return jnp.concatenate([leaf[-1] for leaf in solution.ys])

    # One compilation for the forward-mode and the finite-difference Jacobian.
    jacobian, expected = jax.jit(
        lambda z: (jax.jacfwd(flat_step)(z), finite_difference_jacobian(flat_step, z))
    )(flat_point)
    assert max_difference(jacobian, expected) < 1e-8


@pytest.mark.parametrize("stages", [1, 2, 3])
def test_step_backwards_returns_to_start(stages):
    solver, dt, steps = GaussLegendre(stages=stages), 0.05, 10
    forward = final_state(CHAOTIC_START, steps * dt, dt, solver)
    back = final_state(forward, 0.0, -dt, solver, t0=steps * dt)
    assert max_difference(forward, CHAOTIC_START) > 0.1
    assert max_difference(back, CHAOTIC_START) <= 1e-13


def kepler(t, y, args):
    position, momentum = y
    return momentum, -position / jnp.sum(position**2) ** 1.5


def test_implicit_midpoint_conserves_angular_momentum_exactly():
    """L = x p_y − y p_x is quadratic, so every Gauss method conserves it exactly."""
    solution = diffrax.diffeqsolve(
        diffrax.ODETerm(kepler),
        ImplicitMidpoint(),
        0.0,
        50.0,
        0.05,
        (jnp.array([1.0, 0.0]), jnp.array([0.0, 1.2])),
        saveat=diffrax.SaveAt(steps=True),
        max_steps=1100,
    )
    steps = int(solution.stats["num_steps"])
    (x, y), (px, py) = (leaf[:steps].T for leaf in solution.ys)
    angular_momentum = x * py - y * px
    assert jnp.max(jnp.abs(angular_momentum - 1.2)) < 1e-13


# -- long-time energy ---------------------------------------------------------------


def relative_energy_errors(solver, dt, steps):
    solution = integrate(
        solver,
        CHAOTIC_START,
        jnp.asarray(0.0),
        jnp.asarray(steps * dt),
        jnp.asarray(dt),
        saveat=diffrax.SaveAt(steps=True),
    )
    return np.asarray(solution.ts[:steps]), np.asarray(
        _relative_energy_change(solution.ys, steps)
    )


@functools.partial(jax.jit, static_argnums=1)
def _relative_energy_change(states, steps):
    """|H(y_k) − H(y_0)|/|H(y_0)| over the first `steps` saved states, compiled once
    for both energy tests."""
    q, p = (leaf[:steps] for leaf in states)
    energy = jax.vmap(double_pendulum_energy)(q, p)
    initial = double_pendulum_energy(*CHAOTIC_START)
    return jnp.abs((energy - initial) / initial)


def linear_drift(times, errors):
    """Energy change over the run explained by a straight-line fit."""
    return abs(np.polyfit(times, errors, 1)[0]) * (times[-1] - times[0])


def test_energy_error_is_bounded_without_drift_on_chaotic_double_pendulum():
    times, errors = relative_energy_errors(GaussLegendre(stages=3), 0.005, 20_000)
    first_half, second_half = np.split(errors, 2)
    assert errors.max() <= 1e-10
    assert second_half.max() <= 2 * first_half.max()
    assert linear_drift(times, errors) <= 0.1 * errors.max()


def test_loose_stage_tolerance_shows_energy_drift():
    """Hairer, McLachlan & Razakarivony: stopping early leaves a non-symplectic,
    systematic error — the drift the test above rules out."""
    loose = optx.FixedPointIteration(rtol=1e-8, atol=1e-8)
    solver = GaussLegendre(stages=3, root_finder=loose)
    times, errors = relative_energy_errors(solver, 0.005, 20_000)
    assert linear_drift(times, errors) > 0.5 * errors.max()


# -- failure reporting --------------------------------------------------------------


def stiff_relaxation(t, y, args):
    return -1e4 * (y - jnp.cos(t))


def blow_up(t, y, args):
    return y**2


def test_divergent_fixed_point_iteration_is_reported():
    """h·λ = 10³: fixed-point iteration diverges; the step must say so."""
    solution = diffrax.diffeqsolve(
        diffrax.ODETerm(stiff_relaxation),
        GaussLegendre(stages=3),
        0.0,
        1.0,
        0.1,
        jnp.array(1.0),
        throw=False,
    )
    assert solution.result == diffrax.RESULTS.nonlinear_max_steps_reached


def test_stage_equations_without_solution_are_reported():
    """y' = y² from 1 blows up at t = 1. With h = 2 the midpoint stage equation
    Z = h (1 + Z/2)² has discriminant 1 − 2h < 0: no real root for Newton to find."""
    solver = ImplicitMidpoint(root_finder=NEWTON)
    args = (diffrax.ODETerm(blow_up), solver, 0.0, 4.0, 2.0, jnp.array(1.0))
    solution = diffrax.diffeqsolve(*args, throw=False)
    assert solution.result == diffrax.RESULTS.nonlinear_max_steps_reached
    with pytest.raises(eqx.EquinoxRuntimeError, match="nonlinear solver"):
        diffrax.diffeqsolve(*args)


# -- batching -----------------------------------------------------------------------


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_vmapped_batch_equals_loop():
    keys = jax.random.split(jax.random.key(0), 2)
    q0s = jax.random.uniform(keys[0], (16, 2), minval=-2.0, maxval=2.0)
    p0s = jax.random.uniform(keys[1], (16, 2), minval=-1.0, maxval=1.0)
    solver = GaussLegendre(stages=3)
    batched = jax.vmap(lambda q, p: final_state((q, p), 1.0, 0.05, solver))(q0s, p0s)
    looped = [final_state((q, p), 1.0, 0.05, solver) for q, p in zip(q0s, p0s)]
    stacked = jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *looped)
    assert tree_allclose(batched, stacked, rtol=1e-12, atol=1e-12)
