"""heyoka runs inside JAX programs: `jax.pure_callback`, batched by heyoka.

heyoka is compiled C++ on NumPy values. Under `jax.jit` and `jax.vmap` a run is
staged as a `jax.pure_callback` whose `vmap_method="broadcast_all"` hands the
callback the whole batch at once — every input with the batch's leading axes
(unbatched ones tiled) — so `jax.vmap(simulate)` over `y0`, `args`, `t0`, `t1`
or `ts` becomes ONE call of heyoka's batch mode (`heyoka_runs.HeyokaRunner`:
blocks of the SIMD width, each member with its own steps), not a loop of single
runs. Nested `vmap`s flatten into one batch. Concrete inputs skip JAX and call
the runner directly (no dispatch on the fast CPU route); both paths run the
same `HeyokaRunner`.

What a callback cannot do is refused by name: heyoka's runs carry no
derivatives, so `jax.grad`, `jax.jvp` and `jax.jacfwd` through them raise a
`TypeError` naming the JAX-native route (`lj.Taylor(backend="jax")`) instead of
JAX's generic "pure_callback does not support JVP". A callback cannot raise
either (JAX's contract), so failures come back as outcome codes that the caller
turns into `diffrax.RESULTS` and, with `throw=True`, an `eqx.error_if`.

References: the JAX documentation, "External callbacks" (`jax.pure_callback`,
`vmap_method`); F. Biscani & D. Izzo, MNRAS 504 (2021) 2614 (heyoka's batch
mode).
"""

from __future__ import annotations

import functools
from typing import Any

import jax
import numpy as np
from jax.core import Tracer

from lagjax.taylor.heyoka_runs import HeyokaRunner, Rows

GRADIENT_REFUSAL = (
    "lj.Taylor(backend='heyoka') cannot be differentiated: heyoka's runs are "
    "compiled C++ outside JAX and carry no derivatives, so jax.grad, jax.jvp and "
    "jax.jacfwd cannot pass through them. Use lj.Taylor(backend='jax') (the same "
    "Taylor method in JAX, differentiable in both modes) or a diffrax solver."
)


def heyoka_member_run(
    runner: HeyokaRunner, y0: Any, pars: Any, t0: Any, t1: Any, ts: Any
) -> Rows:
    """One member's run — `y0` (n,), `pars` (P,), `t0`, `t1` scalars, `ts` (T,) —
    as `Rows` without the batch axis: `ts` (T,), `ys` (T, n), `num_steps` and
    `codes` scalars. Traced inputs (`jit`, `vmap`) go through the callback;
    concrete ones straight to heyoka."""
    inputs = (y0, pars, t0, t1, ts)
    if any(isinstance(x, Tracer) for x in inputs):
        return Rows(*_traced_run(runner, *inputs))
    one = runner.one_to_end(*inputs)
    if one is not None:
        return one
    rows = runner(*(np.asarray(x)[None] for x in inputs))
    return Rows(*(np.asarray(x[0]) for x in rows))


@functools.partial(jax.custom_jvp, nondiff_argnums=(0,))
def _traced_run(runner: HeyokaRunner, y0, pars, t0, t1, ts):
    dtype = y0.dtype
    shapes = (
        jax.ShapeDtypeStruct(ts.shape, dtype),
        jax.ShapeDtypeStruct((*ts.shape, y0.shape[0]), dtype),
        jax.ShapeDtypeStruct((), np.int32),
        jax.ShapeDtypeStruct((), np.int32),
    )
    return jax.pure_callback(
        functools.partial(_batched_callback, runner),
        shapes,
        y0,
        pars,
        t0,
        t1,
        ts,
        vmap_method="broadcast_all",
    )


@_traced_run.defjvp
def _refuse_derivatives(runner, primals, tangents):
    raise TypeError(GRADIENT_REFUSAL)


def _batched_callback(runner: HeyokaRunner, y0, pars, t0, t1, ts):
    """The callback: any leading batch axes (from `vmap`, tiled alike by
    "broadcast_all") flattened into one batch for heyoka, and restored."""
    y0 = np.asarray(y0)
    lead = y0.shape[:-1]
    dtypes = (y0.dtype, y0.dtype, np.int32, np.int32)
    one = None if lead else runner.one_to_end(y0, pars, t0, t1, ts)
    if one is not None:  # one member under `jit`, no `vmap`: no batch bookkeeping
        return tuple(np.asarray(x, dtype) for x, dtype in zip(one, dtypes))
    count = int(np.prod(lead))

    def members(x: Any, rank: int) -> np.ndarray:
        x = np.asarray(x)
        return x.reshape((count, *x.shape[x.ndim - rank :]))

    rows = runner(
        members(y0, 1), members(pars, 1), members(t0, 0), members(t1, 0),
        members(ts, 1),
    )  # fmt: skip
    return tuple(
        np.asarray(x, dtype).reshape((*lead, *x.shape[1:]))
        for x, dtype in zip(rows, dtypes)
    )
