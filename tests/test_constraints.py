"""Holonomic constraints with Lagrange multipliers: the forces plain Lagrange can't give.

Each system is written in redundant Cartesian coordinates with a constraint and
checked against its generalized-coordinate formulation and the closed-form
constraint force (string tension, rope tension, the wire's normal force).
"""

import diffrax
import jax
import jax.numpy as jnp
import pytest

import lagjax as lj
from lagjax.mechanics.constraints import Constraints
from lagjax.scenes.constrained import (
    CartesianAtwoodMachine,
    CartesianPendulum,
    CartesianRotatingWireBead,
)
from lagjax.scenes.pendulums import SimplePendulum
from tests.helpers import relative_close

MASS, GRAVITY, LENGTH = 2.0, 9.81, 1.5


def cartesian_pendulum_lagrangian(q, qdot):
    return 0.5 * MASS * jnp.sum(qdot**2) - MASS * GRAVITY * q[1]


def string_length(q):
    return jnp.sqrt(q[0] ** 2 + q[1] ** 2) - LENGTH


PENDULUM = lj.Lagrangian(cartesian_pendulum_lagrangian, constraints=string_length)


def on_circle(theta, omega):
    """Cartesian (q, q̇) of the pendulum at angle θ from the downward vertical."""
    q = LENGTH * jnp.stack([jnp.sin(theta), -jnp.cos(theta)])
    qdot = LENGTH * omega * jnp.stack([jnp.cos(theta), jnp.sin(theta)])
    return q, qdot


def test_pendulum_acceleration_and_tension_at_a_state():
    theta, omega = 0.7, 1.3
    q, qdot = on_circle(theta, omega)
    tangential = -GRAVITY / LENGTH * jnp.sin(theta)  # θ̈ of the angle formulation
    radial = LENGTH * omega**2 * jnp.array([-jnp.sin(theta), jnp.cos(theta)])
    along = LENGTH * tangential * jnp.array([jnp.cos(theta), jnp.sin(theta)])
    assert relative_close(PENDULUM.acceleration(q, qdot), radial + along, 1e-14)
    tension = MASS * (GRAVITY * jnp.cos(theta) + LENGTH * omega**2)
    # G = r̂, so the force Gᵀλ = λ r̂ pulls inwards with |λ| = tension.
    assert relative_close(-PENDULUM.multipliers(q, qdot)[0], tension, 1e-14)
    force = PENDULUM.constraint_force(q, qdot)
    assert relative_close(force, -tension * q / LENGTH, 1e-14)


@pytest.mark.integration  # compile-heavy (12 s): CI runs it in its integration step
def test_an_implicit_diffrax_solver_is_projected_too():
    """Kvaerno5 on the Cartesian pendulum: diffrax treats the projected solver as
    implicit (it forwards `isinstance`) and sets its root finder's tolerances,
    which raised AttributeError before the projection exposed them."""
    q0, qdot0 = on_circle(0.7, 0.0)
    run = lj.simulate(PENDULUM, (q0, qdot0), t1=1.0, solver=diffrax.Kvaerno5(),
                      rtol=1e-8, atol=1e-8)  # fmt: skip
    assert run.stats["solver"] == "ConstraintProjection"
    q, qdot = run.q[-1], run.qdot[-1]
    assert abs(float(string_length(q))) < 1e-14  # projected after every step
    assert abs(float(jnp.dot(q, qdot))) < 1e-12
    energy0 = PENDULUM.energy(q0, qdot0)
    assert relative_close(PENDULUM.energy(q, qdot), energy0, 1e-6)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_cartesian_pendulum_matches_angle_formulation_with_tension():
    cartesian = CartesianPendulum(mass=MASS, length=LENGTH, gravity=GRAVITY)
    angle = SimplePendulum(
        mass=MASS, length=LENGTH, gravity=GRAVITY, amplitude=cartesian.amplitude
    )
    fixed = dict(solver=diffrax.Dopri8(), dt=0.005, t1=3.0)
    angle_run = lj.simulate(angle, angle.initial_state(), **fixed)
    run = lj.simulate(cartesian, cartesian.initial_state(), **fixed)
    assert run.stats["solver"] == "ConstraintProjection"
    theta, omega = angle_run.q[-1], angle_run.qdot[-1]
    q, qdot = run.q[-1], run.qdot[-1]
    expected_q, expected_qdot = on_circle(theta, omega)
    assert float(jnp.max(jnp.abs(q - expected_q))) < 1e-9
    assert float(jnp.max(jnp.abs(qdot - expected_qdot))) < 1e-9
    tension = -PENDULUM.multipliers(q, qdot)[0]
    expected = MASS * (GRAVITY * jnp.cos(theta) + LENGTH * omega**2)
    assert relative_close(tension, expected, 1e-9)
    for measured, closed_form in cartesian.checks(run).values():
        assert relative_close(measured, closed_form, 1e-9)
    # Projected after every step: the constraints hold to round-off.
    assert abs(float(string_length(q))) < 1e-14
    assert abs(float(jnp.dot(q, qdot))) < 1e-13
    energy0 = PENDULUM.energy(*cartesian.initial_state())
    assert relative_close(PENDULUM.energy(q, qdot), energy0, 1e-11)


