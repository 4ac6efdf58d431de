r"""How costs grow with the batch size: trajectory-steps per second.

The double pendulum, `THROUGHPUT_STEPS` fixed Tsit5 steps per trajectory, batches
run in chunks of `CHUNK` (memory stays bounded by a chunk): `jax.vmap` of
`lj.simulate` against `jax.vmap` of a hand-written `diffrax.diffeqsolve`.
`lj.sweep` is timed as called (it compiles on every call).

References: JAX documentation, automatic vectorization (`jax.vmap`).
"""

from __future__ import annotations

import time
from typing import Any

import diffrax
import jax
import jax.numpy as jnp

import lagjax as lj
from benchmarks import peers
from lagjax import diagnostics
from lagjax.scenes.pendulums import DoublePendulum

THROUGHPUT_STEPS, THROUGHPUT_DT, CHUNK = 200, 0.01, 4096


def _batched_starts(batch: int) -> tuple[jax.Array, jax.Array]:
    """The scene's start with θ₁ spread by up to 10⁻³ rad across the batch."""
    q0, qdot0 = DoublePendulum().initial_state()
    spread = 1e-3 * jnp.linspace(-1.0, 1.0, batch)[:, None] * jnp.array([1.0, 0.0])
    return q0 + spread, jnp.broadcast_to(qdot0, (batch, 2))


def _chunked_rate(single: Any, starts: Any, batch: int, timing: dict) -> dict:
    """Compile `vmap(single)` for one chunk, then time the whole batch chunk by chunk."""
    size = min(batch, CHUNK)
    chunks = [
        jax.tree_util.tree_map(lambda x, k=k: x[k : k + size], starts)
        for k in range(0, batch, size)
    ]
    began = time.perf_counter()
    compiled = jax.jit(jax.vmap(single)).lower(chunks[0]).compile()
    build = time.perf_counter() - began
    measured = diagnostics.time_run(
        lambda: [compiled(chunk) for chunk in chunks], jit=False, **timing
    )
    rate = batch * THROUGHPUT_STEPS / measured.run_seconds
    return dict(build_s=build, run_s=measured.run_seconds, steps_per_s=rate)


def throughput(batches: tuple[int, ...], sweep_batches: tuple[int, ...], timing: dict):
    """Trajectory-steps per second of the double pendulum against the batch size."""
    scene, t1 = DoublePendulum(), THROUGHPUT_STEPS * THROUGHPUT_DT
    peer = peers.double_pendulum(scene)
    term = diffrax.ODETerm(lambda t, y, args: peer.vector_field(jnp, y))

    def ours(y0):
        solver = diffrax.Tsit5()
        return lj.simulate(scene, y0, t1=t1, dt=THROUGHPUT_DT, solver=solver).ys

    def hand(y0):
        return diffrax.diffeqsolve(
            term, diffrax.Tsit5(), 0.0, t1, THROUGHPUT_DT, y0,
            saveat=diffrax.SaveAt(t1=True), max_steps=THROUGHPUT_STEPS + 1,
        ).ys  # fmt: skip

    rows = []
    for batch in batches:
        q0, qdot0 = _batched_starts(batch)
        for route, single, starts in (
            ("lagjax (vmap of lj.simulate)", ours, (q0, qdot0)),
            ("hand-written diffrax (vmap)", hand, jnp.concatenate([q0, qdot0], -1)),
        ):
            rows.append(
                dict(
                    batch=batch,
                    route=route,
                    **_chunked_rate(single, starts, batch, timing),
                )
            )
    for batch in sweep_batches:  # lj.sweep as a user calls it: it compiles each time
        starts = _batched_starts(batch)
        measured = diagnostics.time_run(
            lambda starts=starts: lj.sweep(scene, starts, t1=t1, dt=THROUGHPUT_DT,
                                           solver=diffrax.Tsit5(), chunk_size=CHUNK).ys,
            jit=False, warmup=0, repeats=1,
        )  # fmt: skip
        rate = batch * THROUGHPUT_STEPS / measured.run_seconds
        rows.append(dict(batch=batch, route="lj.sweep (per call)", build_s=0.0,
                         run_s=measured.run_seconds, steps_per_s=rate))  # fmt: skip
    for row in rows:
        print(f"  batch {row['batch']:6d} {row['route']:30s} {row['steps_per_s']:9.3g} "
              f"trajectory-steps/s (run {row['run_s']:.2e} s)", flush=True)  # fmt: skip
    return rows
