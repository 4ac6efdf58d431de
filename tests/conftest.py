"""Test configuration: float64 everywhere, and shared comparison helpers."""

import jax

jax.config.update("jax_enable_x64", True)
