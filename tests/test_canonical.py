"""Canonical maps: the symplectic test and maps from the four kinds of generator,
checked against closed forms (Goldstein §9.1–9.4; the course text §6.4)."""

import jax
import jax.numpy as jnp
import pytest

from lagjax.mechanics.canonical import GeneratingFunction, is_canonical
from tests.helpers import tree_allclose

MASS, OMEGA = 1.3, 0.7


def oscillator_hamiltonian(q, p):
    return jnp.sum(p**2 / (2 * MASS) + MASS * OMEGA**2 * q**2 / 2)


def action_angle_generator(q, Q):
    """F1 = Σ mω q²/2 · cot Q (course text eq. 6.39)."""
    return jnp.sum(MASS * OMEGA * q**2 / (2 * jnp.tan(Q)))


# Angles in both quadrants where sin Q > 0, actions of different sizes.
ANGLES = jnp.array([0.3, 0.9, 1.4, 2.0, 2.8])
ACTIONS = jnp.array([0.5, 1.0, 2.0, 0.2, 3.0])


def test_action_angle_map_of_the_oscillator():
    action_angle = GeneratingFunction(action_angle_generator, kind=1)
    # K = ω P for each oscillator separately: vmap over the points, one at a time.
    new_hamiltonian = jax.vmap(
        action_angle.transformed_hamiltonian(oscillator_hamiltonian)
    )

    # One jitted function: compiling beats running the root-finds op by op.
    @jax.jit
    def round_trip(angles, actions):
        q, p = action_angle.inverse(angles, actions)
        canonical = is_canonical(action_angle.forward, q, p)
        return (
            q,
            p,
            action_angle.forward(q, p),
            canonical,
            new_hamiltonian(angles, actions),
        )

    q, p, new, canonical, energies = round_trip(ANGLES, ACTIONS)
    # Course text eq. 6.40–6.41.
    assert tree_allclose(q, jnp.sqrt(2 * ACTIONS / (MASS * OMEGA)) * jnp.sin(ANGLES))
    assert tree_allclose(p, jnp.sqrt(2 * ACTIONS * MASS * OMEGA) * jnp.cos(ANGLES))
    assert tree_allclose(new, (ANGLES, ACTIONS))
    assert bool(canonical)
    assert tree_allclose(energies, OMEGA * ACTIONS)


def test_forward_guess_selects_the_branch():
    # p = mωq cot Q fixes Q only modulo π; a guess near Q + π finds that root.
    action_angle = GeneratingFunction(action_angle_generator, kind=1)
    q = jnp.sqrt(2 * ACTIONS / (MASS * OMEGA)) * jnp.sin(ANGLES)
    p = jnp.sqrt(2 * ACTIONS * MASS * OMEGA) * jnp.cos(ANGLES)
    forward = jax.jit(action_angle.forward)
    shifted, actions = forward(q, p, guess=ANGLES + jnp.pi + 0.1)
    assert tree_allclose(shifted, ANGLES + jnp.pi)
    assert tree_allclose(actions, ACTIONS)


Q0 = jnp.array([0.4, -1.1, 0.8])
P0 = jnp.array([-0.6, 0.3, 1.2])


def _sum_of_products(x, y):
    return jnp.sum(x * y)


@pytest.mark.parametrize(
    ("generator", "kind", "closed_form"),
    [
        # F2 = Σ q P: the identity.
        (_sum_of_products, 2, lambda q, p: (q, p)),
        # F1 = Σ q Q: exchanges coordinates and momenta, Q = p, P = −q.
        (_sum_of_products, 1, lambda q, p: (p, -q)),
        # F3 = −Σ p sinh Q: the point map q = sinh Q, with P = p cosh Q.
        (
            lambda p, Q: -jnp.sum(p * jnp.sinh(Q)),
            3,
            lambda q, p: (jnp.arcsinh(q), p * jnp.sqrt(1 + q**2)),
        ),
        # F4 = −Σ p sinh P: q = sinh P and Q = −p cosh P.
        (
            lambda p, P: -jnp.sum(p * jnp.sinh(P)),
            4,
            lambda q, p: (-p * jnp.sqrt(1 + q**2), jnp.arcsinh(q)),
        ),
    ],
    ids=["F2-identity", "F1-exchange", "F3-point-map", "F4-momentum-map"],
)
def test_generated_maps_match_closed_forms(generator, kind, closed_form):
    transform = GeneratingFunction(generator, kind=kind)

    @jax.jit
    def round_trip(q, p):
        new = transform.forward(q, p)
        forward_ok = is_canonical(transform.forward, q, p)
        return (
            new,
            transform.inverse(*new),
            forward_ok,
            is_canonical(transform.inverse, *new),
        )

    new, old, forward_is_canonical, inverse_is_canonical = round_trip(Q0, P0)
    assert tree_allclose(new, closed_form(Q0, P0))
    assert tree_allclose(old, (Q0, P0))
    assert bool(forward_is_canonical)
    assert bool(inverse_is_canonical)


