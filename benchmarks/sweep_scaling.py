"""The targets of sweeps that outgrow one machine (issue 31), measured in one run.

1. **Strong scaling** on MEGNO members: ⟨Y⟩ of 10⁵ Hénon–Heiles orbits
   (`lj.sweep_to_disk(..., measure=lj.megno)`, Yoshida4 at dt = 0.05, renormalised
   every 0.5, to t1 = 100; quick mode 8192 orbits to t1 = 10), one start (q, p) per
   member drawn uniformly in [−0.25, 0.25]⁴ (all bound: E < 1/6), by 2 processes ×
   1 core (JAX's distributed runtime, coordinator on localhost) against 1 process ×
   1 core. Target ≥ 1.8×. Each configuration runs in fresh worker processes pinned
   to cores 0 (and 1), which report their breakdown: Python and JAX start-up,
   `jax.distributed.initialize`, the first sweep (to a scratch directory) and the
   compile time inside it (JAX's own monitoring events), the timed second sweep
   through the compiled program, this process's chunks through the same program
   with nothing written (integration alone), and the gather the in-memory
   `lj.sweep` does of their results. The headline ratio is the second sweep's;
   the integration-alone and end-to-end (process start to the first sweep's end)
   ratios come with it. The chunk size divides the members evenly among the
   processes (32 chunks of 3125). The two stores must be equal bit for bit.
2. **Streaming overhead**: `lj.sweep_to_disk` against the in-memory `lj.sweep`,
   same members and chunks, best of 3 each, plain `simulate` members (Hénon–Heiles,
   default splitting Yoshida4 at dt = 0.01, final state kept). Target ≤ 10 %.
3. **Bounded memory and throughput**: a sweep of 10⁶ such members (full mode)
   streamed to disk in a fresh process: its peak RSS against the RSS before the
   sweep and the size of what it wrote; its time per member against `jax.jit(
   jax.vmap(simulate))` over all members at once, in the same process. Target:
   within 10 %.

Measured on an idle 16-core machine (one thread per core; jax 0.11.2, CPU backend,
2026-11-27), the full run taking 2 min 27 s: scaling 2.08× (integration alone
1.92×, end to end 1.49×). Per process: start-up 2.1 s, `distributed.initialize`
0.23 s, compile 3.4 s alone and 4.3–4.5 s with two compiling at once (in
parallel), integration 19.5 s against 9.3 and 10.2 s, writing and checks < 1 s,
the gather 0.04 s (process 0 waits 0.9 s in it for the slower process 1). What
keeps end to end below 2× is the fixed ~6.7 s a process spends before integrating.

Every timing but the end-to-end one excludes start-up and compilation, and every
process is pinned to one core (`taskset`, or `os.sched_setaffinity` where taskset
is missing), the workers to distinct physical cores (not two hyperthreads of one).

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
FULL = dict(scaling=100_000, scaling_t1=100.0, scaling_chunk=3125, streaming=50_000,
            streaming_t1=10.0, memory=1_000_000)  # fmt: skip
QUICK = dict(scaling=8192, scaling_t1=10.0, scaling_chunk=1024, streaming=8192,
             streaming_t1=1.0, memory=20_000)  # fmt: skip
MEMORY_T1 = 1.0
CHUNK = 4096
# MEGNO members as benchmarks/phase_space.py maps them; ⟨Y⟩ above 4 counts as chaotic.
MEGNO = dict(dt=0.05, renormalize_every=0.5)
CHAOTIC_MEGNO = 4.0


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


def _warm(members: int, t1: float, out: Path) -> None:
    """Compile the sweep's program and its first-call costs: a whole chunk and a
    last chunk as short as the sweep's own through `lj.sweep` and
    `lj.sweep_to_disk` (into `out`). A short last chunk of a new size compiles a
    dozen small operations (its padding, the trimming of its results): about
    0.1 s each on the loaded machine, once per call and size."""
    import jax

    import lagjax as lj
    from lagjax.phase_space.henon_heiles import henon_heiles

    size = min(members, CHUNK + members % CHUNK)
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


# -- 1. strong scaling: MEGNO members, one worker process per configuration -------


def _physical_cores() -> list[int]:
    """One logical CPU per physical core, in order: two workers on the two
    hyperthreads of one core would share its execution units."""
    chosen, seen = [], set()
    for cpu in range(os.cpu_count() or 1):  # not this process's affinity: core 0
        topology = Path(f"/sys/devices/system/cpu/cpu{cpu}/topology")
        try:
            core = tuple((topology / name).read_text().strip()
                         for name in ("physical_package_id", "core_id"))  # fmt: skip
        except OSError:
            core = (str(cpu),)
        if core not in seen:
            seen.add(core)
            chosen.append(cpu)
    return chosen or [0]


def _pinned(worker: int, command: list[str]) -> list[str]:
    cores = _physical_cores()
    core = cores[worker % len(cores)]
    return (
        ["taskset", "-c", str(core), *command] if shutil.which("taskset") else command
    )


class _CompileClock:
    """Seconds JAX spends tracing, lowering and compiling (its own monitoring
    events), summed from when it is made."""

    EVENTS = ("/jax/core/compile/jaxpr_trace_duration",
              "/jax/core/compile/jaxpr_to_mlir_module_duration",
              "/jax/core/compile/backend_compile_duration")  # fmt: skip

    def __init__(self):
        import jax.monitoring

        self.seconds = 0.0
        jax.monitoring.register_event_duration_secs_listener(self._heard)

    def _heard(self, event: str, duration: float, **_) -> None:
        if event in self.EVENTS:
            self.seconds += duration


def _megno_sweep(members: int, t1: float, chunk: int, out: Path) -> None:
    import lagjax as lj
    from lagjax.phase_space.henon_heiles import henon_heiles

    lj.sweep_to_disk(henon_heiles(), starts(members), out_dir=out, chunk_size=chunk,
                     measure=lj.megno, t1=t1, **MEGNO)  # fmt: skip


def _integration_only(members: int, t1: float, chunk: int) -> dict:
    """The parts of a sweep, timed one by one in this process: its checks (one
    member traced, `chunked_run`), this process's chunks through the compiled
    program with nothing written (integration), and the in-memory sweep's gather
    of their results across the processes."""
    import jax

    import lagjax as lj
    from lagjax._sweep.processes import chunks_of_this_process, gather_chunks
    from lagjax.phase_space.henon_heiles import henon_heiles
    from lagjax.sweep import chunk_results, chunked_run

    start = time.perf_counter()
    chunks = chunked_run(henon_heiles(), starts(members), None, chunk, None,
                         dict(t1=t1, **MEGNO), lj.megno)  # fmt: skip
    figures = {"checks_s": time.perf_counter() - start}
    mine = chunks_of_this_process(chunks.count)
    start = time.perf_counter()
    pieces = list(chunk_results(chunks, mine))  # one at a time, as the sweeps run
    figures["integration_s"] = time.perf_counter() - start
    start = time.perf_counter()
    if jax.process_count() > 1:
        gather_chunks(pieces, mine, chunks.count, chunks.step, chunks.size)
    figures["gather_s"] = time.perf_counter() - start
    figures["chunks"] = len(mine)
    figures["members"] = sum(min(chunks.step, members - i * chunks.step) for i in mine)
    return figures


def scaling_worker(launched: str, port: str, index: str, count: str, members: str,
                   t1: str, chunk: str, out: str) -> None:  # fmt: skip
    """One process of the scaling row: start-up, the first (compiling) sweep, a
    second sweep through the compiled program, and its integration alone."""
    # Python's start and the imports of jax and lagjax (benchmarks/__init__.py).
    clock = {"startup_s": time.time() - float(launched)}
    if not shutil.which("taskset"):
        cores = _physical_cores()
        os.sched_setaffinity(0, {cores[int(index) % len(cores)]})
    n, t1_, size = int(members), float(t1), int(chunk)
    import jax

    began = time.perf_counter()
    if int(count) > 1:
        jax.distributed.initialize(
            f"127.0.0.1:{port}", num_processes=int(count), process_id=int(index)
        )
    clock["distributed_initialize_s"] = time.perf_counter() - began
    _start_jax()
    from lagjax._sweep.processes import wait_for_all_processes

    compiling = _CompileClock()
    began = time.perf_counter()
    _megno_sweep(n, t1_, size, Path(out + "-cold"))
    clock["first_sweep_s"] = time.perf_counter() - began
    clock["compile_s"] = compiling.seconds
    clock["end_to_end_s"] = time.time() - float(launched)
    wait_for_all_processes("benchmark: second sweep")
    began = time.perf_counter()
    _megno_sweep(n, t1_, size, Path(out))
    clock["sweep_s"] = time.perf_counter() - began
    wait_for_all_processes("benchmark: integration alone")
    clock.update(_integration_only(n, t1_, size))
    print("FIGURES " + json.dumps(clock), flush=True)


def _workers(count: int, members: int, t1: float, chunk: int, out: Path) -> list:
    """Run `count` pinned worker processes (cores 0, 1, …); their figures."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = str(probe.getsockname()[1])
    env = dict(os.environ, JAX_PLATFORMS="cpu", PYTHONPATH=str(ROOT))
    worker = [sys.executable, "-m", "benchmarks.sweep_scaling", "--scaling-worker"]
    options = [str(members), str(t1), str(chunk), str(out)]
    runs = [
        subprocess.Popen(
            _pinned(
                k, [*worker, f"{time.time():.6f}", port, str(k), str(count), *options]
            ),
            cwd=ROOT,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for k in range(count)
    ]
    outputs = [run.communicate(timeout=3600) for run in runs]
    figures = [
        json.loads(line.removeprefix("FIGURES "))
        for output, _ in outputs
        for line in output.splitlines()
        if line.startswith("FIGURES ")
    ]
    if len(figures) != count:
        raise RuntimeError("a scaling worker failed:\n" + outputs[0][1][-3000:])
    return figures


def scaling(members: int, t1: float, chunk: int, scratch: Path) -> dict:
    """1 pinned worker process against 2 (pinned to cores 0 and 1)."""
    import lagjax as lj

    one = _workers(1, members, t1, chunk, scratch / "one")[0]
    two = _workers(2, members, t1, chunk, scratch / "two")
    a, b = lj.open_sweep(scratch / "one"), lj.open_sweep(scratch / "two")
    values = a.array("value")

    def slowest(name):
        return max(worker[name] for worker in two)

    return {
        "members": members,
        "t1": t1,
        "chunk_size": chunk,
        "one_process": one,
        "two_processes": two,
        "speed_up": one["sweep_s"] / slowest("sweep_s"),
        "speed_up_integration": one["integration_s"] / slowest("integration_s"),
        "speed_up_end_to_end": one["end_to_end_s"] / slowest("end_to_end_s"),
        "bit_identical": bool(np.array_equal(values, b.array("value"))),
        "failed": int(np.count_nonzero(a.failed())),
        "chaotic_share": float(np.mean(values > CHAOTIC_MEGNO)),
        "median_megno": float(np.median(values)),
    }


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


def _breakdown(label: str, w: dict) -> str:
    return (
        f"  {label:<13} start-up {w['startup_s']:.2f} s (Python, imports) + "
        f"distributed init {w['distributed_initialize_s']:.2f} s; first sweep "
        f"{w['first_sweep_s']:.2f} s of which compile {w['compile_s']:.2f} s; "
        f"second sweep {w['sweep_s']:.2f} s = integration {w['integration_s']:.2f} s "
        f"({w['chunks']} chunks, {w['members']} members) + checks "
        f"{w['checks_s']:.2f} s + writing and waiting "
        f"{w['sweep_s'] - w['integration_s'] - w['checks_s']:.2f} s; gather "
        f"{w['gather_s']:.3f} s"
    )


def report_scaling(s: dict) -> None:
    one, two = s["one_process"], s["two_processes"]
    print(
        f"scaling    {s['members']} MEGNO members to t1 = {s['t1']:g} in chunks of "
        f"{s['chunk_size']}: 1 process × 1 core {one['sweep_s']:.2f} s, 2 × 1 core "
        f"{max(w['sweep_s'] for w in two):.2f} s: {s['speed_up']:.2f}× (target "
        f"≥ 1.8×); integration alone {s['speed_up_integration']:.2f}×; end to end "
        f"(process start, compile, first sweep) {s['speed_up_end_to_end']:.2f}×; "
        f"bit-identical: {s['bit_identical']}; ⟨Y⟩ > {CHAOTIC_MEGNO:g}: "
        f"{100 * s['chaotic_share']:.1f} %, {s['failed']} failed"
    )
    print(_breakdown("1 process", one))
    for k, worker in enumerate(two):
        print(_breakdown(f"2: process {k}", worker), flush=True)


def report_streaming(t: dict) -> None:
    print(
        f"streaming  {t['members']} members to t1 = {t['t1']:g}: in memory "
        f"{t['in_memory_s']:.3f} s, to disk {t['to_disk_s']:.3f} s: "
        f"{100 * t['overhead']:+.1f} % (target ≤ 10 %), "
        f"{t['overhead_ms_per_chunk']:.1f} ms per chunk of {CHUNK}",
        flush=True,
    )


def report_memory(m: dict) -> None:
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
    figures = {"mode": "quick" if options.quick else "full"}
    # Each row is printed as soon as it is measured.
    with tempfile.TemporaryDirectory() as scratch:
        figures["scaling"] = scaling(
            sizes["scaling"], sizes["scaling_t1"], sizes["scaling_chunk"], Path(scratch)
        )
        report_scaling(figures["scaling"])
        figures["streaming"] = streaming(
            sizes["streaming"], sizes["streaming_t1"], Path(scratch)
        )
        report_streaming(figures["streaming"])
        figures["memory"] = memory(sizes["memory"], Path(scratch))
        report_memory(figures["memory"])
    if options.out is not None:
        options.out.mkdir(parents=True, exist_ok=True)
        (options.out / "sweep_scaling.json").write_text(json.dumps(figures, indent=1))


if __name__ == "__main__":
    main()
