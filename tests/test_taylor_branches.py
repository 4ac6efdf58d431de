"""Branches (`lax.cond`, `lax.switch`) in a vector field under the Taylor method:
the step keeps the branch its start selects, in the scalar and the array graph;
a branch without Taylor rules fails the step instead of giving a number; and a
Lagrangian of four coordinates (whose mass-matrix solve has an LU fallback
branch) integrates."""

import math

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.taylor import RESULTS, taylor_coefficients, taylor_integrate
from lagjax.taylor.batch import taylor_integrate_batch

# Two linear fields: the solution through y0 has coefficients Aᵏ y0 / k!.
ROTATION = np.array([[0.0, 1.0], [-1.0, 0.0]])
DAMPED = np.array([[0.0, 1.0], [-2.0, -0.3]])


def linear_by_sign(t, y, args):
    return jax.lax.cond(
        y[0] > 0,
        lambda: jnp.asarray(ROTATION) @ y,
        lambda: jnp.asarray(DAMPED) @ y,
    )


def exact_coefficients(matrix: np.ndarray, y0: np.ndarray, order: int) -> np.ndarray:
    rows, term = [], np.asarray(y0, float)
    for k in range(order + 1):
        rows.append(term)
        term = matrix @ term / (k + 1)
    return np.stack(rows)


@pytest.mark.parametrize("start", [0.4, -0.4])
@pytest.mark.parametrize("scalar", [False, True])
@pytest.mark.parametrize("unroll", [False, True])
def test_cond_coefficients_are_the_selected_branchs(start, scalar, unroll):
    y0 = jnp.array([start, 0.3])
    coeffs = taylor_coefficients(
        linear_by_sign, 0.0, y0, order=10, unroll=unroll, scalar=scalar
    )
    matrix = ROTATION if start > 0 else DAMPED
    expected = exact_coefficients(matrix, np.asarray(y0), 10)
    np.testing.assert_allclose(coeffs, expected, rtol=1e-13, atol=1e-16)


def test_switch_with_three_branches():
    def field(t, y, args):
        index = jnp.clip(jnp.floor(y[0]).astype(jnp.int32), 0, 2)
        return jax.lax.switch(
            index,
            [lambda: -y, lambda: -2.0 * y, lambda: jnp.sin(y)],
        )

    y0 = jnp.array([1.5, 0.2])  # index 1: y' = −2y, y = y0 e^{−2t}
    coeffs = taylor_coefficients(field, 0.0, y0, order=8, scalar=True, unroll=False)
    expected = [np.asarray(y0) * (-2.0) ** k / math.factorial(k) for k in range(9)]
    np.testing.assert_allclose(coeffs, np.stack(expected), rtol=1e-13)


def _with_loop_branch(t, y, args):
    """y' = −y where y₀ > 0; elsewhere a branch written as a loop, which has no
    Taylor rule."""

    def looped():
        return jax.lax.fori_loop(0, 3, lambda i, v: v - y / 3.0, jnp.zeros_like(y))

    return jax.lax.cond(y[0] > 0, lambda: -y, looped)


def test_a_branch_without_rules_fails_the_step_where_it_is_taken():
    good = taylor_integrate(_with_loop_branch, jnp.array([1.0, 0.5]), 0.0, 1.0)
    assert good.result == RESULTS.successful
    np.testing.assert_allclose(
        good.ys[-1], np.array([1.0, 0.5]) * math.exp(-1.0), rtol=1e-13
    )
    bad = taylor_integrate(_with_loop_branch, jnp.array([-1.0, 0.5]), 0.0, 1.0)
    assert bad.result == RESULTS.non_finite
    assert int(bad.num_steps) == 0


def test_no_branch_with_rules_is_refused_by_name():
    def field(t, y, args):
        loop = lambda: jax.lax.fori_loop(0, 2, lambda i, v: v * 0.5, y)
        return jax.lax.cond(y[0] > 0, loop, loop)

    with pytest.raises(NotImplementedError, match=r"scan|while"):
        taylor_integrate(field, jnp.array([1.0, 0.5]), 0.0, 1.0)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_four_coordinate_lagrangian_integrates():
    """Two bodies in a plane, Cartesian coordinates: the Euler–Lagrange solve
    has 4 unknowns (LDLᵀ with a pivoted-LU fallback branch). Total momentum is
    conserved exactly by the equations; the run agrees with Dopri8."""

    def lagrangian(q, v):
        r = jnp.sqrt((q[0] - q[2]) ** 2 + (q[1] - q[3]) ** 2)
        kinetic = 0.5 * (v[0] ** 2 + v[1] ** 2) + (v[2] ** 2 + v[3] ** 2)
        return kinetic + 2.0 / r

    lag = lj.Lagrangian(lagrangian)
    y0 = (jnp.array([1.0, 0.0, -0.5, 0.0]), jnp.array([0.0, 0.8, 0.0, -0.4]))
    ts = jnp.linspace(0.0, 20.0, 41)
    run = lj.simulate(lag, y0, t1=20.0, ts=ts, solver=lj.Taylor(rtol=1e-13, atol=1e-13))
    momentum = run.qdot[:, :2] + 2.0 * run.qdot[:, 2:]
    np.testing.assert_allclose(momentum, momentum[:1].repeat(41, 0), atol=1e-12)
    reference = lj.simulate(lag, y0, t1=20.0, ts=ts, solver=diffrax.Dopri8(), rtol=1e-13,
                            atol=1e-13, max_steps=10**6)  # fmt: skip
    np.testing.assert_allclose(run.q, reference.q, atol=1e-9)


@pytest.mark.integration  # a long run; CI runs it in its integration step (default-suite time)
def test_members_of_a_batch_take_their_own_branch():
    """y0 on either side of the branch, one `vmap`: each member follows the
    flow of its own side, exp(A t) y0, while it stays there (t ≤ 0.3)."""
    starts = jnp.array([[0.4, 0.3], [-0.4, 0.3]])
    mapped = jax.vmap(lambda y: taylor_integrate(linear_by_sign, y, 0.0, 0.3).ys[-1])
    native = taylor_integrate_batch(linear_by_sign, starts, 0.0, 0.3).ys[:, -1]
    for ends in (mapped(starts), native):
        for start, end, matrix in zip(starts, ends, (ROTATION, DAMPED)):
            exact = jax.scipy.linalg.expm(0.3 * jnp.asarray(matrix)) @ start
            np.testing.assert_allclose(end, exact, rtol=1e-13, atol=1e-15)
