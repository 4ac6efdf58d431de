"""Refuse a system whose equations depend on time explicitly.

The phase-space tools (Lyapunov spectra, MEGNO, sections) run every interval of
their flow from t = 0 (`lagjax.phase_space.flow`), so a driven system — the
Mathieu equation, a forced pendulum — would restart its drive at every interval:
the Lyapunov exponent of the Mathieu equation came out 0.0037 where Floquet theory
gives 0.0995. Whether the equations depend on t is checked once, before the tools
run: the rate of the state at the start, and at a point beside it (a start at
rest on an equilibrium hides a drive that multiplies q), compared across a few
times. Equal rates at all of them mean autonomous, to round-off.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.core import Tracer
from jax.flatten_util import ravel_pytree

# Times that share no period with common drives (2π, π, 1, 1/2, …).
_PROBE_TIMES = (0.0, 0.731, 2.093, -1.377)
# Rates that differ by less than this, relative to their size, are equal.
_RELATIVE_CHANGE = 1e-10


@eqx.filter_jit
def _rate_changes(system: Any, y0: Any, args: Any) -> tuple[jax.Array, jax.Array]:
    flat, unravel = ravel_pytree(y0)
    flat = jnp.asarray(flat, dtype=jnp.result_type(flat, float))
    direction = 1.0 - 0.37 * jnp.arange(flat.size, dtype=flat.dtype) / flat.size
    beside = flat + 0.1 * (1.0 + jnp.max(jnp.abs(flat))) * direction

    def rate(y, t):
        return ravel_pytree(system.state_rate(*unravel(y), t, args))[0]

    times = jnp.asarray(_PROBE_TIMES, flat.dtype)
    rates = jnp.stack(
        [jax.vmap(lambda t, y=y: rate(y, t))(times) for y in (flat, beside)]
    )
    change = jnp.max(jnp.abs(rates - rates[:, :1]))
    return change, jnp.max(jnp.abs(rates))


def _traced(tree: Any) -> bool:
    return any(isinstance(x, Tracer) for x in jax.tree_util.tree_leaves(tree))


def refuse_time_dependence(system: Any, y0: Any, args: Any) -> None:
    """Raise when `system`'s equations of motion depend on t explicitly."""
    if not jax.tree_util.tree_leaves(y0) or _traced(args) or _traced(system):
        return
    if _traced(y0):  # under vmap: probe at rest, and beside it
        y0 = jax.tree_util.tree_map(lambda x: np.zeros(x.shape, x.dtype), y0)
    measured = _rate_changes(system, y0, args)
    if _traced(measured):  # inside the caller's own jit: nothing concrete to judge
        return
    change, size = (np.asarray(v) for v in measured)
    if not (np.isfinite(change) and change > _RELATIVE_CHANGE * size):
        return
    raise ValueError(
        "The phase-space tools (Lyapunov exponents, MEGNO, sections) need an "
        "autonomous system, but these equations of motion depend "
        "on t explicitly (the rate at y0 changes between t = 0 and t = "
        f"{', '.join(str(t) for t in _PROBE_TIMES[1:])}): the flow here restarts "
        "every interval at t = 0, so a drive would restart too and the result would "
        "be wrong. Write the system in extended phase space instead: the drive's "
        "phase θ = ωt as one more coordinate, with θ̇ = ω."
    )
