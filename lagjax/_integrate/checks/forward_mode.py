"""Forward-mode differentiation through an adaptive run: the adjoint it needs, named.

diffrax's default adjoint, `RecursiveCheckpointAdjoint`, is a `jax.custom_vjp`:
reverse mode (`jax.grad`) goes through it, forward mode (`jax.jvp`, `jax.jacfwd`,
tangent propagation for Lyapunov exponents) cannot, and JAX says only "can't apply
forward-mode autodiff (jvp) to a custom_vjp function". The fixed-step scan path
has no custom rule and differentiates both ways; the adaptive path (and any run
through `diffeqsolve`) needs `adjoint=diffrax.ForwardMode()`, which differentiates
the loop itself forward (Kidger, *On Neural Differential Equations*, 2021, §5.1:
forward-mode sensitivities).

References: Kidger, *On Neural Differential Equations*, PhD thesis, Oxford (2021),
§5.1 (forward and reverse sensitivities); the diffrax documentation of
`diffrax.ForwardMode`.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

# JAX's words (jax._src.custom_derivatives), matched to recognise the failure.
_JAX_FORWARD_MODE_TEXT = "can't apply forward-mode autodiff (jvp) to a custom_vjp"


@contextlib.contextmanager
def forward_mode_explained() -> Iterator[None]:
    """Re-raise JAX's forward-mode-through-custom_vjp `TypeError` with the remedy
    that applies to a `simulate` call; any other error passes unchanged."""
    try:
        yield
    except TypeError as error:
        if _JAX_FORWARD_MODE_TEXT not in str(error):
            raise
        raise TypeError(
            "jax.jvp / jax.jacfwd cannot go through this run: it runs through "
            "diffrax.diffeqsolve (adaptive steps, or saving/events/adjoints the "
            "fixed-step scan does not cover), whose default adjoint supports "
            "reverse mode (jax.grad) only. Pass adjoint=diffrax.ForwardMode() to "
            "simulate for forward mode (or use jax.grad / jax.jacrev)"
        ) from error
