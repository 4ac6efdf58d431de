"""A loop of a static or a traced number of steps, for the reversible adjoint.

The marks of a run saving on the step grid are uniform: every stretch between
two has the same, static, number of steps, run as a `lax.scan` unrolled as the
forward loop is (`scan_body.steps_per_trip`: Störmer–Verlet's short step would
otherwise pay the loop's own cost per step). The marks of off-grid saves lie at
the steps the save times fall in, so the stretches differ and their lengths are
traced: a `lax.fori_loop` with traced bounds (a `while_loop`, not unrolled). Both
run only in the custom VJP's forward and backward passes, which are never
differentiated themselves, so a while loop is no loss there.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax


def repeat_steps(step: Callable[[Any], Any], carry: Any, length: Any, unroll: int):
    """`step` applied `length` times to `carry`: a scan unrolled `unroll` times
    when `length` is a Python int, a fori loop when it is traced."""
    if isinstance(length, int):

        def body(carry, _):
            return step(carry), None

        return jax.lax.scan(body, carry, None, length=length, unroll=unroll)[0]
    return jax.lax.fori_loop(0, length, lambda _, carry: step(carry), carry)
