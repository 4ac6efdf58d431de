"""Test configuration: float64 everywhere, and XLA's CPU loop option as the command
and the benchmarks set it (`lagjax.enable_fast_cpu_loops`), before JAX starts."""

import jax

import lagjax

lagjax.enable_fast_cpu_loops()
jax.config.update("jax_enable_x64", True)
