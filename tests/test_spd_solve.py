"""`solve_symmetric`: Cholesky for a positive definite M, LU only when needed.

The answers are checked against NumPy's LU solve of the same matrix and the
derivatives against the closed form dx = M⁻¹(db − dM x); the batch-level fallback is
checked by what it computes (every member of a mixed batch exact, NaN-free
gradients) and by its structure (under `vmap` the fallback stays a branch on one
unbatched predicate). Through `simulate`, the n-link pendulum's gradient is
compared with central finite differences on both paths that use the solve (the
scalar formulation at 4–6 coordinates, the dense one above).
"""

import re

import diffrax
import jax
import jax.extend
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax._linalg.loop_factorizations import LOOP_FACTORIZATION_LIMIT
from lagjax._linalg.small_solves import (
    solve_dense,
    solve_symmetric,
    solve_symmetric_system,
    solve_unrolled_symmetric,
)
from tests.helpers import relative_close

N = 7
# The in-kernel loops (up to LOOP_FACTORIZATION_LIMIT unknowns) and LAPACK above.
SIZES = pytest.mark.parametrize("n", [N, LOOP_FACTORIZATION_LIMIT + 1])


def positive_definite(rng, n=N):
    a = rng.normal(size=(n, n))
    return a @ a.T + n * np.eye(n)


def indefinite_zero_minor(rng, n=N):
    """Symmetric, nonsingular, indefinite, M_00 = 0: Cholesky breaks down."""
    a = rng.normal(size=(n, n))
    mass = a + a.T
    mass[0, 0] = 0.0
    return mass


def singular_symmetric(rng, n=N):
    mass = indefinite_zero_minor(rng, n)
    mass[:, -1] = mass[:, 0]
    mass[-1, :] = mass[0, :]
    return mass


def mixed_batch(n=N):
    rng = np.random.default_rng(3)
    masses = [
        positive_definite(rng, n),
        indefinite_zero_minor(rng, n),
        positive_definite(rng, n),
    ]
    rhs = rng.normal(size=(3, n))
    return np.stack(masses), rhs


@SIZES
@pytest.mark.parametrize("make", [positive_definite, indefinite_zero_minor])
def test_solves_exactly_positive_definite_or_not(make, n):
    rng = np.random.default_rng(0)
    mass, rhs = make(rng, n), rng.normal(size=n)
    expected = np.linalg.solve(mass, rhs)
    for solve in (solve_symmetric, jax.jit(solve_symmetric)):
        x, singular = solve(jnp.asarray(mass), jnp.asarray(rhs))
        assert relative_close(x, expected, 1e-12)
        assert not bool(singular)


@SIZES
def test_singular_verdict_matches_lu(n):
    rng = np.random.default_rng(1)
    rhs = jnp.asarray(rng.normal(size=n))
    for mass in (singular_symmetric(rng, n), np.zeros((n, n))):
        assert bool(solve_symmetric(jnp.asarray(mass), rhs)[1])
        assert bool(solve_dense(jnp.asarray(mass), rhs)[1])
    nearly = np.diag([1.0] * (n - 1) + [1e-15])  # positive definite, cond 1e15
    assert bool(solve_symmetric(jnp.asarray(nearly), rhs)[1])


def _unjudged(m, b):
    return solve_symmetric_system(lambda: (m, b), judge=False)


@SIZES
@pytest.mark.parametrize("solve", [solve_symmetric, _unjudged])
def test_mixed_batch_every_member_exact(solve, n):
    masses, rhs = mixed_batch(n)
    x, singular = jax.jit(jax.vmap(solve))(masses, rhs)
    expected = np.linalg.solve(masses, rhs[..., None])[..., 0]
    for member in range(3):
        assert relative_close(x[member], expected[member], 1e-12)
    assert not np.any(singular)


def _equations_named(jaxpr, name):
    """Every equation of primitive `name` in jaxpr and its sub-jaxprs."""
    for equation in jaxpr.eqns:
        if equation.primitive.name == name:
            yield equation
        for sub in jax.extend.core.jaxprs_in_params(equation.params):
            yield from _equations_named(sub, name)


def test_under_vmap_the_fallback_is_one_branch_not_a_select():
    masses, rhs = mixed_batch()
    closed = jax.make_jaxpr(jax.vmap(solve_symmetric))(masses, rhs)
    shapes = [e.invars[0].aval.shape for e in _equations_named(closed.jaxpr, "cond")]
    # The LU fallback (and LU's own branches): each one unbatched predicate.
    assert len(shapes) >= 1 and all(shape == () for shape in shapes)


