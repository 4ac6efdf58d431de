"""`value_and_scalar_gradient`: the value and gradient on scalars agree with
`jax.value_and_grad` (a pair potential with a time-dependent strength, a
quadratic form whose gradient's jaxpr holds an outer product), and a function
too large for the scalar form is taken as written."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lagjax._linalg.scalar_value_and_gradient import value_and_scalar_gradient
from lagjax.mechanics.particles import pair_energy

MASSES = jnp.array([3.0, 4.0, 5.0])


def gravity(q, t):
    """Three bodies, G(t) = 1 + t/10: ∂V/∂t is not zero."""
    strengths = -(1 + 0.1 * t) * jnp.outer(MASSES, MASSES)
    return pair_energy(q, lambda r: 1 / r, strengths)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_pair_potential_value_and_both_gradients():
    q = jnp.array([[1.0, 3.0], [-2.0, -1.0], [1.0, -1.0]])
    t = jnp.asarray(0.3)
    value, (dv_dq, dv_dt) = value_and_scalar_gradient(gravity, q, t)
    expected, (expected_q, expected_t) = jax.value_and_grad(gravity, (0, 1))(q, t)
    np.testing.assert_allclose(value, expected, rtol=1e-14)
    np.testing.assert_allclose(dv_dq, expected_q, rtol=1e-13)
    np.testing.assert_allclose(dv_dt, expected_t, rtol=1e-13)
    # The scalar route was taken: no array contraction is left in the graph.
    graph = str(
        jax.make_jaxpr(lambda q, t: value_and_scalar_gradient(gravity, q, t))(q, t)
    )
    assert "dot_general" not in graph and "custom_jvp" not in graph


def test_quadratic_form_under_vmap():
    """T = p·p/2: its gradient's jaxpr multiplies a scalar cotangent into a vector
    (a dot without contraction)."""
    ps = jnp.array([[0.5, -2.0], [3.0, 1.0]])
    values, (gradients,) = jax.vmap(
        lambda p: value_and_scalar_gradient(lambda p: p @ p / 2, p)
    )(ps)
    np.testing.assert_allclose(values, np.sum(ps**2, axis=1) / 2, rtol=1e-15)
    np.testing.assert_allclose(gradients, ps, rtol=1e-15)


def test_many_coordinates_are_taken_as_written():
    x = jnp.linspace(0.1, 2.0, 40)  # above SCALAR_GRADIENT_LIMIT
    value, (gradient,) = value_and_scalar_gradient(lambda x: jnp.sum(jnp.sin(x)), x)
    np.testing.assert_allclose(value, np.sum(np.sin(x)), rtol=1e-14)
    np.testing.assert_allclose(gradient, np.cos(x), rtol=1e-14)
