"""Poisson brackets: the canonical and angular-momentum algebras, the Lie-algebra
identities on random polynomials, and dF/dt = {F, H} + ∂F/∂t along a trajectory."""

import itertools

import diffrax
import hypothesis.extra.numpy as hnp
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from jax.flatten_util import ravel_pytree

from lagjax.mechanics.brackets import poisson_bracket
from tests.helpers import tree_allclose

LEVI_CIVITA = np.zeros((3, 3, 3))
for _i, _j, _k in itertools.permutations(range(3)):
    LEVI_CIVITA[_i, _j, _k] = np.linalg.det(np.eye(3)[[_i, _j, _k]])

Q0 = jnp.array([0.3, -1.2, 0.7])
P0 = jnp.array([1.1, 0.4, -0.5])


def angular_momentum(q, p):
    return jnp.cross(q, p)


def position(q, p):
    return q


def momentum(q, p):
    return p


def test_canonical_brackets():
    assert tree_allclose(poisson_bracket(position, momentum)(Q0, P0), jnp.eye(3))
    assert tree_allclose(poisson_bracket(momentum, position)(Q0, P0), -jnp.eye(3))
    assert tree_allclose(poisson_bracket(position, position)(Q0, P0), jnp.zeros((3, 3)))
    assert tree_allclose(poisson_bracket(momentum, momentum)(Q0, P0), jnp.zeros((3, 3)))


@pytest.mark.parametrize(
    ("partner", "closed_form"),
    [
        (angular_momentum, angular_momentum),  # [L_i, L_j] = ε_ijk L_k
        (position, position),  # [L_i, q_j] = ε_ijk q_k
        (momentum, momentum),  # [L_i, p_j] = ε_ijk p_k
    ],
)
def test_angular_momentum_algebra(partner, closed_form):
    bracket = poisson_bracket(angular_momentum, partner)(Q0, P0)
    expected = jnp.einsum("ijk,k->ij", LEVI_CIVITA, closed_form(Q0, P0))
    assert bracket.shape == (3, 3)
    assert tree_allclose(bracket, expected, rtol=1e-12, atol=1e-12)


def test_angular_momentum_commutes_with_central_hamiltonian():
    mass, stiffness = 1.7, 0.3

    def central(q, p):
        r = jnp.linalg.norm(q)
        return p @ p / (2 * mass) - 1 / r + stiffness * r**4

    def anisotropic(q, p):
        return central(q, p) + stiffness * q[0] ** 2

    def l_z(q, p):
        return angular_momentum(q, p)[2]

    assert tree_allclose(poisson_bracket(l_z, central)(Q0, P0), 0.0, atol=1e-12)
    # A potential c·x² breaks the symmetry: {L_z, c x²} = 2 c x y.
    expected = 2 * stiffness * Q0[0] * Q0[1]
    assert tree_allclose(poisson_bracket(l_z, anisotropic)(Q0, P0), expected)


# Random polynomials of degree ≤ 3 in z = (q1, q2, p1, p2): monomials w_a w_b w_c
# with w = (1, z) and a ≤ b ≤ c, so coefficients alone pick the polynomial and one
# compiled function serves every hypothesis example.
_MONOMIALS = np.array(list(itertools.combinations_with_replacement(range(5), 3)))


def _polynomial(coefficients, q, p):
    w = jnp.concatenate([jnp.ones(1), q, p])
    return coefficients @ (
        w[_MONOMIALS[:, 0]] * w[_MONOMIALS[:, 1]] * w[_MONOMIALS[:, 2]]
    )


def _f(q, p, t, args):
    return _polynomial(args[0], q, p)


def _g(q, p, t, args):
    return _polynomial(args[1], q, p)


def _h(q, p, t, args):
    return _polynomial(args[2], q, p)


def _g_times_h(q, p, t, args):
    return _g(q, p, t, args) * _h(q, p, t, args)


def _bracket_products(F, G):
    """Σ_i |∂F/∂q_i ∂G/∂p_i| + |∂F/∂p_i ∂G/∂q_i|: the size of the products that the
    bracket {F, G} adds and cancels, the scale of its round-off."""

    def products(q, p, t, args):
        def gradient(fn):
            return jax.grad(fn, argnums=(0, 1))(q, p, t, args)

        (f_q, f_p), (g_q, g_p) = gradient(F), gradient(G)
        return jnp.sum(jnp.abs(f_q * g_p)) + jnp.sum(jnp.abs(f_p * g_q))

    return products


