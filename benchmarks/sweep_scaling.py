"""The targets of sweeps that outgrow one machine (issue 31), measured in one run.

The workload: Hénon–Heiles orbits (`lagjax.phase_space.henon_heiles`), one member
per start (q, p) drawn uniformly in [−0.25, 0.25]⁴, integrated by the default
splitting (Yoshida4, dt = 0.01) to t1, the final state kept. `lj.sweep` runs
`simulate` per member, so these are plain simulate members, not MEGNO ones (a
MEGNO member is a tangent-map integration that `lj.megno` runs outside `lj.sweep`);
the per-member work is the same kind. Every timing excludes start-up and
compilation (each process runs a warm-up chunk through the same compiled program
first), and every process is pinned to one core (`taskset`, or
`os.sched_setaffinity` where taskset is missing).

1. **Strong scaling**: `lj.sweep_to_disk` of the same members by 2 processes × 1
   core (JAX's distributed runtime, coordinator on localhost) against 1 process ×
   1 core. Target ≥ 1.8×. The two stores must be equal bit for bit.
2. **Streaming overhead**: `lj.sweep_to_disk` against the in-memory `lj.sweep`,
   same members and chunks, best of 3 each. Target ≤ 10 %.
3. **Bounded memory and throughput**: a sweep of 10⁶ members (full mode) streamed
   to disk in a fresh process: its peak RSS against the RSS before the sweep and
   the size of what it wrote; its time per member against `jax.jit(jax.vmap(
   simulate))` over all members at once, in the same process. Target: within 10 %.

    python -m benchmarks.sweep_scaling [--quick] [--out DIR]

`--out DIR` writes the figures to DIR/sweep_scaling.json. On a machine shared with
other work the ratios are what to read; absolute times are inflated by the load.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
DT = 0.01
FULL = dict(scaling=100_000, scaling_t1=10.0, streaming=50_000, streaming_t1=10.0,
            memory=1_000_000)  # fmt: skip
QUICK = dict(scaling=8192, scaling_t1=2.0, streaming=8192, streaming_t1=1.0,
             memory=20_000)  # fmt: skip
MEMORY_T1 = 1.0
CHUNK = 4096


def starts(members: int) -> tuple[np.ndarray, np.ndarray]:
    """The members' (q0, p0), the same in every process (NumPy: nothing may start
    JAX before jax.distributed.initialize)."""
    rng = np.random.default_rng(31)
    return rng.uniform(-0.25, 0.25, (members, 2)), rng.uniform(
        -0.25, 0.25, (members, 2)
    )


def _start_jax() -> None:
    from lagjax import enable_fast_cpu_loops

    enable_fast_cpu_loops()
    import jax

    jax.config.update("jax_enable_x64", True)


def _options(t1: float) -> dict:
    return dict(t1=t1, dt=DT, throw=False)


def _warm(members: int, t1: float, out: Path, chunks: int = 1) -> None:
    """Compile the sweep's program and its first-call costs: `chunks` whole chunks
    and a last chunk as short as the sweep's own through `lj.sweep` and
    `lj.sweep_to_disk` (into `out`). A short last chunk of a new size compiles a
    dozen small operations (its padding, the trimming of its results): about
    0.1 s each on the loaded machine, once per call and size."""
    import jax

    import lagjax as lj
    from lagjax.phase_space.henon_heiles import henon_heiles

    size = min(members, CHUNK * chunks + members % CHUNK)
    q0, p0 = starts(members)
    y0s = (q0[:size], p0[:size])
    options = dict(chunk_size=CHUNK, **_options(t1))
    jax.block_until_ready(lj.sweep(henon_heiles(), y0s, **options))
    lj.sweep_to_disk(henon_heiles(), y0s, out_dir=out, **options)


def _to_disk(members: int, t1: float, out: Path) -> float:
    import lagjax as lj
    from lagjax.phase_space.henon_heiles import henon_heiles

    start = time.perf_counter()
    lj.sweep_to_disk(
        henon_heiles(), starts(members), out_dir=out, chunk_size=CHUNK, **_options(t1)
    )
    return time.perf_counter() - start


def _in_memory(members: int, t1: float) -> float:
    import jax

    import lagjax as lj
    from lagjax.phase_space.henon_heiles import henon_heiles

    start = time.perf_counter()
    traj = lj.sweep(henon_heiles(), starts(members), chunk_size=CHUNK, **_options(t1))
    jax.block_until_ready(traj)
    return time.perf_counter() - start


# -- 2. streaming overhead (this process) ------------------------------------------


def streaming(members: int, t1: float, scratch: Path) -> dict:
    _warm(members, t1, scratch / "warm-stream")
    memory, disk = [], []
    for attempt in range(3):
        memory.append(_in_memory(members, t1))
        disk.append(_to_disk(members, t1, scratch / f"stream{attempt}"))
        shutil.rmtree(scratch / f"stream{attempt}")
    chunks = -(-members // CHUNK)
    return {
        "members": members,
        "t1": t1,
        "in_memory_s": min(memory),
        "to_disk_s": min(disk),
        "overhead": min(disk) / min(memory) - 1,
        "overhead_ms_per_chunk": 1e3 * (min(disk) - min(memory)) / chunks,
    }


# -- 1. strong scaling -------------------------------------------------------------


def _pinned(core: int, command: list[str]) -> list[str]:
    core %= os.cpu_count() or 1
    return (
        ["taskset", "-c", str(core), *command] if shutil.which("taskset") else command
    )


def scaling_worker(port: str, index: str, count: str, members: str, t1: str, out: str):
    if not shutil.which("taskset"):
        os.sched_setaffinity(0, {int(index) % (os.cpu_count() or 1)})
    import jax

    jax.distributed.initialize(
        f"127.0.0.1:{port}", num_processes=int(count), process_id=int(index)
    )
    _start_jax()
    from lagjax._sweep.processes import wait_for_all_processes

    _warm(int(members), float(t1), Path(out + "-warm"), chunks=int(count))
    wait_for_all_processes("benchmark start")
    print(f"SECONDS {_to_disk(int(members), float(t1), Path(out)):.6f}", flush=True)


def scaling(members: int, t1: float, scratch: Path) -> dict:
    """2 pinned processes against this one (pinned to core 0)."""
    import lagjax as lj

    _warm(members, t1, scratch / "warm-one")
    one = _to_disk(members, t1, scratch / "one")
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = str(probe.getsockname()[1])
    env = dict(os.environ, JAX_PLATFORMS="cpu", PYTHONPATH=str(ROOT))
    worker = [sys.executable, "-m", "benchmarks.sweep_scaling", "--scaling-worker"]
    runs = [
        subprocess.Popen(
            _pinned(
                k,
                [
                    *worker,
                    port,
                    str(k),
                    "2",
                    str(members),
                    str(t1),
                    str(scratch / "two"),
                ],
            ),
            cwd=ROOT,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for k in range(2)
    ]
    outputs = [run.communicate(timeout=3600) for run in runs]
    seconds = [
        float(line.split()[1])
        for output, _ in outputs
        for line in output.splitlines()
        if line.startswith("SECONDS")
    ]
    if len(seconds) != 2:
        raise RuntimeError("a scaling worker failed:\n" + outputs[0][1][-3000:])
    two = max(seconds)
    a, b = lj.open_sweep(scratch / "one"), lj.open_sweep(scratch / "two")
    identical = all(np.array_equal(a.array(f), b.array(f)) for f in ("q", "p", "ts"))
    return {
        "members": members,
        "t1": t1,
        "one_process_s": one,
        "two_processes_s": two,
        "speed_up": one / two,
        "bit_identical": bool(identical),
        "failed": int(np.count_nonzero(a.failed())),
        "energy_drift": _energy_drift(a, members),
    }


def _energy_drift(store, members: int) -> float:
    """max |H(final) − H(start)| over the members that stayed bound (E < 1/6)."""
    from lagjax.phase_space.henon_heiles import ESCAPE_ENERGY

    def energy(q, p):
        x, y = q[:, 0], q[:, 1]
        return 0.5 * (p**2).sum(1) + 0.5 * (x**2 + y**2) + x**2 * y - y**3 / 3

    q0, p0 = starts(members)
    before = energy(q0, p0)
    after = energy(store.array("q")[:, -1], store.array("p")[:, -1])
    bound = before < ESCAPE_ENERGY
    return float(np.max(np.abs(after - before)[bound]))


# -- 3. bounded memory and throughput (a fresh process) ----------------------------


def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # Linux: kB


def memory_worker(members: str, out: str) -> None:
    _start_jax()
    import jax

    import lagjax as lj
    from lagjax.phase_space.henon_heiles import henon_heiles

    n = int(members)
    _warm(n, MEMORY_T1, Path(out + "-warm"))
    y0s = starts(n)
    reference = jax.jit(
        jax.vmap(lambda y0: lj.simulate(henon_heiles(), y0, **_options(MEMORY_T1)))
    )
    compiled = reference.lower(y0s).compile()
    before = _peak_rss_mb()
    seconds = _to_disk(n, MEMORY_T1, Path(out))
    sweep_peak = _peak_rss_mb()
    start = time.perf_counter()
    jax.block_until_ready(compiled(y0s))
    vmapped = time.perf_counter() - start
    written = sum(f.stat().st_size for f in Path(out).rglob("*") if f.is_file())
    figures = {
        "members": n,
        "rss_before_sweep_mb": before,
        "peak_rss_sweep_mb": sweep_peak,
        "peak_rss_after_vmap_mb": _peak_rss_mb(),
        "written_mb": written / 2**20,
        "inputs_mb": sum(x.nbytes for x in y0s) / 2**20,
        "sweep_s": seconds,
        "vmap_s": vmapped,
        "sweep_us_per_member": 1e6 * seconds / n,
        "vmap_us_per_member": 1e6 * vmapped / n,
        "throughput_ratio": vmapped / seconds,
    }
    print("FIGURES " + json.dumps(figures), flush=True)


def memory(members: int, scratch: Path) -> dict:
    command = [sys.executable, "-m", "benchmarks.sweep_scaling", "--memory-worker",
               str(members), str(scratch / "memory")]  # fmt: skip
    env = dict(os.environ, JAX_PLATFORMS="cpu", PYTHONPATH=str(ROOT))
    done = subprocess.run(
        _pinned(0, command), cwd=ROOT, env=env, capture_output=True, text=True
    )
    lines = [line for line in done.stdout.splitlines() if line.startswith("FIGURES")]
    if done.returncode or not lines:
        raise RuntimeError("the memory worker failed:\n" + done.stderr[-3000:])
    return json.loads(lines[0].removeprefix("FIGURES "))


def report(figures: dict) -> None:
    s, t, m = figures["scaling"], figures["streaming"], figures["memory"]
    print(
        f"scaling    {s['members']} members to t1 = {s['t1']:g}: 1 process × 1 core "
        f"{s['one_process_s']:.2f} s, 2 × 1 core {s['two_processes_s']:.2f} s: "
        f"{s['speed_up']:.2f}× (target ≥ 1.8×); bit-identical: {s['bit_identical']}"
    )
    print(
        f"streaming  {t['members']} members to t1 = {t['t1']:g}: in memory "
        f"{t['in_memory_s']:.3f} s, to disk {t['to_disk_s']:.3f} s: "
        f"{100 * t['overhead']:+.1f} % (target ≤ 10 %), "
        f"{t['overhead_ms_per_chunk']:.1f} ms per chunk of {CHUNK}"
    )
    print(
        f"memory     {m['members']} members: peak RSS {m['peak_rss_sweep_mb']:.0f} MB "
        f"(before the sweep {m['rss_before_sweep_mb']:.0f} MB; inputs "
        f"{m['inputs_mb']:.0f} MB; written {m['written_mb']:.0f} MB)"
    )
    print(
        f"throughput {m['sweep_us_per_member']:.2f} µs/member streamed, "
        f"{m['vmap_us_per_member']:.2f} µs/member jit(vmap(simulate)): "
        f"{m['throughput_ratio']:.2f}× (target within 10 %)"
    )


def main() -> None:
    if sys.argv[1:2] == ["--scaling-worker"]:
        return scaling_worker(*sys.argv[2:])
    if sys.argv[1:2] == ["--memory-worker"]:
        return memory_worker(*sys.argv[2:])
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--out", type=Path, default=None)
    options = parser.parse_args()
    sizes = QUICK if options.quick else FULL
    # This process runs the one-process figures: one core, like each worker.
    os.sched_setaffinity(0, {0})
    _start_jax()
    with tempfile.TemporaryDirectory() as scratch:
        figures = {
            "mode": "quick" if options.quick else "full",
            "scaling": scaling(sizes["scaling"], sizes["scaling_t1"], Path(scratch)),
            "streaming": streaming(
                sizes["streaming"], sizes["streaming_t1"], Path(scratch)
            ),
            "memory": memory(sizes["memory"], Path(scratch)),
        }
    report(figures)
    if options.out is not None:
        options.out.mkdir(parents=True, exist_ok=True)
        (options.out / "sweep_scaling.json").write_text(json.dumps(figures, indent=1))


if __name__ == "__main__":
    main()
