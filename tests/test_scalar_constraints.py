"""Constrained accelerations in the scalar formulation (few coordinates) and its
dense fallback: physics answers, extra decoupled coordinates, hard matrices."""

import diffrax
import jax
import jax.numpy as jnp
import pytest

import lagjax as lj
from lagjax.cli.demo import G, handwritten_acceleration
from tests.helpers import relative_close


def cartesian_double_pendulum(q, qdot):
    return 0.5 * jnp.sum(qdot[:4] ** 2) - G * (q[1] + q[3])


def rods(q):
    return jnp.stack(
        [q[0] ** 2 + q[1] ** 2 - 1.0, (q[2] - q[0]) ** 2 + (q[3] - q[1]) ** 2 - 1.0]
    )


def with_free_oscillators(q, qdot):
    # Three decoupled unit oscillators after the pendulum: 7 coordinates, past the
    # scalar formulation's limit, so the dense saddle-point solve answers.
    return cartesian_double_pendulum(q, qdot) + 0.5 * jnp.sum(
        qdot[4:] ** 2 - q[4:] ** 2
    )


def cartesian_state(theta, omega):
    """Cartesian (q, q̇) of the unit double pendulum at absolute angles θ."""
    s, c = jnp.sin(theta), jnp.cos(theta)
    q = jnp.stack([s[0], -c[0], s[0] + s[1], -c[0] - c[1]])
    qdot = jnp.stack(
        [
            c[0] * omega[0],
            s[0] * omega[0],
            c[0] * omega[0] + c[1] * omega[1],
            s[0] * omega[0] + s[1] * omega[1],
        ]
    )
    return q, qdot


def cartesian_acceleration(theta, omega, alpha):
    """Second derivatives of the Cartesian positions for angles θ(t)."""
    s, c = jnp.sin(theta), jnp.cos(theta)
    ax = c * alpha - s * omega**2
    ay = s * alpha + c * omega**2
    return jnp.stack([ax[0], ay[0], ax[0] + ax[1], ay[0] + ay[1]])


THETA, OMEGA = jnp.array([0.9, -0.4]), jnp.array([1.1, -2.3])


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_cartesian_double_pendulum_matches_the_angle_equations():
    lag = lj.Lagrangian(cartesian_double_pendulum, constraints=rods)
    q, qdot = cartesian_state(THETA, OMEGA)
    expected = cartesian_acceleration(
        THETA, OMEGA, handwritten_acceleration(THETA, OMEGA)
    )
    assert relative_close(lag.acceleration(q, qdot), expected, 1e-13)
    assert relative_close(jax.jit(lag.acceleration)(q, qdot), expected, 1e-13)


def test_decoupled_coordinates_change_nothing_on_either_formulation():
    lag = lj.Lagrangian(with_free_oscillators, constraints=rods)
    q4, qdot4 = cartesian_state(THETA, OMEGA)
    extra = jnp.array([0.3, -0.2, 0.5])
    q, qdot = jnp.concatenate([q4, extra]), jnp.concatenate([qdot4, jnp.zeros(3)])
    expected = cartesian_acceleration(
        THETA, OMEGA, handwritten_acceleration(THETA, OMEGA)
    )
    qddot = lag.acceleration(q, qdot)
    assert relative_close(qddot[:4], expected, 1e-13)
    assert relative_close(qddot[4:], -extra, 1e-14)
    four = lj.Lagrangian(cartesian_double_pendulum, constraints=rods)
    assert relative_close(lag.multipliers(q, qdot), four.multipliers(q4, qdot4), 1e-13)


def test_indefinite_mass_matrix_with_a_regular_saddle_is_still_solved():
    # M = diag(1, −1) has no LDLᵀ with positive pivots, but the constraint y = 0
    # leaves only x free, where M is positive: the motion is ẍ = −x.
    def lagrangian(q, qdot):
        return 0.5 * (qdot[0] ** 2 - qdot[1] ** 2) - 0.5 * q[0] ** 2

    lag = lj.Lagrangian(lagrangian, constraints=lambda q: q[1])
    q, qdot = jnp.array([0.7, 0.0]), jnp.array([0.2, 0.0])
    expected = jnp.array([-0.7, 0.0])
    assert relative_close(lag.acceleration(q, qdot), expected, 1e-14)
    assert relative_close(jax.jit(lag.acceleration)(q, qdot), expected, 1e-14)


def squared_length(q):
    return 0.5 * (q[0] ** 2 + q[1] ** 2 - 1.0)


def falling(q, qdot):
    return 0.5 * jnp.sum(qdot**2) - 9.81 * q[1]


