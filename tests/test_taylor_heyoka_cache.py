"""The heyoka backend's integrator cache compares translated equations by the
jaxpr they were read from, never by heyoka's `==` (a tree walk of a graph)."""

import jax.numpy as jnp
import numpy as np
import pytest

pytest.importorskip("heyoka")

from lagjax.taylor.heyoka_cache import heyoka_cache_info, heyoka_integrator
from lagjax.taylor.heyoka_expressions import _Equations, jaxpr_to_heyoka


def nested(levels: int, scale):
    """x ↦ x·x + x, `levels` times: a graph of 2·levels operations whose tree
    has 2^levels leaves (a pendulum chain's equations share their terms alike)."""

    def field(t, y, args):
        x = y[0]
        for _ in range(levels):
            x = x * x + x
        return jnp.stack([y[1], jnp.reshape(scale * x, ())])

    return field


def test_equal_jaxprs_share_a_compilation_without_a_tree_walk():
    first = jaxpr_to_heyoka(nested(40, jnp.asarray([0.5])[0]), 2)
    again = jaxpr_to_heyoka(nested(40, jnp.asarray([0.5])[0]), 2)  # traced anew
    assert all(a is not b for a, b in zip(first.key.rhs, again.key.rhs))
    assert first.key == again.key and hash(first.key) == hash(again.key)
    before = heyoka_cache_info()["compilations"]
    ta = heyoka_integrator(first, 1e-9, 1, np.float64, False)
    assert heyoka_integrator(again, 1e-9, 1, np.float64, False) is ta
    assert heyoka_cache_info()["compilations"] == before + 1


class _NoEquality:
    """An expression whose `==` must not be called (heyoka's walks 2^levels paths)."""

    def __hash__(self) -> int:
        return 0

    def __eq__(self, other: object) -> bool:
        raise AssertionError("the cache compared expressions with ==")


def test_keys_are_equal_by_digest_without_comparing_expressions():
    """Equal digests decide equality; the expressions' own `==` is never called
    (it would walk the 2^40 paths of `nested(40)`: a run that never returns)."""
    first, again = (_Equations((_NoEquality(),), 0, "digest") for _ in range(2))
    assert first == again and hash(first) == hash(again)
    other = _Equations((_NoEquality(),), 0, "another digest")
    assert first != other
    assert _Equations((_NoEquality(),), 1, "digest") != first  # other parameters


def test_other_constants_are_other_equations():
    """The same jaxpr text with another constant array is another system (the
    digest reads the constants' bytes)."""
    half = jaxpr_to_heyoka(nested(3, np.array([0.5])), 2)
    third = jaxpr_to_heyoka(nested(3, np.array([1 / 3])), 2)
    assert half.source != third.source and half.key != third.key
    y = np.array([0.2, 0.1])
    values = [heyoka_integrator(s, 1e-9, 1, np.float64, False) for s in (half, third)]
    assert values[0] is not values[1]
    for ta in values:
        ta.time, ta.state[:] = 0.0, y
        ta.step()
    assert not np.array_equal(values[0].state, values[1].state)
