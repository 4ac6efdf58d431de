"""A host callback without JAX's CPU platform: the failure named with its remedy.

Measured on an H200 (JAX 0.11.2) with JAX_PLATFORMS=cuda: every refusal raised from
inside a compiled run arrived as "pure_callback failed to find a local CPU device"
instead of lagjax's message. This machine has no GPU, so JAX's error is reproduced
by its text (the words `lagjax._core.host_callbacks` matches).
"""

import pytest

from lagjax._core.host_callbacks import host_callbacks_explained
from lagjax.diagnostics import failure_reason

JAX_TEXT = (
    "INTERNAL: CpuCallback error calling callback: Traceback (most recent call "
    "last):\n  ...\nRuntimeError: jax.pure_callback failed to find a local CPU "
    'device to place the inputs on. Make sure "cpu" is listed in --jax_platforms'
)


def test_missing_cpu_is_named_with_the_platform_setting():
    missing_cpu = pytest.raises(RuntimeError, match=r"JAX_PLATFORMS=cuda,cpu")
    with missing_cpu as raised, host_callbacks_explained():
        raise RuntimeError(JAX_TEXT)
    assert "host callback" in str(raised.value)
    assert failure_reason(raised.value.__cause__).startswith("this run raised")


def test_other_errors_pass_unchanged():
    unchanged = pytest.raises(ValueError, match=r"^the mass matrix is singular$")
    with unchanged, host_callbacks_explained():
        raise ValueError("the mass matrix is singular")
