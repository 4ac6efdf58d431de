"""Translations and compiled heyoka integrators, kept for reuse.

Translating a vector field's jaxpr into heyoka's expressions costs milliseconds
to seconds, and compiling the integrator with LLVM seconds more (tens for an
8-link chain): both are kept, least recently used dropped, so a new `y0`, time
span or `args` reuses them.

- A translation is keyed by the function and the signature of `args` (like
  `jax.jit`, a function is traced once per signature: a changed closure is not
  seen; pass what changes in `args`).
- An integrator is keyed by the equations — the same expression objects, or
  those read from the same jaxpr (a function traced anew to the same jaxpr
  reuses the compilation; `heyoka_expressions._Equations`, which never compares
  by heyoka's `==`) —, the tolerance, the batch width, the precision, compact
  mode and the terminal events it watches.

References: F. Biscani & D. Izzo, "Revisiting high-order Taylor methods for
astrodynamics and celestial mechanics", MNRAS 504 (2021) 2614 (heyoka's compact
mode and batch mode).
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Hashable, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from lagjax.taylor.heyoka_expressions import (
    HeyokaSystem,
    import_heyoka,
    jaxpr_to_heyoka,
)

CACHE_SIZE = 32  # translations and compiled integrators kept, least recent dropped
# State dimension above which heyoka compiles in compact mode (loops over the
# operations instead of straight-line code). Measured, 4-link pendulum (dimension
# 8): straight-line 15 s to compile, 10 ms to run; compact 2.3 s and 24 ms.
COMPACT_ABOVE = 6


class _Caches:
    """Translations per function and signature; integrators per system."""

    def __init__(self) -> None:
        self.systems: OrderedDict[Hashable, HeyokaSystem] = OrderedDict()
        self.integrators: OrderedDict[Hashable, Any] = OrderedDict()
        self.translations = 0
        self.compilations = 0


_CACHES = _Caches()


def heyoka_cache_info() -> dict[str, int]:
    """How many translations and compilations this process has made so far."""
    return dict(translations=_CACHES.translations, compilations=_CACHES.compilations)


def translated(
    vector_field: Callable[[Any, Any, Any], Any], n: int, args: Any
) -> HeyokaSystem:
    """The translation of `vector_field`, cached per function and signature."""
    try:
        key = (vector_field, n, _signature(args))
        hash(key)
    except TypeError:
        key = None
    if key is not None and key in _CACHES.systems:
        _CACHES.systems.move_to_end(key)
        return _CACHES.systems[key]
    system = jaxpr_to_heyoka(vector_field, n, args)
    _CACHES.translations += 1
    if key is not None:
        _remember(_CACHES.systems, key, system)
    return system


def heyoka_integrator(
    system: HeyokaSystem,
    tol: float,
    width: int,
    fp_type: Any,
    compact_mode: bool | None,
    events: Sequence[Any] = (),
) -> Any:
    """A compiled heyoka integrator for `system` (scalar for `width` 1, batch
    mode otherwise), watching the terminal `events` (`HeyokaEvent`s)."""
    hy = import_heyoka()
    event_key = tuple((e.expression, e.direction) for e in events)
    key = (system.key, tol, width, np.dtype(fp_type).str, compact_mode, event_key)
    if key in _CACHES.integrators:
        _CACHES.integrators.move_to_end(key)
        return _CACHES.integrators[key]
    n = len(system.equations)
    compact = n > COMPACT_ABOVE if compact_mode is None else compact_mode
    options: dict[str, Any] = dict(
        tol=fp_type(tol), compact_mode=compact, fp_type=fp_type
    )
    event_type = hy.t_event if width == 1 else hy.t_event_batch
    if events:
        # Crossings are filtered by a callback, not by heyoka's `direction`: with
        # the condition zero at a step's start (a projectile launched from the
        # ground), heyoka 7.13 missed a later crossing in the same step when
        # asked for one direction only.
        options["t_events"] = [
            event_type(e.expression, callback=EventFilter(e.direction), fp_type=fp_type)
            for e in events
        ]
    # No `pars=`: heyoka sizes them itself (`used_pars`).
    if width == 1:
        ta = hy.taylor_adaptive(list(system.equations), np.zeros(n, fp_type), **options)
    else:
        ta = hy.taylor_adaptive_batch(
            list(system.equations), np.zeros((n, width), fp_type), **options
        )
    _CACHES.compilations += 1
    _remember(_CACHES.integrators, key, ta)
    return ta


class EventFilter:
    """A terminal event's callback: go on (True) through a crossing in the other
    direction than `wanted` (+1 upward, -1 downward, 0 either), and through a
    zero of the condition at the run's start (`starts`, per lane; set before
    each run), which ends no run, as in diffrax."""

    def __init__(self, wanted: int) -> None:
        self.wanted = wanted
        self.starts = np.zeros(1)

    def __call__(self, ta: Any, d_sgn: Any, *lane: int) -> bool:
        time = ta.time[lane[0]] if lane else ta.time
        at_start = time == self.starts[lane[0] if lane else 0]
        return bool(at_start) or (self.wanted != 0 and int(d_sgn) != self.wanted)


def _signature(args: Any) -> Hashable:
    leaves, treedef = jax.tree_util.tree_flatten(args)
    return treedef, tuple(
        (np.shape(x), np.dtype(jnp.result_type(x)).str) for x in leaves
    )


def _remember(cache: OrderedDict, key: Hashable, value: Any) -> None:
    cache[key] = value
    while len(cache) > CACHE_SIZE:
        cache.popitem(last=False)
