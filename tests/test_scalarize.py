"""The scalar twin of a function computes the same values and derivatives."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax._linalg.scalarize import as_object_array, scalarize
from tests.helpers import relative_close


def vector_style(q, qd):
    mass = jnp.array(
        [
            [2.0, jnp.cos(q[0] - q[1]), 0.1],
            [jnp.cos(q[0] - q[1]), 1.0, 0.0],
            [0.1, 0.0, 3.0],
        ]
    )
    stacked = jnp.stack([q, qd]).T.reshape(-1)
    return (
        0.5 * qd @ mass @ qd
        + jnp.sum(jnp.sin(q) ** 2)
        + jnp.max(jnp.abs(qd)) * jnp.min(q)
        + jnp.prod(jnp.cos(q))
        + jnp.sum(jnp.concatenate([q[::-1], q[1:]]) ** 3)
        + jnp.where(q[0] > 0, q[1], -q[2])
        + jnp.linalg.norm(stacked)
        + jnp.einsum("ij,ij->", jnp.outer(q, qd), mass)
        + qd @ jnp.eye(3) @ q
    )


def test_scalar_twin_matches_values():
    q = jnp.array([0.3, -0.4, 1.1])
    qd = jnp.array([1.0, 0.5, -0.2])
    twin = scalarize(vector_style, q, qd)
    assert twin is not None
    value = twin(as_object_array(q), as_object_array(qd))
    assert relative_close(value, vector_style(q, qd), 1e-14)


def test_unstack_from_unpacking_is_scalarized():
    """JAX ≥ 0.11 lowers `a, b = q` to `unstack`; the scalar path must keep it."""
    from jax._src.lax.lax import unstack  # the primitive itself, on any JAX

    def unpacked(q, qd):
        a, b = unstack(q, 0)
        wa, wb = unstack(qd, 0)
        return wa**2 + 0.5 * wb**2 + wa * wb * jnp.cos(a - b) + 2 * jnp.cos(a)

    q, qd = jnp.array([0.5, 0.3]), jnp.array([0.1, -0.2])
    twin = scalarize(unpacked, q, qd)
    assert twin is not None
    value = twin(as_object_array(q), as_object_array(qd))
    assert relative_close(value, unpacked(q, qd), 1e-14)
    acceleration = lj.Lagrangian(unpacked).acceleration(q, qd)
    reference = lj.Lagrangian(vector_free_double_pendulum).acceleration(q, qd)
    assert relative_close(acceleration, reference, 1e-13)


def vector_free_double_pendulum(q, qd):
    return (
        qd[0] ** 2
        + 0.5 * qd[1] ** 2
        + qd[0] * qd[1] * jnp.cos(q[0] - q[1])
        + 2 * jnp.cos(q[0])
    )


def test_summed_cotangents_of_a_gradient_are_scalarized():
    """A gradient's jaxpr sums the cotangents of a reused value with `add_any`
    (the n-link chain's equations have it): the scalar path keeps it."""

    def force(q):
        return jax.grad(lambda x: jnp.sin(x[0]) * x[0] + x[0] * x[1] ** 2)(q)

    q = jnp.array([0.7, -0.4])
    assert "add_any" in str(jax.make_jaxpr(force)(q))
    twin = scalarize(force, q)
    assert twin is not None
    value = np.array(twin(as_object_array(q)), dtype=float)
    exact = [np.cos(0.7) * 0.7 + np.sin(0.7) + 0.16, 2 * 0.7 * -0.4]
    assert relative_close(value, np.array(exact), 1e-14)


@pytest.mark.parametrize("config", [((1, 0, 0), (0, 2, 1)), ((-1, 1, 2), (2, -1, 0))])
def test_pad_with_interior_and_cropping_is_lax_pad(config):
    x = jnp.arange(1.0, 7.0).reshape(2, 3)
    twin = scalarize(lambda x: jax.lax.pad(x, -5.0, config), x)
    assert twin is not None
    value = np.array(twin(as_object_array(x)), dtype=float)
    assert np.array_equal(value, np.asarray(jax.lax.pad(x, -5.0, config)))


def test_pad_with_a_traced_padding_value():
    """The padding value may be a tracer (the FPU chain's potential force under
    `jit`), which an object array must hold as it is."""
    config = ((1, 1, 1),)

    def padded(x):
        return jax.lax.pad(x, x[0] * 2.0, config)

    x = jnp.array([1.0, 2.0, 3.0])
    twin = scalarize(padded, x)
    assert twin is not None
    value = jax.jit(lambda x: jnp.stack(list(twin(as_object_array(x)))))(x)
    assert np.array_equal(np.asarray(value), np.asarray(padded(x)))


def test_unsupported_primitive_falls_back():
    assert scalarize(lambda q: jnp.sort(q)[0], jnp.ones(3)) is None
    assert scalarize(lambda q: jnp.sum(q**2), jnp.ones(500)) is None


@pytest.mark.parametrize("seed", [0, 1])
def test_accelerations_agree_with_dense_formulation(seed):
    # n = 3 is derived through the scalar twin; compare with the dense path run on
    # the same function by padding it to more coordinates than the scalar limit.
    rng = np.random.default_rng(seed)
    q, qd = jnp.asarray(rng.normal(size=3)), jnp.asarray(rng.normal(size=3))
    small = lj.Lagrangian(vector_style).acceleration(q, qd)

    def padded(q_big, qd_big):
        return vector_style(q_big[:3], qd_big[:3]) + 0.5 * jnp.sum(qd_big[3:] ** 2)

    big = lj.Lagrangian(padded).acceleration(
        jnp.concatenate([q, jnp.zeros(5)]), jnp.concatenate([qd, jnp.zeros(5)])
    )
    assert np.allclose(small, big[:3], rtol=1e-10, atol=1e-12)


def test_closed_over_tracer_parameters():
    # Parameters captured from an outer trace (vmap over stiffness) are scalarized too.
    def accel(k):
        lag = lj.Lagrangian(lambda q, qd: 0.5 * qd @ qd - 0.5 * k * q @ q)
        return lag.acceleration(jnp.array([1.0, 2.0]), jnp.zeros(2))

    ks = jnp.array([1.0, 2.0, 3.0])
    assert np.allclose(jax.vmap(accel)(ks), -ks[:, None] * jnp.array([1.0, 2.0]))
