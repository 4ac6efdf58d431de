"""Negations folded in the heyoka translation (`lagjax.taylor.heyoka_signs`): the
same numbers as the unfolded translation and as JAX, fewer terms, and the
singular-mass-matrix guard still stopping a run."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj

hy = pytest.importorskip("heyoka")

from lagjax.taylor import heyoka_expressions  # noqa: E402
from lagjax.taylor.heyoka_backend import heyoka_integrate  # noqa: E402
from lagjax.taylor.heyoka_rules import elementwise_rules  # noqa: E402


def signs(t, y, args):
    """Every folded pattern: double negation, sums and differences with a
    negation, products and quotients with one or two, by ±1 and by a number, and
    the guard `|x| <= c` (also written `c >= |x|`) in front of a division."""
    a, b, c, d = y[0], y[1], y[2], y[3]
    near = jnp.abs(a - b) <= 0.25
    return jnp.stack([
        -(-jnp.sin(a)),  # noqa: B002 (the double negations are the point)
        a - (-(b * c)) + (-d),
        b * -jnp.cos(a) - (-c) * (-d),
        19.62 * -jnp.sin(b) - (-1.0 * a) + 1.0 * -c,
        (-a) / (-(d + 3.0)) + (-b) / (c * c + 1.0),
        jnp.where(near, jnp.nan, c / (a - b)),
        jnp.where(0.5 >= jnp.abs(c),  # noqa: SIM300 (the relation `ge`)
                   -(a * -b), -(-d) / 2.0),  # noqa: B002
        jnp.sum(jnp.stack([-a, b, -c]) * jnp.stack([d, -d, 2.0])),
    ])  # fmt: skip


def both_translations(fn, n, args=None):
    """(folded, unfolded) translations of `fn`: the second with the plain
    element rules, as before the folding."""
    folded = heyoka_expressions.jaxpr_to_heyoka(fn, n, args)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(
            heyoka_expressions, "folding_rules", lambda hy: dict(elementwise_rules(hy))
        )
        unfolded = heyoka_expressions.jaxpr_to_heyoka(fn, n, args)
    return folded, unfolded


def compiled(system):
    return hy.cfunc([f for _, f in system.equations], [y for y, _ in system.equations])


def points(n: int) -> np.ndarray:
    """Random states (n, 8), and the special ones: signed zeros, the guard's
    edge and inside it."""
    rng = np.random.default_rng(1)
    special = np.array([
        [0.0, -0.0, 0.0, -0.0],
        [-0.0, 0.0, -0.0, 0.0],
        [0.3, 0.3, 0.5, -0.5],
        [0.55, 0.3, -0.5, 1.0],
        [0.3, 0.55, 2.0, -3.0],
    ])  # fmt: skip
    special = np.concatenate([special, special], axis=1)
    return np.concatenate([rng.normal(scale=2.0, size=(n, 8)), special])


def test_folded_translation_computes_the_same_numbers_with_fewer_terms():
    folded, unfolded = both_translations(signs, 8)
    states = points(2000)  # y4..y7 unused: `jaxpr_to_heyoka` wants 8 outputs, 8 states
    columns = np.ascontiguousarray(states.T)
    new, old = compiled(folded)(columns), compiled(unfolded)(columns)
    # equal but for the last bits where heyoka fuses a moved product into a sum
    # (FMA), NaN where the guard fires included
    np.testing.assert_allclose(new, old, rtol=1e-13, atol=1e-14)
    np.testing.assert_array_equal(np.isnan(new), np.isnan(old))
    assert np.isnan(new[5]).sum() == np.sum(np.abs(states[:, 0] - states[:, 1]) <= 0.25)
    jax_values = jax.jit(jax.vmap(signs, (None, 0, None)))(0.0, states, None)
    np.testing.assert_allclose(new.T, jax_values, rtol=1e-14, atol=1e-14)
    assert len(compiled(folded).dc) < len(compiled(unfolded).dc)


G = 9.81


def pendulum(q, qd, t, args):
    (a, b), (u, v) = (q[0], q[1]), (qd[0], qd[1])
    return (
        u**2 + 0.5 * v**2 + u * v * jnp.cos(a - b) + G * (2 * jnp.cos(a) + jnp.cos(b))
    )


PENDULUM = lj.Lagrangian(pendulum)


def pendulum_field(t, y, args):
    return jnp.concatenate([y[2:], PENDULUM.acceleration(y[:2], y[2:], t, args)])


def test_double_pendulum_runs_as_before_with_fewer_terms():
    """The double pendulum's translation: 41 terms instead of 49 (heyoka's own
    `lagrangian` has 49), and its run within rounding of the unfolded one and of
    heyoka's own equations."""
    folded, unfolded = both_translations(pendulum_field, 4)
    y0 = np.array([0.5, 0.3, 0.0, 0.0])
    runs = [
        hy.taylor_adaptive(list(s.equations), y0, tol=1e-15, compact_mode=False)
        for s in (folded, unfolded)
    ]
    assert len(runs[0].decomposition) < len(runs[1].decomposition)
    a, b, u, v = hy.make_vars("a", "b", "u", "v")
    lagrangian = u**2 + 0.5 * v**2 + u * v * hy.cos(a - b)
    lagrangian += G * (2 * hy.cos(a) + hy.cos(b))
    native = hy.taylor_adaptive(
        hy.lagrangian(lagrangian, [a, b], [u, v]), y0, tol=1e-15
    )
    for ta in (*runs, native):
        ta.propagate_until(5.0)
    np.testing.assert_allclose(runs[0].state, runs[1].state, rtol=0, atol=1e-14)
    np.testing.assert_allclose(runs[0].state, native.state, rtol=0, atol=1e-13)


def aligned(q, qd, t, args):
    """Two rods whose mass matrix [[1, cos(a - b)], [cos(a - b), 1]] is singular
    where a = b."""
    (a, b), (u, v) = (q[0], q[1]), (qd[0], qd[1])
    return 0.5 * u**2 + 0.5 * v**2 + u * v * jnp.cos(a - b) + jnp.cos(a)


ALIGNED = lj.Lagrangian(aligned)


def aligned_field(t, y, args):
    return jnp.concatenate([y[2:], ALIGNED.acceleration(y[:2], y[2:], t, args)])


def test_singular_mass_matrix_still_stops_the_run():
    """The unrolled solve's guard survives the folding: at a singular mass
    matrix the field is NaN and heyoka stops as non-finite, with no number."""
    folded, _ = both_translations(aligned_field, 4)
    values = compiled(folded)(
        np.array([[0.3, 0.7], [0.3, 0.1], [0.1, 0.1], [0.0, 0.0]])
    )
    assert np.isnan(values[2:, 0]).all() and np.isfinite(values[:, 1]).all()
    with pytest.raises(FloatingPointError, match="singular mass matrix"):
        heyoka_integrate(aligned_field, np.array([0.3, 0.3, 0.1, 0.0]), 0.0, 1.0)
    stopped = heyoka_integrate(aligned_field, np.array([0.3, 0.3, 0.1, 0.0]), 0.0,
                               1.0, throw=False)  # fmt: skip
    assert stopped.status == "err_nf_state" and np.isnan(stopped.ys).all()