def test_time_dependent_generator_adds_partial_t():
    # Galilean boost F2 = (q − v t)·P + m v·q: Q = q − v t, P = p − m v, and for a
    # free particle K = H − v·P = P²/2m + m v²/2.
    def boost(q, P, t, velocity):
        return jnp.sum((q - velocity * t) * P + MASS * velocity * q)

    def free_particle(q, p):
        return jnp.sum(p**2) / (2 * MASS)

    velocity, t = jnp.array([0.5, -0.2, 1.0]), 0.8
    transform = GeneratingFunction(boost, kind=2)
    K = transform.transformed_hamiltonian(free_particle)

    @jax.jit
    def boosted(q, p, t, velocity):
        Q, P = transform.forward(q, p, t, velocity)
        canonical = is_canonical(transform.forward, q, p, t, velocity)
        return Q, P, K(Q, P, t, velocity), canonical

    Q, P, energy, canonical = boosted(Q0, P0, t, velocity)
    assert tree_allclose((Q, P), (Q0 - velocity * t, P0 - MASS * velocity))
    expected = jnp.sum(P**2) / (2 * MASS) + MASS * jnp.sum(velocity**2) / 2
    assert tree_allclose(energy, expected)
    assert bool(canonical)


def test_pytree_variables():
    q = {"x": jnp.array([0.4, -1.1]), "y": jnp.array(0.8)}
    p = {"x": jnp.array([-0.6, 0.3]), "y": jnp.array(1.2)}

    def tree_dot(a, b):
        leaves = jax.tree_util.tree_leaves(jax.tree_util.tree_map(jnp.vdot, a, b))
        return sum(leaves)

    exchange = GeneratingFunction(tree_dot, kind=1)

    @jax.jit
    def round_trip(q, p):  # one compilation for both directions
        new = exchange.forward(q, p)
        return new, exchange.inverse(*new)

    (Q, P), old = round_trip(q, p)
    assert tree_allclose((Q, P), (p, jax.tree_util.tree_map(jnp.negative, q)))
    assert tree_allclose(old, (q, p))


def test_is_canonical_rejects_a_scaling_of_q_only():
    def stretch_q(q, p):
        return 2.0 * q, p

    # Jitted: one compilation instead of dozens of op-by-op dispatches.
    assert not bool(jax.jit(lambda q, p: is_canonical(stretch_q, q, p))(Q0, P0))


def test_is_canonical_is_relative_to_the_jacobian_scale():
    # A strong shear followed by a rotation: det = 1 exactly, but Mᵀ J M carries
    # round-off of order ε·shear² (about 3e-5 here), far above an absolute 1e-10.
    shear = 1e6

    def sheared_rotation(q, p, t):
        sheared_p = p + shear * q
        c, s = jnp.cos(t), jnp.sin(t)
        return c * q + s * sheared_p, -s * q + c * sheared_p

    # One compilation for a scalar point and a vmapped batch of them.
    @jax.jit
    def single_and_batched(q, p, qs, ps, t):
        batched = jax.vmap(is_canonical, in_axes=(None, 0, 0, None))
        return (
            is_canonical(sheared_rotation, q, p, t),
            batched(sheared_rotation, qs, ps, t),
        )

    single, batch = single_and_batched(jnp.array(0.4), jnp.array(0.2), Q0, P0, 0.3)
    assert bool(single)
    assert bool(jnp.all(batch))


@pytest.mark.parametrize("kind", [0, 5, "1", 1.5])
def test_bad_kind_raises(kind):
    with pytest.raises(ValueError, match="kind must be 1, 2, 3 or 4"):
        GeneratingFunction(_sum_of_products, kind=kind)
