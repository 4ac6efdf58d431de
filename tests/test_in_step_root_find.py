"""Newton inside a step: the unrolled pivoted LU, the `InStepLU` lineax solver and
`root_find_in_step`, against NumPy/LAPACK and closed-form roots.

The unrolled LU must solve unsymmetric matrices that need row exchanges (a zero
leading entry) and give LAPACK's pivots; a singular matrix must never give a finite
answer. `InStepLU` must solve the transposed system too (reverse mode through
`optimistix.root_find` solves with Jᵀ) and name a singular Jacobian. The root
finder is checked on a system whose root and whose derivative with respect to a
parameter are known in closed form (implicit function theorem).
"""

import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import lineax as lx
import numpy as np
import optimistix as optx
import pytest

from lagjax._linalg.in_step_root_find import InStepLU, root_find_in_step
from lagjax._linalg.unrolled_lu import lu_solve_unrolled
from tests.helpers import relative_close


def _needs_pivoting(rng, n):
    matrix = rng.normal(size=(n, n))
    matrix[0, 0] = 0.0  # elimination without a row exchange divides by zero
    return matrix


@pytest.mark.parametrize("n", [1, 2, 3, 4, 6])
def test_unrolled_lu_solves_and_pivots_as_lapack(n):
    rng = np.random.default_rng(20 + n)
    for matrix in (rng.normal(size=(n, n)), _needs_pivoting(rng, n)):
        if n == 1:
            matrix[0, 0] = 0.5
        rhs = rng.normal(size=n)
        solve = jax.jit(lambda m, b: lu_solve_unrolled(list(map(list, m)), list(b)))
        x, pivots = solve(jnp.asarray(matrix), jnp.asarray(rhs))
        assert relative_close(jnp.stack(x), np.linalg.solve(matrix, rhs), 1e-11)
        lu, _ = jsl.lu_factor(jnp.asarray(matrix))
        assert relative_close(jnp.stack(pivots), jnp.diagonal(lu), 1e-12)


def test_unrolled_lu_of_a_singular_matrix_is_never_a_finite_answer():
    rhs = [1.0, -2.0, 0.5]
    rank_one = np.outer([1.0, 2.0, 3.0], [1.0, -1.0, 2.0])
    for matrix in (np.zeros((3, 3)), rank_one):
        x, pivots = lu_solve_unrolled(matrix.tolist(), rhs)
        assert not np.all(np.isfinite(np.stack(x)))
        assert min(abs(float(p)) for p in pivots) <= 1e-15 * np.max(np.abs(matrix))


@pytest.mark.parametrize("n", [3, 9])  # unrolled, XLA loops
def test_in_step_lu_solves_the_system_and_its_transpose(n):
    rng = np.random.default_rng(30 + n)
    matrix, rhs = jnp.asarray(_needs_pivoting(rng, n)), jnp.asarray(rng.normal(size=n))
    operator = lx.MatrixLinearOperator(matrix)
    solution = lx.linear_solve(operator, rhs, InStepLU())
    assert solution.result == lx.RESULTS.successful
    assert relative_close(solution.value, np.linalg.solve(matrix, rhs), 1e-11)

    # Reverse mode through the solve: d(w·x)/db = M⁻ᵀ w, solved with the transpose.
    weights = jnp.asarray(rng.normal(size=n))

    def weighted(b):
        return weights @ lx.linear_solve(operator, b, InStepLU()).value

    expected = np.linalg.solve(np.asarray(matrix).T, weights)
    assert relative_close(jax.grad(weighted)(rhs), expected, 1e-11)


@pytest.mark.parametrize("n", [2, 9])
def test_in_step_lu_names_a_singular_operator(n):
    singular = jnp.outer(jnp.arange(1.0, n + 1), jnp.ones(n))
    solution = lx.linear_solve(
        lx.MatrixLinearOperator(singular), jnp.ones(n), InStepLU(), throw=False
    )
    assert solution.result == lx.RESULTS.singular


def test_root_find_in_step_on_a_closed_form_root_and_its_derivative():
    # x² + y² = a², x − y = 1 (an unsymmetric Jacobian): with s = √(2a² − 1),
    # x = (1 + s)/2, y = (s − 1)/2 and dx/da = dy/da = a/s.
    def residual(z, a):
        x, y = z
        return jnp.stack([x**2 + y**2 - a**2, x - y - 1.0])

    newton = optx.Newton(rtol=1e-13, atol=1e-13)

    def root(a):
        value, result = root_find_in_step(
            lambda z, _: residual(z, a), newton, jnp.array([1.5, 0.2]), 32
        )
        return value, result

    a = 2.0
    s = np.sqrt(2 * a**2 - 1)
    value, result = jax.jit(root)(a)
    assert result == optx.RESULTS.successful
    assert relative_close(value, [(1 + s) / 2, (s - 1) / 2], 1e-14)
    derivative = jax.jacfwd(lambda a: root(a)[0])(a)
    assert relative_close(derivative, [a / s, a / s], 1e-12)
    gradient = jax.grad(lambda a: jnp.sum(root(a)[0]))(a)
    assert relative_close(gradient, 2 * a / s, 1e-12)
