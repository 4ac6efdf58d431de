"""Constants and signs folded while the Taylor graph is lowered
(`lagjax.taylor.graph_signs`): the coefficients stay those of nested JVPs, the
double pendulum's graph loses its products by ±1 and a repeated product, and a
batch with a vmapped parameter still lowers."""

import jax
import jax.numpy as jnp
import pytest

import lagjax as lj
from lagjax.taylor import taylor_coefficients
from lagjax.taylor.coefficients import lower_vector_field
from tests.helpers import lie_coefficients
from tests.test_taylor import LAGRANGIAN, double_pendulum


def _signs(t, y, args):
    """Every sign rule once: −(−a), a·(−1), (−a)·(−b), a + (−b), (−a) + b,
    a − (−b), (−a) − (−b), c/(−b), (−a)/b, and factors made of literals."""
    a, b = y[0], y[1]
    minus_one = jnp.multiply(-0.5, 2.0)  # an operation on literals: folded
    na, nb = -a, -b
    first = -na * minus_one + na * nb + (a + nb) * ((na + b) - (a - nb))
    second = (na - nb) * 1.5 / (2.0 + nb) + (na * b) / (3.0 + b * b) + 2.0 / (nb - 4.0)
    return jnp.stack([first * jnp.multiply(1.0, 1.0), second])


@pytest.mark.parametrize("scalar", [False, True])
def test_folded_coefficients_match_nested_jvp(scalar):
    y0 = jnp.array([0.7, -0.4])
    ours = jax.jit(
        lambda y: taylor_coefficients(_signs, 0.0, y, order=4, scalar=scalar)
    )(y0)
    field = lambda z: _signs(0.0, z, None)
    reference = jax.jit(lambda y: lie_coefficients(field, y, 4))(y0)
    assert jnp.allclose(ours, reference, rtol=1e-13, atol=1e-14)


def test_the_double_pendulum_graph_is_folded():
    y0 = jnp.array([0.5, 0.3, 0.1, -0.2])
    graph, _ = lower_vector_field(double_pendulum, 0.0, y0, None, scalar=True)
    census = graph.census()
    # wa·wb·(−sin δ) and wa·wb·(−(−1·sin δ)) are one product now; 9 before.
    assert census["Product"] == 8, census
    negations = [
        op for op in graph.ops
        if op.outs[0] in graph.series and getattr(op.rule, "primitive", None) is jax.lax.neg_p
    ]  # fmt: skip
    negated = {op.ins[0] for op in negations}
    assert not negated & {op.outs[0] for op in negations}  # no −(−x)
    for op in graph.ops:  # no product by a constant ±1 is left
        for i in op.ins:
            if i in graph.constants and type(op.rule).__name__ == "Scale":
                assert abs(float(graph.constants[i])) != 1.0, op


@pytest.mark.integration  # a batch loop compiles (seconds)
def test_vmap_over_a_folded_graph_matches_one_run():
    """The double pendulum's derivation holds operations on literals (1·1, −1),
    folded inside the batch loop's custom_vmap trace (where a constant made by
    `jnp.asarray` would be a tracer): the batch equals the runs one by one."""

    def final(y):
        solver = lj.Taylor(rtol=1e-13, atol=1e-13)
        run = lj.simulate(LAGRANGIAN, (y[:2], y[2:]), t1=1.0, solver=solver)
        return run.q[-1]

    y0s = jnp.array([[0.3, -0.1, 0.0, 0.2], [0.5, 0.2, 0.1, 0.0], [0.1, 0.4, 0.0, 0.0]])
    batch = jax.jit(jax.vmap(final))(y0s)
    for i in range(3):
        assert jnp.allclose(batch[i], jax.jit(final)(y0s[i]), rtol=0, atol=1e-13)
