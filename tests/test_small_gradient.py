"""Forces ṗ = −∂V/∂q from `small_gradient`: each route against the closed form.

Up to 6 coordinates V is differentiated in its scalar form (checked on Kepler's
force, a pytree of coordinates and a V with t and args), a V that cannot be
re-expressed in scalars falls back to `jacfwd`, and above 6 coordinates reverse
mode is used (a harmonic chain); the derivative is differentiable again (the
Hessian of Kepler's potential in closed form) and batches under `vmap`.
"""

import jax
import jax.numpy as jnp
import numpy as np

from lagjax._linalg.scalarize import scalarize
from lagjax._linalg.small_gradient import small_gradient
from tests.helpers import relative_close


def kepler_potential(q):
    return -1.0 / jnp.sqrt(jnp.sum(q * q))


def kepler_gradient(q):  # ∂(−1/r)/∂q = q / r³
    return q / np.linalg.norm(q) ** 3


def test_scalar_form_gives_keplers_gradient_and_hessian():
    q = jnp.array([0.4, -0.3, 0.2])
    assert scalarize(kepler_potential, q) is not None  # the scalar route is taken
    assert relative_close(
        small_gradient(kepler_potential)(q), kepler_gradient(q), 1e-14
    )
    r = float(jnp.linalg.norm(q))
    hessian = np.eye(3) / r**3 - 3.0 * np.outer(q, q) / r**5
    assert relative_close(
        jax.jacfwd(small_gradient(kepler_potential))(q), hessian, 1e-13
    )
    qs = jnp.stack([q, 2.0 * q, -q])
    batched = jax.jit(jax.vmap(small_gradient(kepler_potential)))(qs)
    for member, point in zip(batched, qs):
        assert relative_close(member, kepler_gradient(np.asarray(point)), 1e-14)


def test_pytree_coordinates_time_and_arguments():
    def potential(q, t, args):
        return args["k"] * jnp.cos(t) * (jnp.sum(q["a"] ** 4) + q["b"] ** 2)

    q = {"a": jnp.array([1.0, -2.0]), "b": jnp.asarray(0.5)}
    gradient = jax.jit(small_gradient(potential))(q, 0.3, {"k": 2.0})
    scale = 2.0 * np.cos(0.3)
    assert relative_close(gradient["a"], scale * 4.0 * np.array([1.0, -8.0]), 1e-14)
    assert relative_close(gradient["b"], scale * 2.0 * 0.5, 1e-14)


def test_unscalarizable_potential_falls_back_to_jacfwd():
    def sorted_weights(q):  # sort is not in the scalar form's primitive set
        return jnp.sum(jnp.arange(1.0, 4.0) * jnp.sort(q) ** 2)

    q = jnp.array([0.7, -0.2, 0.4])
    assert scalarize(sorted_weights, q) is None
    # Sorted order (−0.2, 0.4, 0.7) carries weights 1, 2, 3: ∂/∂q_i = 2 w_i q_i.
    expected = 2.0 * np.array([3.0, 1.0, 2.0]) * np.asarray(q)
    assert relative_close(small_gradient(sorted_weights)(q), expected, 1e-14)


def test_above_the_forward_limit_a_chain_by_reverse_mode():
    def chain(q):  # unit springs between neighbours, ends held at 0
        padded = jnp.concatenate([jnp.zeros(1), q, jnp.zeros(1)])
        return 0.5 * jnp.sum(jnp.diff(padded) ** 2)

    q = jnp.linspace(-1.0, 1.0, 9) ** 3
    stiffness = 2.0 * np.eye(9) - np.eye(9, k=1) - np.eye(9, k=-1)
    assert relative_close(small_gradient(chain)(q), stiffness @ np.asarray(q), 1e-14)
