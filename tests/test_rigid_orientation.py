"""Orientation: the course text's z-x-z Euler angles, quaternions, angular velocity."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lagjax.rigid import (
    axis_angle_quaternion,
    body_angular_velocity,
    euler_zxz_body_angular_velocity,
    euler_zxz_matrix,
    euler_zxz_space_angular_velocity,
    euler_zxz_to_quaternion,
    euler_zxz_to_rotation,
    matrix_to_quaternion,
    quaternion_conjugate,
    quaternion_multiply,
    quaternion_rate,
    quaternion_to_matrix,
    rotate,
    rotation_to_euler_zxz,
    rotation_vector_quaternion,
    skew,
    space_angular_velocity,
)

ANGLES = jax.random.uniform(
    jax.random.key(3),
    (16, 3),
    minval=jnp.array([-3.0, 0.05, -3.0]),
    maxval=jnp.array([3.0, 3.09, 3.0]),
)
RATES = jax.random.normal(jax.random.key(4), (16, 3))


def _turn_about_z(angle):  # the course text's passive turn, eq. 4.12 / 4.16
    c, s = jnp.cos(angle), jnp.sin(angle)
    return jnp.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])


def _turn_about_x(angle):  # eq. 4.14
    c, s = jnp.cos(angle), jnp.sin(angle)
    return jnp.array([[1.0, 0.0, 0.0], [0.0, c, s], [0.0, -s, c]])


def test_euler_matrix_is_the_product_of_three_turns_and_orthogonal():
    for phi, theta, psi in ANGLES[:4]:
        product = _turn_about_z(psi) @ _turn_about_x(theta) @ _turn_about_z(phi)
        a = euler_zxz_matrix(jnp.array([phi, theta, psi]))
        assert np.allclose(a, product, atol=1e-15)
    a = jax.vmap(euler_zxz_matrix)(ANGLES)
    assert np.allclose(jnp.swapaxes(a, 1, 2) @ a, np.eye(3), atol=1e-15)
    assert np.allclose(jnp.linalg.det(a), 1.0)
    # Eq. 4.20's last row: (sin θ sin φ, −sin θ cos φ, cos θ).
    phi, theta = ANGLES[0, 0], ANGLES[0, 1]
    last_row = [
        jnp.sin(theta) * jnp.sin(phi),
        -jnp.sin(theta) * jnp.cos(phi),
        jnp.cos(theta),
    ]
    assert np.allclose(a[0, 2], last_row)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_quaternion_and_matrix_forms_agree():
    q = jax.vmap(euler_zxz_to_quaternion)(ANGLES)
    assert np.allclose(jnp.linalg.norm(q, axis=-1), 1.0)
    assert np.allclose(quaternion_to_matrix(q), jax.vmap(euler_zxz_to_rotation)(ANGLES))
    # Hamilton product composes rotations.
    assert np.allclose(
        quaternion_to_matrix(quaternion_multiply(q[:8], q[8:])),
        quaternion_to_matrix(q[:8]) @ quaternion_to_matrix(q[8:]),
        atol=1e-14,
    )
    identity = quaternion_multiply(q, quaternion_conjugate(q))
    assert np.allclose(identity, jnp.array([1.0, 0.0, 0.0, 0.0]), atol=1e-15)
    v = jnp.array([0.3, -1.0, 2.0])
    assert np.allclose(rotate(q[0], v), quaternion_to_matrix(q[0]) @ v)
    # A non-unit quaternion still maps to the same exact rotation.
    assert np.allclose(quaternion_to_matrix(3.0 * q), quaternion_to_matrix(q))


@pytest.mark.parametrize(
    "axis, angle",
    [
        ((0, 0, 1), 0.0),
        ((1, 0, 0), np.pi),
        ((0, 1, 0), np.pi),
        ((0, 0, 1), np.pi),
        ((1, 1, 1), 2.5),
    ],
)
def test_matrix_to_quaternion_covers_every_branch(axis, angle):
    axis = jnp.asarray(axis, dtype=float) / np.linalg.norm(axis)
    q = axis_angle_quaternion(axis, angle)
    back = matrix_to_quaternion(quaternion_to_matrix(q))
    assert back[0] >= 0
    assert np.allclose(back, q, atol=1e-15) or np.allclose(back, -q, atol=1e-15)


def test_euler_angles_round_trip_and_gimbal_lock():
    rotations = jax.vmap(euler_zxz_to_rotation)(ANGLES)
    assert np.allclose(jax.vmap(rotation_to_euler_zxz)(rotations), ANGLES, atol=1e-12)
    assert np.allclose(
        jax.vmap(matrix_to_quaternion)(rotations),
        jax.vmap(euler_zxz_to_quaternion)(ANGLES)
        * jnp.sign(jax.vmap(euler_zxz_to_quaternion)(ANGLES)[:, :1]),
        atol=1e-14,
    )
    for theta in (0.0, np.pi):  # only φ ± ψ is defined; the rotation must survive
        locked = jnp.array([0.4, theta, 0.9])
        recovered = rotation_to_euler_zxz(euler_zxz_to_rotation(locked))
        assert np.isclose(recovered[1], theta) and recovered[2] == 0.0
        assert np.allclose(
            euler_zxz_to_rotation(recovered), euler_zxz_to_rotation(locked), atol=1e-15
        )


def test_exponential_map_is_smooth_at_identity():
    assert np.allclose(rotation_vector_quaternion(jnp.zeros(3)), [1.0, 0, 0, 0])
    jac = jax.jacfwd(rotation_vector_quaternion)(jnp.zeros(3))
    assert np.allclose(jac, np.vstack([np.zeros(3), 0.5 * np.eye(3)]))
    v = jnp.array([0.2, -0.4, 1.1])
    angle = jnp.linalg.norm(v)
    assert np.allclose(
        rotation_vector_quaternion(v), axis_angle_quaternion(v / angle, angle)
    )


def _along_curve(angles, rates):
    """Rotation and quaternion along angles + t·rates, and their t-derivatives at 0."""

    def at(t):
        return euler_zxz_to_rotation(angles + t * rates), euler_zxz_to_quaternion(
            angles + t * rates
        )

    return jax.jvp(at, (0.0,), (1.0,))


def test_angular_velocity_from_euler_rates_and_quaternions():
    for angles, rates in zip(ANGLES[:6], RATES[:6]):
        (rotation, q), (rotation_dot, q_dot) = _along_curve(angles, rates)
        omega_body = euler_zxz_body_angular_velocity(angles, rates)
        omega_space = euler_zxz_space_angular_velocity(angles, rates)
        # Ṙ = R ω̂_body = ω̂_space R.
        assert np.allclose(rotation.T @ rotation_dot, skew(omega_body), atol=1e-14)
        assert np.allclose(rotation_dot @ rotation.T, skew(omega_space), atol=1e-14)
        assert np.allclose(omega_space, rotation @ omega_body, atol=1e-14)
        assert np.allclose(body_angular_velocity(q, q_dot), omega_body, atol=1e-14)
        assert np.allclose(space_angular_velocity(q, q_dot), omega_space, atol=1e-14)
        assert np.allclose(quaternion_rate(q, omega_body), q_dot, atol=1e-14)


def test_euler_rates_lose_rank_at_gimbal_lock():
    def rates_to_omega(angles):
        return jax.jacfwd(euler_zxz_body_angular_velocity, argnums=1)(
            angles, jnp.zeros(3)
        )

    # det ∂ω/∂(φ̇, θ̇, ψ̇) = −sin θ: one direction of rates is invisible at θ = 0.
    for theta in (0.0, 1e-9, 0.7):
        det = jnp.linalg.det(rates_to_omega(jnp.array([0.3, theta, -0.2])))
        assert np.isclose(det, -np.sin(theta), atol=1e-15)


def test_bad_shapes_are_named():
    with pytest.raises(ValueError, match="Euler angles"):
        euler_zxz_matrix(jnp.zeros(4))
    with pytest.raises(ValueError, match="quaternion"):
        quaternion_to_matrix(jnp.zeros(3))
