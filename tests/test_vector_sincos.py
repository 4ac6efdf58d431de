"""`lagjax.taylor.vector_sincos`: within 1 ulp of libm's sin and cos from tiny
arguments to the reduction's bound, libm itself beyond, and exact symmetries."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lagjax.taylor.vector_sincos import BOUND, sin_cos


def ulps(ours: np.ndarray, exact: np.ndarray) -> np.ndarray:
    return np.abs(ours - exact) / np.spacing(np.maximum(np.abs(exact), 1e-300))


@pytest.mark.parametrize("scale", [1e-8, 1.0, 10.0, 1e3, 1e5, 0.99 * BOUND])
def test_within_one_ulp_of_libm(scale):
    x = np.random.default_rng(1).uniform(-scale, scale, 20_000)
    sin, cos = jax.jit(sin_cos)(jnp.asarray(x))
    assert np.max(ulps(np.asarray(sin), np.sin(x))) <= 1.0
    assert np.max(ulps(np.asarray(cos), np.cos(x))) <= 1.0


def test_near_multiples_of_half_pi_and_beyond_the_bound():
    n = np.arange(1, 2000, 7.0)
    x = np.nextafter(n * np.pi / 2, np.inf)  # the reduction's hardest cancellations
    sin, cos = jax.jit(sin_cos)(jnp.asarray(x))
    # relative to the larger of |sin|, |cos| (one of them is ~1e-16 here)
    assert np.max(np.abs(np.asarray(sin) - np.sin(x))) < 2e-16 * np.max(n)
    assert np.max(np.abs(np.asarray(cos) - np.cos(x))) < 2e-16 * np.max(n)
    big = jnp.asarray([3.0 * BOUND, -1e12, 0.5])
    np.testing.assert_array_equal(jax.jit(sin_cos)(big)[0], jnp.sin(big))


def test_odd_and_even():
    x = jnp.linspace(0.0, 40.0, 1001)
    (s, c), (s_minus, c_minus) = sin_cos(x), sin_cos(-x)
    np.testing.assert_array_equal(s_minus, -s)
    np.testing.assert_array_equal(c_minus, c)
