"""Comparison helpers shared by the tests."""

import contextlib
import math

import jax
import jax.numpy as jnp
import numpy as np


def tree_allclose(x, y, *, rtol=1e-10, atol=1e-10) -> bool:
    """True when two pytrees have the same structure and all leaves are close."""
    x_leaves, x_def = jax.tree_util.tree_flatten(x)
    y_leaves, y_def = jax.tree_util.tree_flatten(y)
    if x_def != y_def:
        return False
    return all(
        jnp.shape(a) == jnp.shape(b) and np.allclose(a, b, rtol=rtol, atol=atol)
        for a, b in zip(x_leaves, y_leaves)
    )


def relative_close(actual, expected, rtol: float) -> bool:
    """max|actual − expected| ≤ rtol · max|expected|: relative to the quantity's scale.

    Unlike `np.allclose(..., rtol=...)`, no default absolute tolerance (1e-8) can
    hide a failure of a tight relative bound, and components that are zero in the
    closed form do not demand an impossible elementwise relative accuracy.
    """
    actual, expected = np.asarray(actual), np.asarray(expected)
    scale = max(float(np.max(np.abs(expected))), np.finfo(float).tiny)
    return float(np.max(np.abs(actual - expected))) <= rtol * scale


def assert_singular_verdicts(lagrangian, q, qdot, match: str) -> None:
    """The default contract of `acceleration` at a state where it is undefined: an
    error on values, NaN under `jit` (no branch in a fused step), and an error
    under `jit` with check=True."""
    import pytest

    with pytest.raises(Exception, match=match):
        jax.block_until_ready(lagrangian.acceleration(q, qdot))
    traced = jax.jit(lagrangian.acceleration)(q, qdot)
    assert bool(jnp.all(jnp.isnan(traced)))
    checked = jax.jit(lambda a, b: lagrangian.acceleration(a, b, check=True))
    with pytest.raises(Exception, match=match):
        jax.block_until_ready(checked(q, qdot))


@contextlib.contextmanager
def counted_compilations():
    """A list that receives one entry per XLA compilation inside the block."""
    compiled = []

    def listener(name, seconds, **kwargs):
        if "backend_compile" in name:
            compiled.append(name)

    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        yield compiled
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)


def one_error_line(capsys) -> str:
    """The command's one-line error (no traceback) from pytest's captured stderr."""
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    return lines[0]


def lie_coefficients(f, y0, order):
    """Taylor coefficients yₖ = (L_f)ᵏ y / k! of y' = f(y) at y0, by nested
    `jax.jvp` (autonomous f): the reference the recurrences are checked against."""
    derivative = lambda y: y
    coefficients = [y0]
    for k in range(1, order + 1):
        derivative = (lambda g: lambda y: jax.jvp(g, (y,), (f(y),))[1])(derivative)
        coefficients.append(derivative(y0) / math.factorial(k))
    return jnp.stack(coefficients)
