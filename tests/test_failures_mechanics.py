"""Catalogue of bad physics input: user functions, Legendre transforms, rigid bodies,
canonical maps, scene parameters, implicit stage solves.

Each case asserts the error and a message naming the problem and the fix, or the
correct result against a closed form (the relativistic Legendre transform).
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest

import lagjax as lj
from lagjax.rigid.inertia import check_moments, point_mass_inertia
from lagjax.rigid.quaternion import check_nonzero_quaternion
from lagjax.scenes.central import KeplerCartesian
from lagjax.scenes.oscillators import HarmonicOscillator
from lagjax.scenes.pendulums import DoublePendulum, SimplePendulum
from lagjax.solvers.implicit import stage_failure_message


def branchy(q, qd):
    if q > 0:  # Python control flow on a traced value
        return 0.5 * qd**2
    return 0.5 * qd**2 - q


def numpy_inside(q, qd):
    return 0.5 * qd**2 + np.cos(q)


def python_float(q, qd):
    return 0.5 * qd**2 + math.cos(q)


def no_return(q, qd):
    0.5 * qd**2


def returns_text(q, qd):
    return "energy"


USER_FUNCTION_CASES = [
    (branchy, TypeError, r"branchy .*Python `if`.*jnp.where.*lax.cond"),
    (numpy_inside, TypeError, r"numpy_inside .*NumPy.*jax.numpy"),
    (python_float, TypeError, r"python_float .*concrete value"),
    (no_return, ValueError, r"returned None.*`return` missing"),
    (returns_text, ValueError, "must return a real scalar, but returned a str"),
    (lambda q, qd: qd * jnp.ones(3), ValueError, r"array of shape \(3,\)"),
    (lambda q, qd: jnp.int32(1), ValueError, "must return a real float"),
]


@pytest.mark.parametrize("function, error, message", USER_FUNCTION_CASES)
def test_lagrangian_mistakes_are_named(function, error, message):
    lag = lj.Lagrangian(function)
    with pytest.raises(error, match=message):
        lag.acceleration(jnp.asarray(0.3), jnp.asarray(0.1))


@pytest.mark.parametrize("function, error, message", USER_FUNCTION_CASES[:5])
def test_hamiltonian_mistakes_are_named(function, error, message):
    ham = lj.Hamiltonian(function)
    with pytest.raises(error, match=message):  # traced as simulate traces it
        jax.jit(ham.vector_field)(jnp.asarray(0.3), jnp.asarray(0.1))


def test_mistake_in_the_potential_of_a_separable_hamiltonian():
    ham = lj.SeparableHamiltonian(lambda p: 0.5 * p**2, lambda q: np.exp(q))
    with pytest.raises(TypeError, match="NumPy"):
        ham.vector_field(jnp.asarray(0.3), jnp.asarray(0.1))
    ham = lj.SeparableHamiltonian(lambda p: 0.5 * p**2, lambda q: None)
    with pytest.raises(ValueError, match="potential energy V returned None"):
        ham.vector_field(jnp.asarray(0.3), jnp.asarray(0.1))


def test_mistake_inside_a_simulate_call_is_named():
    with pytest.raises(TypeError, match=r"jnp\.where"):
        lj.simulate(lj.Lagrangian(branchy), (0.3, 0.1), t1=1.0)


# -- the relativistic particle: L = −mc²√(1 − v²/c²) − kq²/2, m = c = 1 --------------


def relativistic(q, qd):
    return -jnp.sqrt(1.0 - qd @ qd) - 0.5 * q @ q


@pytest.mark.parametrize("size", [0.5, 1.5, 50.0, 1e4])
def test_relativistic_velocity_from_any_momentum(size):
    # v = p/√(m² + p²/c²) for every p; |p| > mc made plain Newton leave |v| < c.
    ham = lj.Lagrangian(relativistic, quadratic_in_velocity=False).to_hamiltonian()
    p = size * jnp.array([0.8, -0.6])
    velocity = ham.velocity(jnp.zeros(2), p)
    exact = p / jnp.sqrt(1.0 + p @ p)
    assert float(jnp.max(jnp.abs(velocity - exact))) <= 4e-16
    assert float(jnp.linalg.norm(velocity)) < 1.0


def test_relativistic_velocity_derivative_is_the_closed_form():
    # ∂v/∂p = (1 − v vᵀ)/γ: the implicit-function derivative through the solve.
    ham = lj.Lagrangian(relativistic, quadratic_in_velocity=False).to_hamiltonian()
    p = jnp.array([3.0, 1.0])
    jacobian = jax.jacfwd(lambda p_: ham.velocity(jnp.zeros(2), p_))(p)
    gamma_inverse = 1.0 / jnp.sqrt(1.0 + p @ p)
    exact = (jnp.eye(2) - jnp.outer(p, p) * gamma_inverse**2) * gamma_inverse
    assert float(jnp.max(jnp.abs(jacobian - exact))) < 1e-12


def test_velocity_beyond_light_has_no_momentum():
    ham = lj.Hamiltonian(
        lambda q, p: jnp.sqrt(1.0 + p @ p) + 0.5 * q @ q, quadratic_in_momentum=False
    )
    lag = ham.to_lagrangian()
    assert abs(float(lag(jnp.zeros(2), jnp.array([0.6, 0.0]))) + 0.8) < 1e-14
    with pytest.raises(Exception, match=r"Legendre transform failed.*∂H/∂p = q̇"):
        jax.block_until_ready(lag(jnp.zeros(2), jnp.array([1.5, 0.0])))


# -- rigid bodies -----------------------------------------------------------------


@pytest.mark.parametrize(
    "moments, message",
    [
        ([1.0, 2.0, math.inf], "not all finite"),
        ([1.0, math.nan, 2.0], "not all finite"),
        ([1.0, 0.0, 2.0], "must all be positive"),
        ([1.0, -1.0, 2.0], "must all be positive"),
        ([1.0, 2.0], r"three principal moments \(shape \(3,\)\)"),
        (1.0, r"three principal moments"),
    ],
)
def test_bad_moments_refused_at_construction(moments, message):
    with pytest.raises(ValueError, match=message):
        lj.RigidBody(moments)


def test_traced_bad_moments_fail_at_run_time():
    body_moments = jax.jit(lambda m: check_moments(m))
    with pytest.raises(Exception, match="finite and positive"):
        jax.block_until_ready(body_moments(jnp.array([1.0, 0.0, 2.0])))


@pytest.mark.parametrize(
    "quaternion, message",
    [
        (jnp.zeros(4), "is zero, which is no rotation"),
        (jnp.full(4, jnp.nan), "not finite"),
    ],
)
def test_quaternion_that_is_no_rotation(quaternion, message):
    body = lj.RigidBody(jnp.array([1.0, 2.0, 3.0]))
    with pytest.raises(ValueError, match=message):
        body.state_from_angular_velocity(quaternion, jnp.ones(3))
    with pytest.raises(Exception, match="zero or not finite"):
        jax.block_until_ready(jax.jit(check_nonzero_quaternion)(quaternion))


@pytest.mark.parametrize("masses", [[1.0, -2.0], [1.0, math.nan], [0.0, 1.0]])
def test_point_masses_must_be_positive(masses):
    with pytest.raises(ValueError, match="finite and positive"):
        point_mass_inertia(jnp.asarray(masses), jnp.eye(3)[:2])


# -- canonical transformations ----------------------------------------------------


@pytest.mark.parametrize(
    "transform, message",
    [
        (
            lambda q, p: (jnp.concatenate([q, p[:1]]), p[1:]),
            "Q of size 3 for q of size 2",
        ),
        (
            lambda q, p: (q[:1], jnp.concatenate([p, q[1:]])),
            "Q of size 1 for q of size 2",
        ),
        (lambda q, p: jnp.concatenate([p, -q]), "must return a pair"),
    ],
)
def test_is_canonical_refuses_mismatched_sides(transform, message):
    with pytest.raises(ValueError, match=message):
        lj.is_canonical(transform, jnp.ones(2), jnp.ones(2))


def test_is_canonical_still_answers_for_matching_sides():
    assert bool(lj.is_canonical(lambda q, p: (p, -q), jnp.ones(2), jnp.ones(2)))
    assert not bool(
        lj.is_canonical(lambda q, p: (2 * q, 2 * p), jnp.ones(2), jnp.ones(2))
    )


# -- scene parameters (validated where they are set) -------------------------------


@pytest.mark.parametrize(
    "build, message",
    [
        (lambda: SimplePendulum(mass=-1.0), "mass = -1.0 must be > 0"),
        (lambda: SimplePendulum(length=-1.0), "length = -1.0 must be > 0"),
        (lambda: SimplePendulum(length=0.0), "length = 0.0 must be > 0"),
        (lambda: SimplePendulum(gravity=math.nan), "gravity"),
        (lambda: HarmonicOscillator(stiffness=math.inf), "stiffness"),
        (lambda: KeplerCartesian(eccentricity=1.5), "eccentricity"),
        (lambda: DoublePendulum(lengths=jnp.array([1.0, -1.0])), "lengths"),
    ],
)
def test_scene_parameters_refused_where_set(build, message):
    with pytest.raises(ValueError, match=message):
        build()


# -- implicit stage solves --------------------------------------------------------


def test_stage_failure_message_names_newton():
    for solver in (lj.ImplicitMidpoint(), lj.GaussLegendre(stages=3)):
        message = stage_failure_message(solver)
        assert "root_finder=optimistix.Newton" in message
        assert type(solver).__name__ in message
    newton = lj.GaussLegendre(root_finder=optx.Newton(rtol=1e-12, atol=1e-12))
    assert "reduce dt" in stage_failure_message(newton)