def test_a_batch_with_one_degenerate_member_poisons_only_that_member():
    lag = lj.Lagrangian(falling, constraints=squared_length)
    q = jnp.array([[1.0, 0.0], [0.0, 0.0], [0.0, -1.0]])
    qdot = jnp.array([[0.0, 0.5], [0.0, 0.0], [2.0, 0.0]])
    qddot = jax.jit(jax.vmap(lag.acceleration))(q, qdot)
    assert relative_close(qddot[0], jnp.array([-0.25, -9.81]), 1e-13)
    assert bool(jnp.all(jnp.isnan(qddot[1])))
    # At the bottom, moving at 2: centripetal 4 upwards, gravity balanced by the rod.
    assert relative_close(qddot[2], jnp.array([0.0, 4.0]), 1e-13)


def test_singular_mass_matrix_is_named_with_constraints():
    def lagrangian(q, qdot):  # no kinetic term for y
        return 0.5 * qdot[0] ** 2 - q[1] ** 2

    lag = lj.Lagrangian(lagrangian, constraints=lambda q: q[0] - q[1])
    q, qdot = jnp.array([0.5, 0.5]), jnp.zeros(2)
    with pytest.raises(Exception, match="mass matrix"):
        jax.block_until_ready(lag.acceleration(q, qdot))
    assert bool(jnp.all(jnp.isnan(jax.jit(lag.acceleration)(q, qdot))))


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_derivatives_of_the_constrained_acceleration_are_finite_differences():
    lag = lj.Lagrangian(cartesian_double_pendulum, constraints=rods)

    def accel_of_angle(theta0):
        q, qdot = cartesian_state(jnp.stack([theta0, THETA[1]]), OMEGA)
        return lag.acceleration(q, qdot)

    derivative = jax.jacfwd(accel_of_angle)(THETA[0])
    gradient = jax.grad(lambda a: jnp.sum(accel_of_angle(a)))(THETA[0])
    h = 1e-6
    central = (accel_of_angle(THETA[0] + h) - accel_of_angle(THETA[0] - h)) / (2 * h)
    assert relative_close(derivative, central, 1e-7)
    assert relative_close(gradient, jnp.sum(central), 1e-7)


def unequal_masses(q, qdot):
    return 0.5 * (qdot[0] ** 2 + 3.0 * qdot[1] ** 2)


@pytest.mark.parametrize(
    "constraints, qdot, expected",
    [
        # x + y = 1 (holonomic): δ = M⁻¹Aᵀλ with λ(1/1 + 1/3) = −1.
        (lambda q: q[0] + q[1] - 1.0, [1.0, 0.0], [0.25, -0.25]),
        # ẋ − 2ẏ = 0 (velocity only): λ(1/1 + 4/3) = 1.
        (
            lj.Constraints(velocity=lambda q, qd: qd[0] - 2.0 * qd[1]),
            [1.0, 1.0],
            [10 / 7, 5 / 7],
        ),
    ],
)
def test_velocity_projection_is_the_least_change_in_the_kinetic_metric(
    constraints, qdot, expected
):
    from lagjax.solvers.projection import project_onto_constraints

    lag = lj.Lagrangian(unequal_masses, constraints=constraints)
    q = jnp.array([0.4, 0.6])
    (_, projected), _ = jax.jit(
        lambda v: project_onto_constraints(lag, q, v, 0.0, None)
    )(jnp.array(qdot))
    assert relative_close(projected, jnp.array(expected), 1e-14)


def test_position_projection_far_off_the_circle_converges_by_the_fallback():
    # 10 % off the unit circle: two simplified Newton iterations leave a defect of
    # ~1e-4, so optimistix's Newton finishes; the closest point in the metric
    # M = I along Gᵀ = q is q/|q|.
    from lagjax.solvers.projection import project_onto_constraints

    lag = lj.Lagrangian(falling, constraints=squared_length)
    q = 1.1 * jnp.array([0.6, -0.8])
    project = jax.jit(
        lambda q: project_onto_constraints(lag, q, jnp.zeros(2), 0.0, None)
    )
    (moved, _), result = project(q)
    assert result == diffrax.RESULTS.successful
    assert relative_close(moved, jnp.array([0.6, -0.8]), 1e-14)


def test_simulate_with_an_indefinite_mass_matrix_takes_every_fallback():
    # M = diag(1, −1) (no LDLᵀ with positive pivots), y = 0: ẍ = −x, x = cos t.
    def lagrangian(q, qdot):
        return 0.5 * (qdot[0] ** 2 - qdot[1] ** 2) - 0.5 * q[0] ** 2

    lag = lj.Lagrangian(lagrangian, constraints=lambda q: q[1])
    run = lj.simulate(
        lag, (jnp.array([1.0, 0.0]), jnp.zeros(2)), t1=2.0, dt=0.01,
        solver=diffrax.Tsit5(),
    )  # fmt: skip
    assert relative_close(run.q[-1], jnp.array([jnp.cos(2.0), 0.0]), 1e-9)
