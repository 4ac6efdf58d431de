"""Refusing a trajectory a scene's `checks` cannot judge, instead of returning NaN.

Quantities measured from a run's saved states — a period from zero crossings, a
precession rate from a fitted slope — need the run saved densely and long enough.
From a run that saved only its final state (the default) they come out NaN, which
a caller comparing numbers would read as a failed physics check, or miss. `measured`
turns that NaN into an error that says what the check needs.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.core import Tracer


def measured(value: jax.Array, scene: Any, quantity: str, needs: str) -> jax.Array:
    """`value`, or an error naming what `quantity` needs when it came out NaN.

    Raised at once (`ValueError`) for a concrete value; under `jit` the error is
    raised when the compiled check runs (`equinox.error_if`).
    """
    message = (
        f"{type(scene).__name__}.checks cannot judge this trajectory: {quantity} "
        f"needs {needs}. Save the run densely, e.g. lj.simulate(scene, "
        "scene.initial_state(), ts=jnp.linspace(0, scene.default_t1, 2001))"
    )
    if not isinstance(value, Tracer):
        if np.any(np.isnan(np.asarray(value))):
            raise ValueError(message)
        return value
    return eqx.error_if(value, jnp.any(jnp.isnan(value)), message)
