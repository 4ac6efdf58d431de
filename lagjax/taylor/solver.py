"""`Taylor`: the configuration of lagjax's Taylor-series integrator.

A Taylor method of order p advances y' = f(t, y) by the truncated series
Σ_{k≤p} yₖ hᵏ of the solution through the current point, its coefficients
computed by automatic differentiation of f's elementary operations (recurrences,
not nested derivatives). The order and the step come from the tolerance (Jorba &
Zou 2005): p = ⌈−ln(ε)/2 + 1⌉ and h from the last two coefficients, so one run
needs no tuning from tolerances of 1e-9 to 1e-16. It integrates with
`taylor_integrate`; `lj.simulate(system, y0, solver=lj.Taylor(), rtol=..., atol=...)`
routes a system's derived equations here (`lagjax._integrate.taylor_run`), by JAX
(`backend="jax"`: `jit`, `vmap`, `grad`, GPUs) or by heyoka (`backend="heyoka"`: the
derived jaxpr translated into heyoka's LLVM-compiled integrator, the fastest on one
CPU; concrete values only).

References: Jorba & Zou, Experimental Mathematics 14 (2005); Biscani & Izzo,
MNRAS 504 (2021).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx

from .integrate import TaylorSolution, check_tolerance, resolve_order, taylor_integrate


class Taylor(eqx.Module):
    """Adaptive-order Taylor integration: `rtol`, `atol` (positive; None: those
    given to `simulate`), `order` (None: from the tolerance), `max_steps`,
    `forward_mode` (True for `jax.jvp`/`jax.jacfwd` through the run, False for
    `jax.grad`), `backend` ("jax" or "heyoka"), `tile` (members per loop when
    `jax.vmap` of `simulate` runs the batch-native loop, `lagjax.taylor.batch`;
    None: 32 on a CPU, the whole batch up to 2¹⁷ on a GPU or TPU)."""

    rtol: float | None = None
    atol: float | None = None
    order: int | None = eqx.field(static=True, default=None)
    max_steps: int = eqx.field(static=True, default=1_000_000)
    forward_mode: bool = eqx.field(static=True, default=False)
    backend: str = eqx.field(static=True, default="jax")
    tile: int | None = eqx.field(static=True, default=None)

    def __check_init__(self):
        for name in ("rtol", "atol"):
            if getattr(self, name) is not None:
                check_tolerance(name, getattr(self, name))
        if self.rtol is not None and self.atol is not None:
            resolve_order(self.rtol, self.atol, self.order)
        if self.tile is not None and (not isinstance(self.tile, int) or self.tile < 1):
            raise ValueError(
                f"lagjax.Taylor: tile must be a positive int or None, got {self.tile!r}"
            )
        if self.backend not in ("jax", "heyoka"):
            raise ValueError(
                f"lagjax.Taylor: backend must be 'jax' or 'heyoka', got {self.backend!r}"
            )

    @property
    def resolved_order(self) -> int:
        """The order this configuration runs at (its tolerances must be set)."""
        return resolve_order(self.rtol, self.atol, self.order)

    def integrate(
        self,
        vector_field: Callable,
        y0: Any,
        t0: Any,
        t1: Any,
        *,
        ts: Any = None,
        args: Any = None,
    ) -> TaylorSolution:
        """`taylor_integrate` with this configuration."""
        return taylor_integrate(
            vector_field,
            y0,
            t0,
            t1,
            ts=ts,
            args=args,
            rtol=1e-15 if self.rtol is None else self.rtol,
            atol=1e-15 if self.atol is None else self.atol,
            order=self.order,
            max_steps=self.max_steps,
            forward_mode=self.forward_mode,
        )
