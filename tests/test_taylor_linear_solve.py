"""Mass-matrix solves in the Taylor graph: one operation with its own recurrence
(`lagjax._linalg.marked_solves`, `recurrences.LinearSolve`), checked against
nested `jax.jvp` and, on a system with more coordinates than the scalar
formulation takes, against a tight Runge–Kutta run."""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax._linalg.marked_solves import MARKED_SOLVE_NAME, marking_solves
from lagjax._linalg.small_solves import solve_symmetric
from lagjax.taylor import taylor_coefficients
from lagjax.taylor.coefficients import lower_vector_field
from lagjax.taylor.tape import supports
from tests.helpers import lie_coefficients

SIZE = 3


def _mass(q):
    """Symmetric positive definite and varying with q."""
    coupling = 0.3 * jnp.outer(jnp.sin(q), jnp.cos(q))
    return jnp.diag(2.0 + q**2) + coupling + coupling.T


def _lagjax_solve(m, rhs):
    return solve_symmetric(m, rhs)[0]


def _moving_matrix_field(t, y, args, solve=_lagjax_solve):
    q, v = y[:SIZE], y[SIZE:]
    rhs = -jnp.sin(q) + 0.2 * v * jnp.roll(v, 1)
    return jnp.concatenate([v, solve(_mass(q), rhs)])


def _fixed_matrix_field(t, y, args, solve=_lagjax_solve):
    q, v = y[:SIZE], y[SIZE:]
    return jnp.concatenate([v, solve(args, -jnp.sin(q) * jnp.exp(0.1 * v))])


Y0 = jnp.array([0.4, -0.3, 0.9, 0.2, 0.5, -0.7])
FIXED_MASS = jnp.array([[2.0, 0.5, 0.1], [0.5, 3.0, 0.4], [0.1, 0.4, 1.5]])


def _rules(field, args):
    graph, _ = lower_vector_field(field, 0.0, Y0, args)
    return [type(op.rule).__name__ for op in graph.ops if op.outs[0] in graph.series]


@pytest.mark.parametrize(
    "field, args", [(_moving_matrix_field, None), (_fixed_matrix_field, FIXED_MASS)]
)
@pytest.mark.parametrize(
    "unroll, scalar",
    [
        (False, False),
        pytest.param(True, False, marks=pytest.mark.integration),
        (False, True),
    ],
)
def test_solve_coefficients_match_nested_jvp(field, args, unroll, scalar):
    """The array graph's solve is one operation (no Cholesky loop lowered); the
    scalar graph's is unrolled LDLᵀ on the tape (`scalarize`)."""
    assert _rules(field, args).count("LinearSolve") == 1
    graph, _ = lower_vector_field(field, 0.0, Y0, args, scalar=True)
    assert graph.scalar and supports(graph)
    ours = jax.jit(
        lambda y: taylor_coefficients(
            field, 0.0, y, args, order=5, unroll=unroll, scalar=scalar
        )
    )(Y0)
    # The same field with JAX's LU solve (nested JVPs through lagjax's Cholesky
    # loops take 20 s to compile at order 5).
    plain = lambda z: field(0.0, z, args, solve=jnp.linalg.solve)
    reference = jax.jit(lambda y: lie_coefficients(plain, y, 5))(Y0)
    scale = jnp.max(jnp.abs(reference), axis=1, keepdims=True)
    assert jnp.max(jnp.abs(ours - reference) / scale) < 1e-13


def test_the_mark_is_only_on_inside_the_taylor_trace():
    """Outside `marking_solves` the solve is the Cholesky path; a trace made
    under the mark is not reused without it (the compiled acceleration keys on
    it)."""

    def calls(jaxpr):
        names = []
        for eqn in jaxpr.eqns:
            names.append(eqn.params.get("name"))
            for value in eqn.params.values():
                for inner in value if isinstance(value, tuple) else (value,):
                    inner = getattr(inner, "jaxpr", inner)
                    if hasattr(inner, "eqns"):
                        names.extend(calls(inner))
        return names

    chain = lj.Lagrangian(_seven_link_lagrangian)
    q, v = jnp.full(7, 0.2), jnp.zeros(7)
    with marking_solves():
        marked = jax.make_jaxpr(chain.acceleration)(q, v)
    plain = jax.make_jaxpr(chain.acceleration)(q, v)
    assert MARKED_SOLVE_NAME in calls(marked.jaxpr)
    assert MARKED_SOLVE_NAME not in calls(plain.jaxpr)
    m = _mass(Y0[:SIZE])
    x, singular = solve_symmetric(m, jnp.ones(SIZE))
    assert np.allclose(m @ x, 1.0, rtol=0, atol=1e-14) and not singular


def _seven_link_lagrangian(q, qdot):
    """A seven-link pendulum (unit masses and lengths, g = 9.81): more
    coordinates than the scalar formulation takes, so the dense solve."""
    y = -jnp.cumsum(jnp.cos(q))
    vx = jnp.cumsum(jnp.cos(q) * qdot)
    vy = jnp.cumsum(jnp.sin(q) * qdot)
    return 0.5 * jnp.sum(vx**2 + vy**2) - 9.81 * jnp.sum(y)


@pytest.mark.integration  # a minute of compilation
@pytest.mark.parametrize("backend", ["jax", "heyoka"])
def test_seven_link_pendulum_matches_dopri8(backend):
    if backend == "heyoka":
        pytest.importorskip("heyoka")
    chain = lj.Lagrangian(_seven_link_lagrangian)
    y0 = (jnp.linspace(0.2, 0.6, 7), jnp.zeros(7))
    solver = lj.Taylor(backend=backend)
    taylor = lj.simulate(chain, y0, t1=3.0, solver=solver, rtol=1e-13, atol=1e-13)
    reference = lj.simulate(
        chain, y0, t1=3.0, solver=diffrax.Dopri8(), rtol=1e-14, atol=1e-14,
        max_steps=10**6,
    )  # fmt: skip
    assert np.allclose(taylor.q[-1], reference.q[-1], rtol=0, atol=1e-10)
    assert np.allclose(taylor.qdot[-1], reference.qdot[-1], rtol=0, atol=1e-9)
    energy = np.asarray(chain.energy(taylor.q[-1], taylor.qdot[-1]))
    assert abs(energy / chain.energy(*y0) - 1) < 1e-11


def _indefinite_lagrangian(q, qdot):
    """Seven coordinates, one with a negative kinetic term (M indefinite)."""
    signs = jnp.array([1.0, 1.0, 1.0, 1.0, 1.0, 1.0, -1.0])
    return 0.5 * jnp.sum(signs * qdot**2 * (1 + 0.1 * jnp.cos(q))) - 0.5 * jnp.sum(q**2)


@pytest.mark.integration  # compile-heavy
@pytest.mark.parametrize("backend", ["jax", "heyoka"])
def test_an_indefinite_mass_matrix_stops_the_taylor_route_by_name(backend):
    """Both routes solve by LDLᵀ without pivoting (LU has no recurrence): a mass
    matrix that is not positive definite is refused, not solved wrongly."""
    if backend == "heyoka":
        pytest.importorskip("heyoka")
    system = lj.Lagrangian(_indefinite_lagrangian)
    y0 = (jnp.linspace(0.1, 0.7, 7), jnp.zeros(7))
    solver = lj.Taylor(backend=backend)
    with pytest.raises(lj.SimulationError, match="non-finite"):
        lj.simulate(system, y0, t1=1.0, solver=solver, rtol=1e-10, atol=1e-10)
