"""The network formulation of the Euler–Lagrange equations (Hessian–vector products).

Oracles: closed-form accelerations (a harmonic oscillator with array parameters, a
charged particle with a time-dependent field); the closed-form formulation
(`euler_lagrange_acceleration`), an independent derivation of the same equations;
and the routing rule stated in `Lagrangian`'s docstring.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj


class Oscillators(eqx.Module):
    """L = ½ q̇ᵀ diag(m) q̇ − ½ qᵀ diag(k) q: q̈ = −k q / m exactly."""

    mass: jax.Array
    stiffness: jax.Array

    def __call__(self, q, qdot):
        return 0.5 * jnp.sum(self.mass * qdot**2 - self.stiffness * q**2)


class DrivenCharge(eqx.Module):
    """A charge in a plane in B = b(t) ẑ (A = ½ b(t) ẑ × r) plus a trainable
    anharmonic well, with pytree coordinates {"x": scalar, "y": scalar}."""

    well: jax.Array

    def __call__(self, q, qdot, t, args):
        field = args * (1.0 + 0.3 * jnp.sin(t))
        kinetic = 0.5 * (qdot["x"] ** 2 + qdot["y"] ** 2)
        magnetic = 0.5 * field * (q["x"] * qdot["y"] - q["y"] * qdot["x"])
        return kinetic + magnetic - self.well * (q["x"] ** 4 + q["y"] ** 2)


def test_module_with_arrays_takes_the_network_formulation():
    assert lj.Lagrangian(Oscillators(jnp.ones(2), jnp.ones(2))).formulation == "network"
    assert lj.Lagrangian(lambda q, v: 0.5 * v**2).formulation == "closed_form"
    explicit = lj.Lagrangian(lambda q, v: 0.5 * v**2, formulation="network")
    assert explicit.formulation == "network"
    forced = lj.Lagrangian(
        Oscillators(jnp.ones(2), jnp.ones(2)), formulation="closed_form"
    )
    assert forced.formulation == "closed_form"
    with pytest.raises(ValueError, match="formulation is 'auto'"):
        lj.Lagrangian(lambda q, v: 0.5 * v**2, formulation="scalar")


@pytest.mark.parametrize("n", [1, 5])
def test_oscillators_exact_acceleration(n):
    mass, stiffness = jnp.linspace(1.0, 2.0, n), jnp.linspace(3.0, 0.5, n)
    lagrangian = lj.Lagrangian(Oscillators(mass, stiffness))
    q, qdot = jnp.linspace(-0.4, 0.7, n), jnp.linspace(0.2, -0.3, n)
    np.testing.assert_allclose(
        lagrangian.acceleration(q, qdot), -stiffness * q / mass, rtol=1e-14
    )


def test_time_dependent_field_with_force_matches_closed_form_formulation():
    # Lorentz force with a time-varying field: q̈ = b q̇ × ẑ + ½ ḃ ẑ × r − ∇V − γ q̇;
    # the ∂²L/∂q̇∂t term (the induced electric field) is the check on the t tangent.
    charge = DrivenCharge(jnp.asarray(0.4))

    def friction(q, qdot):
        return jax.tree_util.tree_map(lambda v: -0.2 * v, qdot)

    q = {"x": jnp.asarray(0.3), "y": jnp.asarray(-0.5)}
    qdot = {"x": jnp.asarray(0.7), "y": jnp.asarray(0.1)}
    t, b0 = 0.8, 1.5
    results = [
        lj.Lagrangian(charge, force=friction, formulation=f).acceleration(
            q, qdot, t, b0
        )
        for f in ("network", "closed_form")
    ]
    b, b_dot = b0 * (1 + 0.3 * np.sin(t)), b0 * 0.3 * np.cos(t)
    x, y, vx, vy = 0.3, -0.5, 0.7, 0.1
    expected_x = b * vy + 0.5 * b_dot * y - 4 * 0.4 * x**3 - 0.2 * vx
    expected_y = -b * vx - 0.5 * b_dot * x - 2 * 0.4 * y - 0.2 * vy
    for result in results:
        np.testing.assert_allclose(result["x"], expected_x, rtol=1e-13)
        np.testing.assert_allclose(result["y"], expected_y, rtol=1e-13)


def test_singular_mass_matrix_raises_or_poisons():
    degenerate = Oscillators(jnp.array([1.0, 0.0]), jnp.ones(2))  # L linear in q̇_2
    lagrangian = lj.Lagrangian(degenerate)
    q, qdot = jnp.array([0.1, 0.2]), jnp.array([0.3, 0.4])
    with pytest.raises(Exception, match="singular"):
        lagrangian.acceleration(q, qdot)
    assert jnp.all(jnp.isnan(eqx.filter_jit(lagrangian.acceleration)(q, qdot)))


def test_gradient_with_respect_to_parameters_is_exact():
    # d q̈ / dk = −q / m and d q̈ / dm = k q / m² for the oscillators.
    q, qdot = jnp.array([0.5, -0.2]), jnp.array([0.1, 0.3])

    def first_acceleration(model):
        return lj.Lagrangian(model).acceleration(q, qdot)[0]

    model = Oscillators(jnp.array([2.0, 1.0]), jnp.array([3.0, 1.0]))
    grads = eqx.filter_grad(first_acceleration)(model)
    np.testing.assert_allclose(grads.stiffness, [-0.5 / 2.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(grads.mass, [3.0 * 0.5 / 4.0, 0.0], atol=1e-15)