@jax.jit
def _bracket_identities(coefficients, z):
    q, p, t = z[:2], z[2:], 0.0

    def at(fn):
        return fn(q, p, t, coefficients)

    fg, gf = at(poisson_bracket(_f, _g)), at(poisson_bracket(_g, _f))
    jacobi_terms = jnp.stack(
        [
            at(poisson_bracket(_f, poisson_bracket(_g, _h))),
            at(poisson_bracket(_g, poisson_bracket(_h, _f))),
            at(poisson_bracket(_h, poisson_bracket(_f, _g))),
        ]
    )
    leibniz_lhs = at(poisson_bracket(_f, _g_times_h))
    leibniz_terms = jnp.stack([fg * at(_h), at(_g) * at(poisson_bracket(_f, _h))])
    # {f, gh} and g{f, h} + h{f, g} each cancel products of first derivatives; the
    # larger of the two sums of those products is the scale both sides are exact to.
    leibniz_scale = jnp.maximum(
        at(_bracket_products(_f, _g_times_h)),
        jnp.abs(at(_h)) * at(_bracket_products(_f, _g))
        + jnp.abs(at(_g)) * at(_bracket_products(_f, _h)),
    )
    return fg, gf, jacobi_terms, leibniz_lhs, leibniz_terms, leibniz_scale


_unit_floats = st.floats(-1.0, 1.0, allow_nan=False, allow_subnormal=False)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
@settings(max_examples=25, deadline=None)
@example(  # f = g = h: both sides of the Leibniz rule are cancellations to 0
    coefficients=np.full((3, len(_MONOMIALS)), 0.96875), z=np.full(4, 0.984375)
)
@given(
    coefficients=hnp.arrays(np.float64, (3, len(_MONOMIALS)), elements=_unit_floats),
    z=hnp.arrays(np.float64, (4,), elements=_unit_floats),
)
def test_antisymmetry_jacobi_and_leibniz(coefficients, z):
    fg, gf, jacobi_terms, leibniz_lhs, leibniz_terms, leibniz_scale = (
        _bracket_identities(coefficients, z)
    )
    # Round-off scales with the size of the terms that cancel. For the Jacobi
    # identity those are its three nested brackets. For the Leibniz rule they are the
    # products of first derivatives inside each bracket: with f = g = h, both sides
    # are 0 analytically while {f, f²} cancels products of size ~10⁴ (1.8e-12 left
    # over was seen), so the outer terms alone (0 there) are no scale. The derivatives
    # themselves cancel inside each polynomial, so the error reaches a few ulp of that
    # scale (at most 4e-15 of it over 9000 random cases); 2e-14 leaves room, and is
    # tighter than the old 1e-12 of the outer terms unless the products exceed those
    # 50-fold (their median ratio is 2.2).
    jacobi_scale = 1.0 + float(jnp.max(jnp.abs(jacobi_terms)))
    assert abs(float(fg + gf)) <= 1e-12 * (1.0 + abs(float(fg)))
    assert abs(float(jnp.sum(jacobi_terms))) <= 1e-12 * jacobi_scale
    leibniz_rhs = float(jnp.sum(leibniz_terms))
    assert abs(float(leibniz_lhs) - leibniz_rhs) <= 2e-14 * (1.0 + float(leibniz_scale))


# A driven oscillator H = p²/2m + k q²/2 − f q cos Ωt and a time-dependent observable.
MASS, STIFFNESS, DRIVE, DRIVE_FREQUENCY = 1.3, 2.0, 0.8, 1.7


def driven_hamiltonian(q, p, t):
    drive = DRIVE * q * jnp.cos(DRIVE_FREQUENCY * t)
    return p**2 / (2 * MASS) + STIFFNESS * q**2 / 2 - drive


def observable(q, p, t):
    return q**3 * p + jnp.sin(t) * q * p**2