@SIZES
def test_unjudged_solve_flags_only_what_cholesky_cannot_factor(n):
    # Positive definite, cond 1e15: judged singular, but unjudged the factor is
    # used as it is (finite, never flagged) — on CPU; other backends solve by LU
    # alone, whose verdict is always judged.
    nearly = jnp.diag(jnp.array([1.0] * (n - 1) + [1e-15]))
    b = jnp.ones(n)
    assert bool(solve_symmetric(nearly, b)[1])
    x_nearly, flagged = _unjudged(nearly, b)
    assert bool(flagged) == (jax.default_backend() != "cpu")
    assert relative_close(x_nearly, np.linalg.solve(np.asarray(nearly), b), 1e-12)
    # A singular indefinite matrix: Cholesky fails, LU judges.
    assert bool(
        _unjudged(jnp.asarray(singular_symmetric(np.random.default_rng(2), n)), b)[1]
    )


def _closed_form_tangent(mass, rhs, dmass, drhs):
    x = np.linalg.solve(mass, rhs)
    return np.linalg.solve(mass, drhs - dmass @ x)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
@SIZES
@pytest.mark.parametrize("solve", [solve_symmetric, _unjudged])
def test_jvp_and_grad_match_the_closed_form_in_a_mixed_batch(solve, n):
    masses, rhs = mixed_batch(n)
    rng = np.random.default_rng(4)
    dmasses, drhs = rng.normal(size=masses.shape), rng.normal(size=rhs.shape)
    dmasses = dmasses + np.swapaxes(dmasses, 1, 2)

    def solution(m, b):
        return jax.vmap(solve)(m, b)[0]

    _, tangent = jax.jit(lambda *a: jax.jvp(solution, a[:2], a[2:]))(
        masses, rhs, dmasses, drhs
    )
    weights = rng.normal(size=rhs.shape)
    grad_m, grad_b = jax.jit(
        jax.grad(lambda m, b: jnp.sum(weights * solution(m, b)), argnums=(0, 1))
    )(masses, rhs)
    for k in range(3):
        expected = _closed_form_tangent(masses[k], rhs[k], dmasses[k], drhs[k])
        assert relative_close(tangent[k], expected, 1e-11)
        # ∂(w·x)/∂b = M⁻ᵀw, ∂(w·x)/∂M = −M⁻ᵀw xᵀ.
        adjoint = np.linalg.solve(masses[k].T, weights[k])
        x = np.linalg.solve(masses[k], rhs[k])
        assert relative_close(grad_b[k], adjoint, 1e-11)
        assert relative_close(grad_m[k], -np.outer(adjoint, x), 1e-11)


def n_link_lagrangian(q, qd):
    vx, vy = jnp.cumsum(jnp.cos(q) * qd), jnp.cumsum(jnp.sin(q) * qd)
    return 0.5 * jnp.sum(vx**2 + vy**2) + 9.81 * jnp.sum(jnp.cumsum(jnp.cos(q)))


# 7 s of compile; the jvp/grad rules are checked above and below by default.
@pytest.mark.slow
def test_grad_through_simulate_matches_finite_differences():
    n = 7  # the dense formulation
    lag = lj.Lagrangian(n_link_lagrangian)
    qd0 = jnp.linspace(-0.2, 0.3, n)

    @jax.jit
    def final_weighted_angles(q0):
        traj = lj.simulate(lag, (q0, qd0), t1=0.05, dt=0.01, solver=diffrax.Heun())
        return jnp.sum(jnp.arange(1.0, n + 1.0) * traj.q[-1])

    q0 = jnp.linspace(0.3, 1.0, n)
    gradient = jax.jit(jax.grad(final_weighted_angles))(q0)
    step = 1e-5
    finite = [
        (final_weighted_angles(q0 + e) - final_weighted_angles(q0 - e)) / (2 * step)
        for e in step * np.eye(n)
    ]
    assert relative_close(gradient, np.array(finite), 1e-7)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_tangent_of_the_scalar_formulation_matches_finite_differences():
    n = 4  # the scalar formulation, whose 4–6 coordinates use the unrolled solve
    acceleration = jax.jit(lj.Lagrangian(n_link_lagrangian).acceleration)
    q, qd = jnp.linspace(0.3, 1.0, n), jnp.linspace(-0.2, 0.3, n)
    direction = jnp.linspace(1.0, -0.5, n)
    tangent = jax.jit(
        lambda x: jax.jvp(lambda y: acceleration(y, qd), (x,), (direction,))[1]
    )(q)
    step = 1e-5
    finite = (
        acceleration(q + step * direction, qd) - acceleration(q - step * direction, qd)
    ) / (2 * step)
    assert relative_close(tangent, finite, 1e-7)


