"""Host callbacks need JAX's CPU platform: the failure, named with its remedy.

lagjax reports what goes wrong inside a compiled run (`eqx.error_if`, diffrax's
`throw=True`) and shows progress through host callbacks (`jax.pure_callback`,
`jax.debug.callback`, `jax.experimental.io_callback`). JAX places a callback's
operands on a local CPU device, so a process started with the CPU platform left
out (`JAX_PLATFORMS=cuda`) fails there, and the message it gets instead of lagjax's
— "pure_callback failed to find a local CPU device" wrapped in a long traceback —
hides the real one (measured on an H200, JAX 0.11.2: 23 of lagjax's refusal tests
failed this way; all passed with the CPU platform kept). A run that raises nothing
never reaches a callback and is unaffected.

`JAX_PLATFORMS` unset (JAX's default) or `JAX_PLATFORMS=cuda,cpu` keeps both.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

# JAX's words (jax._src.callback), matched to recognise the failure.
_MISSING_CPU_TEXT = "failed to find a local CPU device"

MISSING_CPU_MESSAGE = (
    "this run raised an error (or reported progress) from inside its compiled code "
    "through a host callback, which needs JAX's CPU platform, and this process has "
    "none: JAX_PLATFORMS leaves 'cpu' out. Start it with JAX_PLATFORMS unset or "
    "e.g. JAX_PLATFORMS=cuda,cpu (the computation still runs on the GPU) to see "
    "the run's own message"
)


def is_missing_cpu_error(error: BaseException) -> bool:
    """Whether `error` is JAX's failure to place a host callback on a CPU."""
    return _MISSING_CPU_TEXT in str(error)


@contextlib.contextmanager
def host_callbacks_explained() -> Iterator[None]:
    """Re-raise a host callback's missing-CPU failure with its remedy; any other
    error passes unchanged."""
    try:
        yield
    except Exception as error:
        if not is_missing_cpu_error(error):
            raise
        raise RuntimeError(MISSING_CPU_MESSAGE) from error
