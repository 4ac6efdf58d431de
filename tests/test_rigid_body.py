"""`RigidBody` and `RigidBodyTerm`: Euler's equations, torque by autodiff, invariants.

No integration here: the vector field itself must conserve what the physics
conserves (dH/dt = 0, dL/dt = space torque) and give the textbook torque.
"""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lagjax._core.terms import RigidBodyTerm
from lagjax.rigid import (
    RigidBody,
    axis_angle_quaternion,
    quaternion_to_matrix,
)

MOMENTS = jnp.array([1.0, 2.0, 3.0])
Q0 = axis_angle_quaternion(jnp.array([0.6, -0.48, 0.64]), 0.9)
MOMENTUM0 = jnp.array([0.3, -1.2, 0.7])
MGL = 2.5


def gravity(rotation, t, args):
    return args * rotation[2, 2]


def test_free_body_is_eulers_equations():
    body = RigidBody(MOMENTS)
    q_rate, momentum_rate = body.vector_field(Q0, MOMENTUM0)
    omega = MOMENTUM0 / MOMENTS
    i1, i2, i3 = MOMENTS
    # Course text eq. 4.41: I1 ω̇1 = (I2 − I3) ω2 ω3, and cyclically.
    euler = jnp.array(
        [
            (i2 - i3) * omega[1] * omega[2] / i1,
            (i3 - i1) * omega[2] * omega[0] / i2,
            (i1 - i2) * omega[0] * omega[1] / i3,
        ]
    )
    assert np.allclose(momentum_rate / MOMENTS, euler, atol=1e-15)
    # Ṙ = R ω̂ through the quaternion.
    rotation, rotation_rate = jax.jvp(quaternion_to_matrix, (Q0,), (q_rate,))
    assert np.allclose(rotation.T @ rotation_rate, jnp.cross(jnp.eye(3), omega).T * -1)


def _rates_of_invariants(body, args):
    """dH/dt and dL_space/dt along the vector field, by forward-mode autodiff."""
    field = body.vector_field(Q0, MOMENTUM0, 0.0, args)
    _, energy_rate = jax.jvp(lambda q, p: body(q, p, 0.0, args), (Q0, MOMENTUM0), field)
    _, momentum_rate = jax.jvp(body.angular_momentum_space, (Q0, MOMENTUM0), field)
    return energy_rate, momentum_rate


def test_invariants_of_the_vector_field():
    energy_rate, momentum_rate = _rates_of_invariants(RigidBody(MOMENTS), None)
    assert abs(energy_rate) < 1e-15 and np.allclose(momentum_rate, 0.0, atol=1e-15)
    top = RigidBody(MOMENTS, gravity)
    energy_rate, momentum_rate = _rates_of_invariants(top, MGL)
    assert abs(energy_rate) < 1e-14
    # With gravity only the vertical component of L is conserved.
    assert abs(momentum_rate[2]) < 1e-14 and np.linalg.norm(momentum_rate) > 0.1


def test_torque_from_the_potential_is_r_cross_f():
    top = RigidBody(MOMENTS, gravity)
    rotation = quaternion_to_matrix(Q0)
    # Centre of mass at e3 (arm 1), force −Mg ẑ: τ_body = e3 × (−MGL Rᵀẑ).
    expected = jnp.cross(jnp.array([0.0, 0.0, 1.0]), -MGL * rotation.T[:, 2])
    assert np.allclose(top.torque(Q0, 0.0, MGL), expected, atol=1e-15)
    assert np.allclose(RigidBody(MOMENTS).torque(Q0), 0.0)
    energy = top(Q0, MOMENTUM0, 0.0, MGL)
    kinetic = 0.5 * jnp.sum(MOMENTUM0**2 / MOMENTS)
    assert np.isclose(energy, kinetic + MGL * rotation[2, 2])


def test_term_is_an_ordinary_diffrax_term():
    body = RigidBody(MOMENTS)
    term = RigidBodyTerm(body)
    y0 = body.state_from_angular_velocity(2 * Q0, MOMENTUM0 / MOMENTS)
    assert np.isclose(jnp.linalg.norm(y0[0]), 1.0)
    assert np.allclose(y0[1], MOMENTUM0)
    vf = term.vf(0.0, y0, None)
    assert all(np.allclose(a, b) for a, b in zip(vf, body.vector_field(*y0)))
    increment = term.vf_prod(0.0, y0, None, term.contr(0.0, 0.1))
    assert np.allclose(increment[1], 0.1 * vf[1])
    # diffrax's own solvers integrate it like any ODE term.
    solution = diffrax.diffeqsolve(term, diffrax.Tsit5(), 0.0, 0.1, 0.01, y0)
    assert solution.ys is not None and np.all(np.isfinite(solution.ys[1]))


def test_vmap_over_bodies_and_states():
    bodies = jax.vmap(RigidBody)(jnp.stack([MOMENTS, 2 * MOMENTS]))
    energies = jax.vmap(lambda b: b.kinetic_energy(MOMENTUM0))(bodies)
    assert np.allclose(energies, jnp.array([1.0, 0.5]) * energies[0])


def test_bad_bodies_are_named():
    with pytest.raises(ValueError, match="three principal moments"):
        RigidBody(jnp.eye(3))
    with pytest.raises(ValueError, match="must all be positive"):
        RigidBody(jnp.array([1.0, 0.0, 2.0]))
    with pytest.raises(ValueError, match="must return a scalar"):
        RigidBody(MOMENTS, lambda rotation: rotation[2]).potential_energy(Q0)
