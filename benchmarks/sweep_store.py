"""Sweeps on disk and across processes: what streaming costs, what a second process
buys.

1. Streaming overhead: `lj.sweep_to_disk` against the in-memory `lj.sweep` on the
   same Hénon–Heiles sweep and chunks, both compiled beforehand, one process.
2. Strong scaling: the same sweep (gathered, `lj.sweep`) by P CPU processes on JAX's
   distributed runtime (coordinator on localhost), each pinned to one core, against
   one process on one core. Times exclude start-up and compilation (a warm-up
   chunk runs first), and end when the gathered result is in every process.

    python -m benchmarks.sweep_store [--members 20000] [--chunk 2000] [--processes 2]
"""

from __future__ import annotations

import argparse
import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def _problem(members: int):
    import jax.numpy as jnp

    import lagjax as lj

    def potential(q):
        x, y = q[0], q[1]
        return 0.5 * (x**2 + y**2) + x**2 * y - y**3 / 3.0

    system = lj.SeparableHamiltonian(lambda p: 0.5 * (p[0] ** 2 + p[1] ** 2), potential)
    rng = np.random.default_rng(0)
    q0 = rng.uniform(-0.3, 0.3, (members, 2))
    p0 = rng.uniform(-0.3, 0.3, (members, 2))
    return system, (jnp.asarray(q0), jnp.asarray(p0)), dict(t1=20.0, dt=0.01)


def _timed(fn) -> float:
    start = time.perf_counter()
    fn()
    return time.perf_counter() - start


def streaming_overhead(members: int, chunk: int) -> None:
    import jax

    import lagjax as lj

    system, y0s, options = _problem(members)
    options["throw"] = False
    warm = jax.tree_util.tree_map(lambda x: x[:chunk], y0s)
    jax.block_until_ready(lj.sweep(system, warm, chunk_size=chunk, **options))
    rows = []
    for _ in range(3):
        memory = _timed(
            lambda: jax.block_until_ready(
                lj.sweep(system, y0s, chunk_size=chunk, **options)
            )
        )
        with tempfile.TemporaryDirectory() as out:
            disk = _timed(
                lambda: lj.sweep_to_disk(
                    system, y0s, out_dir=out, chunk_size=chunk, **options
                )
            )
        rows.append((memory, disk))
    memory, disk = (min(column) for column in zip(*rows))
    print(
        f"streaming: {members} members, chunks of {chunk}: in memory {memory:.3f} s, "
        f"to disk {disk:.3f} s, overhead {100 * (disk / memory - 1):+.1f} % "
        "(best of 3)"
    )


def worker(port: str, index: str, count: str, members: str, chunk: str) -> None:
    os.sched_setaffinity(0, {int(index) % os.cpu_count()})
    import jax

    jax.distributed.initialize(
        f"127.0.0.1:{port}", num_processes=int(count), process_id=int(index)
    )
    jax.config.update("jax_enable_x64", True)
    import lagjax as lj
    from lagjax._sweep.processes import wait_for_all_processes

    system, y0s, options = _problem(int(members))
    warm = jax.tree_util.tree_map(lambda x: x[: int(chunk) * int(count)], y0s)
    jax.block_until_ready(lj.sweep(system, warm, chunk_size=int(chunk), **options))
    wait_for_all_processes("benchmark start")
    seconds = _timed(
        lambda: jax.block_until_ready(
            lj.sweep(system, y0s, chunk_size=int(chunk), **options)
        )
    )
    print(f"SECONDS {seconds:.4f}", flush=True)


def scaling(members: int, chunk: int, processes: int) -> None:
    times = {}
    for count in (1, processes):
        with socket.socket() as probe:
            probe.bind(("127.0.0.1", 0))
            port = str(probe.getsockname()[1])
        env = dict(os.environ, JAX_PLATFORMS="cpu", PYTHONPATH=str(ROOT))
        command = [sys.executable, "-m", "benchmarks.sweep_store", "--worker", port]
        runs = [
            subprocess.Popen(
                [*command, str(k), str(count), str(members), str(chunk)],
                cwd=ROOT,
                env=env,
                stdout=subprocess.PIPE,
                stderr=subprocess.DEVNULL,
                text=True,
            )
            for k in range(count)
        ]
        outputs = [run.communicate(timeout=3600)[0] for run in runs]
        seconds = [
            float(line.split()[1])
            for output in outputs
            for line in output.splitlines()
            if line.startswith("SECONDS")
        ]
        assert len(seconds) == count, outputs
        times[count] = max(seconds)
    print(
        f"scaling: {members} members, chunks of {chunk}: 1 process {times[1]:.3f} s, "
        f"{processes} processes {times[processes]:.3f} s, "
        f"speed-up {times[1] / times[processes]:.2f}x (one core per process)"
    )


def main() -> None:
    if sys.argv[1:2] == ["--worker"]:
        return worker(*sys.argv[2:])
    parser = argparse.ArgumentParser()
    parser.add_argument("--members", type=int, default=20_000)
    parser.add_argument("--chunk", type=int, default=2_000)
    parser.add_argument("--processes", type=int, default=2)
    options = parser.parse_args()
    import jax

    jax.config.update("jax_enable_x64", True)
    streaming_overhead(options.members, options.chunk)
    scaling(options.members, options.chunk, options.processes)


if __name__ == "__main__":
    main()
