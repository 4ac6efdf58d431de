"""Is a function quadratic where the run goes? A cheap check of a declaration.

`quadratic_in_velocity=True` (a `Lagrangian`) and `quadratic_in_momentum=True` (a
Hamiltonian) make the Legendre transform one Newton step from zero, and let a
separable Hamiltonian take the Runge–Kutta–Nyström splittings. Declared wrongly —
a relativistic L or T — they change the physics without a word: the relativistic
particle then moves as a Newtonian one. So a declaration is verified once, before
the run, at the start state: the function is quadratic when its program proves it
(`is_at_most_quadratic`) or, failing a proof, when its Hessian is the same at the
start, at zero (where the one Newton step begins) and at probes around the start.
Probes outside the function's domain (non-finite Hessian) are skipped.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.core import Tracer
from jax.flatten_util import ravel_pytree

from lagjax.mechanics.legendre import jaxpr_degrees

# Hessians that differ by less than this, relative to the largest entry, are equal:
# an autodiff Hessian of a quadratic is exact to a few ulp; a relativistic one at
# v = c/100 already differs by 1.5e-4.
_RELATIVE_CHANGE = 1e-8
# Probe distances from the start, in units of the state's size (1 when it is 0).
_PROBE_SCALES = (1.0, 0.1, 0.01)


def _probe_points(x0: jax.Array) -> jax.Array:
    """Zero, and points around x0 along a direction with unequal components (so
    that no symmetry of the function hides a change of its Hessian)."""
    scale = jnp.where(jnp.any(x0 != 0), jnp.max(jnp.abs(x0)), 1.0)
    direction = 1.0 - 0.37 * jnp.arange(x0.size, dtype=x0.dtype) / max(x0.size, 1)
    steps = jnp.asarray(_PROBE_SCALES, x0.dtype)[:, None] * scale * direction
    return jnp.concatenate([jnp.zeros_like(x0)[None], x0 + steps])


@eqx.filter_jit
def _hessian_changes(function: Callable, x0: jax.Array) -> tuple[jax.Array, ...]:
    hessian = jax.hessian(function)
    at_start = hessian(x0)
    others = jax.vmap(hessian)(_probe_points(x0))
    change = jnp.max(jnp.abs(others - at_start), axis=(1, 2))
    finite = jnp.all(jnp.isfinite(others), axis=(1, 2))
    return change, finite, jnp.max(jnp.abs(at_start))


# Proofs already read off a program, by (the user's function, the shapes and dtypes
# of the call): reading a program is a trace (7 ms for the double pendulum's L),
# which a run repeated with new values should not pay again. Bounded in size.
_PROOFS: dict[Any, bool] = {}
_PROOFS_KEPT = 256


def _proven_quadratic(function: Callable, fixed: Any, x0: jax.Array, key: Any) -> bool:
    """Whether function(fixed, x) is provably quadratic in x (fixed: degree 0)."""
    signature = (
        jax.tree_util.tree_structure((fixed, x0)),
        tuple(
            (np.shape(leaf), jnp.result_type(leaf))
            for leaf in jax.tree_util.tree_leaves((fixed, x0))
        ),
    )
    cache_key: Any = (key, signature)
    try:
        hash(cache_key)
    except TypeError:  # an unhashable function: prove every time
        cache_key = None
    if cache_key in _PROOFS:
        return _PROOFS[cache_key]
    closed = jax.make_jaxpr(function)(fixed, x0)
    fixed_count = len(jax.tree_util.tree_leaves(fixed))
    degrees = [0] * fixed_count + [1] * (len(closed.jaxpr.invars) - fixed_count)
    (degree,) = jaxpr_degrees(closed.jaxpr, degrees)
    if cache_key is not None:
        if len(_PROOFS) >= _PROOFS_KEPT:
            _PROOFS.clear()
        _PROOFS[cache_key] = degree <= 2
    return degree <= 2


def is_quadratic_near(
    function: Callable[[Any, Any], jax.Array], fixed: Any, x0: Any, key: Any = None
) -> bool:
    """Whether `function(fixed, x)` is quadratic in x (a pytree like the concrete
    `x0`): proven from its program, or a Hessian unchanged from x0 to zero and the
    probes. `key` (the user's function) lets a proof be reused."""
    flat0, unravel = ravel_pytree(x0)
    flat0 = jnp.asarray(flat0, dtype=jnp.result_type(flat0, float))
    if flat0.size == 0:
        return True

    def flat_function(fixed_, x):
        return function(fixed_, unravel(x))

    if _proven_quadratic(flat_function, fixed, flat0, key):
        return True
    change, finite, size = (
        np.asarray(v)
        for v in _hessian_changes(lambda x: flat_function(fixed, x), flat0)
    )
    if not np.isfinite(size):
        return True  # nothing to compare with at the start: the run will say
    return bool(np.all(~finite | (change <= _RELATIVE_CHANGE * size)))


def check_declared_quadratic(
    function: Callable[[Any, Any], jax.Array],
    fixed: Any,
    x0: Any,
    *,
    key: Any,
    flag: str,
    what: str,
) -> None:
    """Refuse a `flag=True` declaration that `function(fixed, x)` (`what`, as a
    function of x) contradicts.

    `fixed` (the other arguments) and `x0` are the concrete start values; traced
    values are not checked (a compiled caller checks before its trace).
    """
    leaves = jax.tree_util.tree_leaves((fixed, x0))
    if any(isinstance(leaf, Tracer) for leaf in leaves):
        return
    if is_quadratic_near(function, fixed, x0, key):
        return
    raise ValueError(
        f"{flag}=True was declared, but {what} is not quadratic: its Hessian "
        "changes between the start state, zero and nearby points (a relativistic "
        "or otherwise non-polynomial kinetic term). The declaration would replace "
        f"the Legendre transform by one linear solve and give the wrong motion. "
        f"Drop {flag}=True (the default detects a quadratic function itself)."
    )
