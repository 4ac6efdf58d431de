"""One process of a multi-process sweep, for tests/test_sweep_store.py.

`python -m tests.sweep_worker PORT PROCESS_ID PROCESS_COUNT OUT_DIR` joins JAX's
distributed runtime (coordinator on 127.0.0.1:PORT), runs the sweep below both
ways — gathered in memory (`lj.sweep`) and streamed (`lj.sweep_to_disk`) — and
process 0 saves the gathered arrays to OUT_DIR/gathered.npz.
"""

import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import lagjax as lj

MEMBERS = 11  # not a multiple of the chunk size: a short last chunk
CHUNK = 3
# NumPy, not jax.numpy: nothing may start JAX before jax.distributed.initialize.
OPTIONS = dict(t1=2.0, dt=0.01, ts=np.linspace(0.0, 2.0, 4))


def _kinetic(p):
    return 0.5 * p**2


def _potential(q, t, w):
    return w**2 * (1.0 - jnp.cos(q))


def problem():
    """A pendulum family: amplitude and frequency vary across the members. The
    functions are module-level, so every call gives an equal system (and a test
    process compiles the sweep once)."""
    system = lj.SeparableHamiltonian(_kinetic, _potential)
    y0s = (jnp.linspace(0.1, 2.5, MEMBERS), jnp.linspace(-0.3, 0.3, MEMBERS))
    omegas = jnp.linspace(0.5, 2.0, MEMBERS)
    return system, y0s, omegas


def main(port: str, process_id: str, process_count: str, out: str) -> None:
    jax.config.update("jax_enable_x64", True)
    jax.distributed.initialize(
        f"127.0.0.1:{port}",
        num_processes=int(process_count),
        process_id=int(process_id),
    )
    system, y0s, omegas = problem()
    # throw=False as sweep_to_disk runs it: one compiled program serves both.
    gathered = lj.sweep(system, y0s, omegas, chunk_size=CHUNK, throw=False, **OPTIONS)
    store = lj.sweep_to_disk(
        system, y0s, omegas, out_dir=Path(out) / "disk", chunk_size=CHUNK, **OPTIONS
    )
    assert store.complete, store.index
    if jax.process_index() == 0:
        np.savez(
            Path(out) / "gathered.npz",
            ts=np.asarray(gathered.ts),
            q=np.asarray(gathered.q),
            p=np.asarray(gathered.ys[1]),
        )
    print(f"process {jax.process_index()} of {jax.process_count()} done", flush=True)


if __name__ == "__main__":
    main(*sys.argv[1:])