def test_baumgarte_stabilization_obeys_its_damped_equation():
    """Off the constraint, g̈ + 2αġ + α²g = 0 along the stabilized acceleration."""
    rate = 7.0
    lag = lj.Lagrangian(
        cartesian_pendulum_lagrangian,
        constraints=Constraints(string_length, baumgarte_rate=rate),
    )
    q, qdot = jnp.array([0.9, -1.3]), jnp.array([0.4, 0.2])  # |q| ≠ l, q·q̇ ≠ 0
    qddot = lag.acceleration(q, qdot)

    def along_path(s):
        return string_length(q + s * qdot + 0.5 * s**2 * qddot)

    g, g_dot = jax.jvp(along_path, (0.0,), (1.0,))
    g_ddot = jax.jvp(lambda s: jax.jvp(along_path, (s,), (1.0,))[1], (0.0,), (1.0,))[1]
    assert abs(float(g)) > 1e-2 and abs(float(g_dot)) > 1e-2
    residual = g_ddot + 2 * rate * g_dot + rate**2 * g
    assert abs(float(residual)) < 1e-12 * rate**2


ATWOOD_MASSES, ROPE = (3.0, 1.0), 2.0


def atwood_lagrangian(q, qdot):
    # y1, y2: depths of the two masses below the pulley.
    m1, m2 = ATWOOD_MASSES
    kinetic = 0.5 * m1 * qdot[0] ** 2 + 0.5 * m2 * qdot[1] ** 2
    return kinetic + GRAVITY * (m1 * q[0] + m2 * q[1])


def test_atwood_machine_tension_and_acceleration():
    lag = lj.Lagrangian(atwood_lagrangian, constraints=lambda q: q[0] + q[1] - ROPE)
    m1, m2 = ATWOOD_MASSES
    y0 = (jnp.array([0.8, ROPE - 0.8]), jnp.array([0.3, -0.3]))
    acceleration = (m1 - m2) * GRAVITY / (m1 + m2)  # the course text, §3.4
    tension = 2 * m1 * m2 * GRAVITY / (m1 + m2)
    assert relative_close(lag.acceleration(*y0), [acceleration, -acceleration], 1e-14)
    # The rope pulls both masses up (towards smaller depth): force (−T, −T).
    assert relative_close(lag.constraint_force(*y0), [-tension, -tension], 1e-14)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_atwood_scene_follows_the_parabola():
    scene = CartesianAtwoodMachine(initial_velocity=0.4)
    run = lj.simulate(scene, scene.initial_state(), t1=0.5, dt=0.01)  # default solver
    for measured, closed_form in scene.checks(run).values():
        assert relative_close(measured, closed_form, 1e-13)
    assert relative_close(jnp.sum(run.q[-1]), scene.rope_length, 1e-15)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_bead_on_rotating_wire_in_cartesian_coordinates():
    scene = CartesianRotatingWireBead()
    fixed = dict(solver=diffrax.Dopri8(), dt=0.005, t1=scene.default_t1)
    run = lj.simulate(scene, scene.initial_state(), **fixed)
    generalized = lj.simulate(
        scene.generalized(), scene.generalized().initial_state(), **fixed
    )
    checks = scene.checks(run)  # radius, and the wire's push 2mωṙ (Coriolis)
    for measured, closed_form in checks.values():
        assert relative_close(measured, closed_form, 1e-9)
    assert relative_close(checks["radius"][0], generalized.q, 1e-10)
    omega, t1 = scene.angular_velocity, scene.default_t1
    q = run.q[-1]
    assert abs(float(q[0] * jnp.sin(omega * t1) - q[1] * jnp.cos(omega * t1))) < 1e-15


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_vmap_over_scene_parameters_and_states():
    lengths = jnp.array([0.5, 1.0, 2.0])
    scenes = jax.vmap(lambda length: CartesianPendulum(length=length))(lengths)

    def final_state(scene):
        return lj.simulate(scene, scene.initial_state(), t1=0.5, dt=0.01)

    runs = jax.jit(jax.vmap(final_state))(scenes)
    radii = jnp.sqrt(jnp.sum(runs.q[:, -1] ** 2, axis=-1))
    assert relative_close(radii, lengths, 1e-15)
    thetas = jnp.linspace(-1.0, 1.0, 5)
    q, qdot = jax.vmap(lambda th: on_circle(th, 0.5))(thetas)
    tension = -jax.jit(jax.vmap(PENDULUM.multipliers))(q, qdot)[:, 0]
    expected = MASS * (GRAVITY * jnp.cos(thetas) + LENGTH * 0.25)
    assert relative_close(tension, expected, 1e-13)
