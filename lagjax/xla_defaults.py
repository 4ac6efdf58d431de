"""lagjax's one process-wide default: let XLA's CPU backend compile whole loop bodies.

XLA on CPU compiles a `while` loop (every `lax.scan` here) into a single kernel only
when its body moves less than `xla_cpu_small_while_loop_byte_threshold` bytes (1 kB
by default); above that, the fused pieces of the body are dispatched one by one at
every iteration. A fourth-order splitting step, an implicit Gauss–Legendre step or
a Lie–Poisson rigid-body step is over that size, and a long single-trajectory run
then spends most of its time in dispatch: Kepler with `Yoshida4` ran 5× a
hand-written scan (65 ms against 13 ms for 4·10⁴ steps with 1001 saves, and
`GaussLegendre(stages=2)` 87 ms against 17 ms; compile times unchanged; measured in
`benchmarks/solver_overhead.py`).

So, on import, lagjax raises that threshold — but only when it can do so safely:

- the JAX backend has not started yet (XLA reads `XLA_FLAGS` once, when it starts;
  import lagjax before the first computation to get the default), and
- `XLA_FLAGS` does not already set `xla_backend_extra_options` (the user's own
  choice wins), and
- `LAGJAX_NO_XLA_DEFAULTS` is not set in the environment (the opt-out).

`cpu_loop_default_applied()` says whether it took effect. The option affects only
the CPU backend; GPU and TPU runs ignore it.
"""

from __future__ import annotations

import os

THRESHOLD_OPTION = "xla_cpu_small_while_loop_byte_threshold=100000000"
OPT_OUT_VARIABLE = "LAGJAX_NO_XLA_DEFAULTS"

_applied = False


def _backend_started() -> bool:
    try:
        from jax._src import xla_bridge  # private: no public query exists

        return bool(xla_bridge.backends_are_initialized())
    except (ImportError, AttributeError):  # a JAX without it: assume started
        return True


def apply_cpu_loop_default() -> bool:
    """Raise XLA's CPU small-loop threshold if safe (module docstring); return
    whether it is now in effect for this process."""
    global _applied
    flags = os.environ.get("XLA_FLAGS", "")
    if THRESHOLD_OPTION in flags:
        _applied = True
    elif (
        not os.environ.get(OPT_OUT_VARIABLE)
        and "xla_backend_extra_options" not in flags
        and not _backend_started()
    ):
        os.environ["XLA_FLAGS"] = (
            f"{flags} --xla_backend_extra_options={THRESHOLD_OPTION}".strip()
        )
        _applied = True
    return _applied


def cpu_loop_default_applied() -> bool:
    """Whether lagjax's CPU loop threshold is in effect (see the module docstring)."""
    return _applied
