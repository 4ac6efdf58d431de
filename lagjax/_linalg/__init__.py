"""Linear algebra and jaxpr walks that stay inside XLA's fused kernels on CPU.

Small dense solves unrolled into scalars or written as XLA loops (no LAPACK custom
call inside a step), Newton inside a step, and the rewrites of a user's function of
small arrays into scalar arithmetic (`scalarize`, `window_cumsum`).
"""
