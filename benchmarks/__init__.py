"""lagjax's benchmarks: work-precision, scaling, stability, overhead against
hand-written twins and peers.

A package so that its modules import one another without path hacks; run each from
the repository root as a module, e.g. `python -m benchmarks.work_precision --quick`.
"""
