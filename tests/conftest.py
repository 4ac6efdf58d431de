"""Test configuration: float64 everywhere, and a compiler set for short programs.

The suite compiles far more than it runs (about 60 % of its CPU time is XLA's
backend compile, 10 % running the compiled code), so the tests ask XLA for its
cheap code generation (`jax_disable_most_optimizations`: LLVM at -O0, no
expensive passes). The HLO the tests inspect (fusions, loop structure) is made
by the passes before code generation and is unchanged; the arithmetic is the
same IEEE operations. Measured on three compile-heavy files: 182 → 154 s CPU.
Benchmarks, notebooks and the command run in their own processes at the default.
"""

import jax

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_disable_most_optimizations", True)