def hand_written_field(t, q, p):
    """Hamilton's equations of the driven oscillator, written out by hand."""
    force = -STIFFNESS * q + DRIVE * jnp.cos(DRIVE_FREQUENCY * t)
    return p / MASS, force


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_time_derivative_along_trajectory_is_bracket_plus_partial_t():
    bracket_with_h = poisson_bracket(observable, driven_hamiltonian)
    partial_t = jax.grad(observable, argnums=2)

    def rate(q, p, t):
        return bracket_with_h(q, p, t) + partial_t(q, p, t)

    # Integrate the state together with ∫ ({F, H} + ∂F/∂t) dt; the integral must
    # equal F(y(t), t) − F(y(0), 0).
    def field(t, state, args):
        q, p, _ = state
        dq, dp = hand_written_field(t, q, p)
        return dq, dp, rate(q, p, t)

    ts = jnp.linspace(0.0, 4.0, 9)
    q0, p0 = jnp.array(0.7), jnp.array(-0.4)
    solution = diffrax.diffeqsolve(
        diffrax.ODETerm(field),
        diffrax.Dopri8(),
        t0=0.0,
        t1=4.0,
        dt0=0.01,
        y0=(q0, p0, jnp.array(0.0)),
        saveat=diffrax.SaveAt(ts=ts),
        stepsize_controller=diffrax.PIDController(rtol=1e-12, atol=1e-12),
        max_steps=100_000,
    )
    qs, ps, integrals = solution.ys  # pyright: ignore
    change = jax.vmap(observable)(qs, ps, ts) - observable(q0, p0, 0.0)
    assert float(jnp.max(jnp.abs(change))) > 0.1  # the observable does evolve
    assert tree_allclose(integrals, change, rtol=1e-9, atol=1e-9)

    # Pointwise: the chain rule along the hand-written flow, dF/dt = ∇F·ẏ + ∂F/∂t.
    def chain_rule(q, p, t):
        velocity = (*hand_written_field(t, q, p), jnp.ones_like(t))
        return jax.jvp(observable, (q, p, t), velocity)[1]

    assert tree_allclose(
        jax.vmap(rate)(qs, ps, ts), jax.vmap(chain_rule)(qs, ps, ts), rtol=1e-12
    )


def test_time_and_args_are_passed_through():
    def f(q, p, t):
        return t * (q @ p)

    def g(q, p, t, args):
        return args * (q @ q)

    # {t q·p, a |q|²} = −(t q)·(2 a q) = −2 a t |q|².
    value = poisson_bracket(f, g)(Q0, P0, 0.6, 1.5)
    assert tree_allclose(value, -2 * 1.5 * 0.6 * (Q0 @ Q0))


def test_pytree_coordinates_match_flat_coordinates():
    q = {"r": jnp.array([0.4, -0.9]), "z": jnp.array(1.3)}
    p = {"r": jnp.array([0.2, 0.5]), "z": jnp.array(-0.7)}
    z, unravel = ravel_pytree((q, p))

    def f_tree(q, p):
        return jnp.stack([q["r"][0] * p["z"] ** 2, jnp.sin(q["z"]) * p["r"][1]])

    def g_tree(q, p):
        return q["z"] * q["r"][1] * p["r"][0] + p["z"] ** 3

    def flat(fn):
        return lambda q_flat, p_flat: fn(*unravel(jnp.concatenate([q_flat, p_flat])))

    tree_value = poisson_bracket(f_tree, g_tree)(q, p)
    flat_value = poisson_bracket(flat(f_tree), flat(g_tree))(z[:3], z[3:])
    assert tree_value.shape == (2,)
    assert tree_allclose(tree_value, flat_value, rtol=1e-13, atol=1e-13)

    def q_flat(q, p):
        return ravel_pytree(q)[0]

    def p_flat(q, p):
        return ravel_pytree(p)[0]

    assert tree_allclose(poisson_bracket(q_flat, p_flat)(q, p), jnp.eye(3))


def test_jit_and_vmap_over_points():
    key_q, key_p = jax.random.split(jax.random.key(0))
    qs = jax.random.normal(key_q, (5, 3))
    ps = jax.random.normal(key_p, (5, 3))
    batched = jax.jit(jax.vmap(poisson_bracket(angular_momentum, angular_momentum)))
    expected = jnp.einsum("ijk,nk->nij", LEVI_CIVITA, jnp.cross(qs, ps))
    assert tree_allclose(batched(qs, ps), expected, rtol=1e-12, atol=1e-12)


def test_bad_inputs_raise():
    with pytest.raises(TypeError, match="at least 2 positional"):
        poisson_bracket(lambda q: q, position)
    with pytest.raises(ValueError, match="same pytree structure"):
        poisson_bracket(position, momentum)({"a": Q0}, P0)
    with pytest.raises(TypeError, match="single array"):
        poisson_bracket(lambda q, p: (q, p), momentum)(Q0, P0)
