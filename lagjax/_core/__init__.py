"""The abstractions at the bottom: the system interface, the diffrax terms that carry
a system, the solver kinds the systems dispatch on, and the small helpers they need
(working precision, batch-safe branches, static values, the CPU loop option).

Nothing here imports a concrete system or solver; those import from here.
"""
