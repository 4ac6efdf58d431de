"""lagjax's benchmarks: work-precision, scaling, stability, overhead against
hand-written twins and peers.

A package so that its modules import one another without path hacks; run each from
the repository root as a module, e.g. `python -m benchmarks.work_precision --quick`.
"""

import os

import lagjax

# Measured the way the command runs: whole loop bodies as one kernel on CPU, set
# before any benchmark starts JAX. LAGJAX_PLAIN_CPU_LOOPS=1 measures XLA's default.
if not os.environ.get("LAGJAX_PLAIN_CPU_LOOPS"):
    lagjax.enable_fast_cpu_loops()
