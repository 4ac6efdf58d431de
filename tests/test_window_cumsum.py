"""`window_cumsum`: long cumulative sums as two short windows in the dense path.

The two-window sum must equal `lax.cumsum` (forward and reversed, any axis, float32
and integers, its derivatives too); the rewritten Lagrangian must give the same
value and derivatives and leave no window XLA turns into its tree; and the chain's
accelerations at n = 24 must solve the closed-form equations of motion, also with
a parameter passed through `args` and differentiated.
"""

import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax._linalg.window_cumsum import dilated_cumsum, with_window_cumsums
from tests.helpers import relative_close
from tests.test_euler_lagrange_chain import chain_lagrangian, closed_form_acceleration


@pytest.mark.parametrize("n", [17, 24, 25, 32, 100, 256])
@pytest.mark.parametrize("reverse", [False, True])
def test_two_windows_sum_as_cumsum(n, reverse):
    x = jnp.asarray(np.random.default_rng(n).normal(size=(3, n, 2)))
    expected = jax.lax.cumsum(x, axis=1, reverse=reverse)
    assert relative_close(dilated_cumsum(x, 1, reverse), expected, 1e-14)

    weights = jnp.asarray(np.random.default_rng(n + 1).normal(size=x.shape))

    def weighted(cumulative):
        return lambda x: jnp.sum(weights * jnp.sin(cumulative(x)))

    ours = jax.grad(weighted(lambda x: dilated_cumsum(x, 1, reverse)))(x)
    theirs = jax.grad(weighted(lambda x: jax.lax.cumsum(x, 1, reverse=reverse)))(x)
    assert relative_close(ours, theirs, 1e-13)


def test_two_windows_keep_the_dtype():
    for x in (
        jnp.arange(20, dtype=jnp.int32),
        jnp.linspace(0, 1, 30, dtype=jnp.float32),
    ):
        summed = dilated_cumsum(x, 0, False)
        assert summed.dtype == x.dtype
        assert np.allclose(summed, np.cumsum(np.asarray(x)), rtol=1e-6)


def _window_lengths(fn, *args) -> set[int]:
    """The longest dimension of each reduce-window's window, as XLA compiled it."""
    hlo = jax.jit(fn).lower(*args).compile().as_text()
    sizes = re.findall(r"window=\{size=([0-9x]+)", hlo)
    return {max(int(d) for d in size.split("x")) for size in sizes}


def test_rewritten_lagrangian_is_the_same_function_in_short_windows():
    n = 24
    rng = np.random.default_rng(3)
    q, qd = jnp.asarray(rng.normal(size=n)), jnp.asarray(rng.normal(size=n))
    rewritten = with_window_cumsums(chain_lagrangian, q, qd)
    assert rewritten is not chain_lagrangian
    assert relative_close(rewritten(q, qd), chain_lagrangian(q, qd), 1e-14)
    for argnums in (0, 1):
        assert relative_close(
            jax.grad(rewritten, argnums)(q, qd),
            jax.grad(chain_lagrangian, argnums)(q, qd),
            1e-13,
        )
    # Windows of ⌈√24⌉ = 5 terms, which XLA keeps; jnp.cumsum's whole-axis window
    # it rewrites into its tree of 16-term windows (and pads, reshapes, slices).
    assert _window_lengths(rewritten, q, qd) == {5}
    assert _window_lengths(jax.grad(rewritten, 1), q, qd) == {5}
    assert 16 in _window_lengths(chain_lagrangian, q, qd)


def test_short_sums_are_left_as_written():
    q = jnp.ones(16)
    assert with_window_cumsums(chain_lagrangian, q, q) is chain_lagrangian


def test_chain_of_24_links_solves_the_closed_form_equations():
    n = 24
    rng = np.random.default_rng(n)
    q, qd = rng.uniform(-1.0, 1.0, size=n), rng.normal(size=n)
    derived = lj.Lagrangian(chain_lagrangian).acceleration(jnp.asarray(q), qd)
    assert relative_close(derived, closed_form_acceleration(q, qd), 1e-10)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_parameters_through_args_are_traced_and_differentiated():
    # L scaled by a mass m from args (a traced constant of the rewritten jaxpr,
    # batched and differentiated through it): q̈ does not depend on m.
    n = 20
    rng = np.random.default_rng(5)
    q, qd = jnp.asarray(rng.normal(size=n)), jnp.asarray(rng.normal(size=n))
    lag = lj.Lagrangian(lambda q, qd, t, m: m * chain_lagrangian(q, qd))
    unit = lag.acceleration(q, qd, 0.0, 1.0)
    batched = jax.jit(jax.vmap(lag.acceleration, (None, None, None, 0)))
    for row in batched(q, qd, 0.0, jnp.array([0.5, 2.0])):
        assert relative_close(row, unit, 1e-12)
    gradient = jax.grad(lambda m: jnp.sum(lag.acceleration(q, qd, 0.0, m)))(2.0)
    assert abs(float(gradient)) < 1e-10 * float(jnp.max(jnp.abs(unit)))


def test_legendre_inverse_of_a_24_link_chain_is_the_closed_form_velocity():
    # p = M(q) q̇ with M_ij = (n − max(i, j)) cos(θ_i − θ_j); the Hamiltonian's
    # velocity (the inverse Legendre transform, through the rewritten L) returns q̇.
    n = 24
    rng = np.random.default_rng(7)
    q, qd = rng.uniform(-1.0, 1.0, size=n), rng.normal(size=n)
    index = np.arange(n)
    weight = n - np.maximum(index[:, None], index[None, :])
    momentum = (weight * np.cos(q[:, None] - q[None, :])) @ qd
    hamiltonian = lj.Lagrangian(chain_lagrangian).to_hamiltonian()
    velocity = jax.jit(hamiltonian.velocity)(jnp.asarray(q), jnp.asarray(momentum))
    assert relative_close(velocity, qd, 1e-10)
