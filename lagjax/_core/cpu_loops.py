"""XLA's CPU loop option: compile whole loop bodies into one kernel, when asked.

XLA on CPU compiles a `while` loop (every `lax.scan` of a fixed-step run) into a
single kernel only when its body moves less than
`xla_cpu_small_while_loop_byte_threshold` bytes (1 kB by default); above that, the
fused pieces of the body are dispatched one by one at every iteration. A
fourth-order splitting step, an implicit Gauss–Legendre step or a Lie–Poisson
rigid-body step is over that size, and a long single-trajectory run then spends
most of its time in dispatch. Measured on the 2-core CI machine (Kepler, 4·10⁴
steps to t = 40, jax 0.10.2, 2026-11-27): `Yoshida4` 14.7 ms without the option,
3.4 ms with it; `GaussLegendre(stages=2)` 31.8 ms and 5.6 ms.

**Why it is an explicit call.** The threshold lives in XLA's backend extra options,
a map that only the process-wide `XLA_FLAGS` can set: JAX's per-compilation
`compiler_options` reach scalar `DebugOptions` fields only, and refuse this map
("not a valid message value"). Setting it on import would change every JAX program
of the process and of its children, so lagjax never does. Call
`enable_fast_cpu_loops()` at the top of a script, before the first JAX computation
(XLA reads `XLA_FLAGS` once, when its CPU backend starts); the `lagjax` command and
the benchmarks do. The option affects only the CPU backend.
"""

from __future__ import annotations

import os

THRESHOLD_OPTION = "xla_cpu_small_while_loop_byte_threshold=100000000"


def enable_fast_cpu_loops() -> bool:
    """Ask XLA's CPU backend to compile whole loop bodies (module docstring).

    Appends the option to `XLA_FLAGS` unless the flags already choose backend
    extra options (the caller's choice wins). It takes effect only if JAX's backend
    has not started yet, so call it before the first JAX computation. Returns
    whether `XLA_FLAGS` now carries the option.
    """
    flags = os.environ.get("XLA_FLAGS", "")
    if THRESHOLD_OPTION in flags:
        return True
    if "xla_backend_extra_options" in flags:
        return False
    os.environ["XLA_FLAGS"] = (
        f"{flags} --xla_backend_extra_options={THRESHOLD_OPTION}".strip()
    )
    return True


def fast_cpu_loops_requested() -> bool:
    """Whether `XLA_FLAGS` carries the option (it acts if set before JAX started)."""
    return THRESHOLD_OPTION in os.environ.get("XLA_FLAGS", "")