def _unrolled(m, b):
    n = b.shape[0]
    upper = [[m[i, j] if j >= i else None for j in range(n)] for i in range(n)]
    return solve_unrolled_symmetric(upper, [b[i] for i in range(n)])


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_unrolled_form_exact_in_a_mixed_batch_with_nan_free_gradients():
    rng = np.random.default_rng(5)
    n = 5
    masses = np.stack(
        [
            positive_definite(rng, n),
            indefinite_zero_minor(rng, n),
            singular_symmetric(rng, n),
        ]
    )
    rhs = rng.normal(size=(3, n))
    x, singular = jax.jit(jax.vmap(_unrolled))(masses, rhs)
    for member in range(2):
        expected = np.linalg.solve(masses[member], rhs[member])
        assert relative_close(x[member], expected, 1e-12)
    assert list(np.asarray(singular)) == [False, False, True]
    weights = rng.normal(size=(2, n))
    grad_m, grad_b = jax.jit(
        jax.grad(
            lambda m, b: jnp.sum(weights * jax.vmap(_unrolled)(m, b)[0]),
            argnums=(0, 1),
        )
    )(masses[:2], rhs[:2])
    for member in range(2):
        adjoint = np.linalg.solve(masses[member].T, weights[member])
        x = np.linalg.solve(masses[member], rhs[member])
        assert relative_close(grad_b[member], adjoint, 1e-11)
        # Only the upper triangle is read: the symmetric pair's sum lands there.
        full = -np.outer(adjoint, x)
        expected = np.triu(full + full.T) - np.diag(np.diag(full))
        assert relative_close(grad_m[member], expected, 1e-11)


def _factorization_shapes(function, platform: str, *inputs) -> dict[str, set[str]]:
    """{"potrf" (Cholesky) / "getrf" (LU): operand shapes} of the factorizations in
    `function` exported for `platform` (no such device needed: export only lowers)."""
    module = jax.export.export(jax.jit(function), platforms=[platform])(*inputs)
    calls = re.findall(r"custom_call @\w*?(potrf|getrf)\w*\((.*)", module.mlir_module())
    shapes: dict[str, set[str]] = {}
    for kind, rest in calls:
        shape = re.search(r"tensor<([\dx]+)xf64>", rest).group(1)
        shapes.setdefault(kind, set()).add(shape)
    return shapes


# (coordinates, members, LAPACK calls on CPU: {routine: operand shapes})
FACTORIZATIONS = [
    (6, 5, {}),  # scalar LDLᵀ; its LU fallback by in-kernel loops
    (8, 5, {}),  # in-kernel loops, no LAPACK at all
    (17, 5, {"potrf": {"5x17x17"}, "getrf": {"5x17x17"}}),  # one batched call
    (17, 64, {"potrf": {"17x17"}, "getrf": {"64x17x17"}}),  # factored per member
]


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
@pytest.mark.parametrize("n, members, on_cpu", FACTORIZATIONS)
def test_factorizations_per_backend(n, members, on_cpu):
    # Up to 16 coordinates the dense formulation factors by XLA loops. Above,
    # jaxlib's batched CPU Cholesky can deadlock when called from XLA's thread
    # pool (n-link pendulum n = 16 ×512 hung in each of 3 tries), so above a work
    # limit (64 × 17³ is over it, 5 × 17³ under) it maps the factorization over
    # the members on CPU; the LU fallback sits in its branch. A GPU solves by LU
    # alone, one batched call, with no branch (a branch waits for the host
    # there). The derivative rule keeps the batched factorization
    # (differentiable again); this checks the undifferentiated run.
    acceleration = lj.Lagrangian(n_link_lagrangian).acceleration
    q = jnp.tile(jnp.linspace(0.3, 1.0, n), (members, 1))
    run = jax.vmap(lambda a, b: acceleration(a, b, check=False))
    assert _factorization_shapes(run, "cpu", q, jnp.zeros_like(q)) == on_cpu
    on_gpu = {"getrf": {f"{members}x{n}x{n}"}}
    assert _factorization_shapes(run, "cuda", q, q) == on_gpu
    # And the answers are those of the unbatched calls.
    scale = jnp.linspace(0.5, 1.5, members)[:, None]
    batched = jax.jit(jax.vmap(acceleration))(q * scale, q)
    for member in (0, members // 2, members - 1):
        single = acceleration(q[member] * scale[member], q[member])
        assert relative_close(batched[member], single, 1e-13)
