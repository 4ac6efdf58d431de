r"""A Taylor run that went non-finite because its series overflowed: told by name.

The k-th Taylor coefficient of a motion with time scale ρ (the radius of
convergence of its series, about 1/ω for an oscillation of angular frequency ω)
grows like $\|y_0\|\,\rho^{-k}$: at order p it passes float64's 1.8·10³⁰⁸ when
$p \log_{10}(1/\rho) + \log_{10}\|y_0\| \gtrsim 308$. A molecule in SI units
(ω ≈ 5·10¹⁴ rad/s, η ≈ 10⁻¹² m) overflows at order 21, so a tight tolerance
(order 20–30) gives inf/NaN from the first step — on lagjax's JAX route and on
heyoka alike — and the generic non-finite message would point at singular mass
matrices and collisions. Nothing here runs in the loop: after a concrete run
that went non-finite, `overflow_message` computes the series once at the last
finite state and, when its rates are finite but its coefficients are not, names
the time scale and the remedy (a time unit near ρ, or Dopri8, which never forms
ρ⁻ᵏ). Under the caller's `jit` nothing can be computed after the run, and the
Taylor run's message lists this cause among the others (`TRACED_MESSAGE`).

References: Jorba & Zou, Experimental Mathematics 14 (2005), §3.2 (the radius
of convergence from the last coefficients).
"""

from __future__ import annotations

from typing import Any

import jax
import numpy as np

from lagjax.taylor.coefficients import taylor_coefficients

TRACED_MESSAGE = (
    "lj.Taylor produced a non-finite state (inf/NaN). Besides the causes of any "
    "solver (a singular mass matrix, a collision, an infinite parameter), a "
    "Taylor series overflows float64 when the motion's time scale is far below "
    "the time unit (ω ≈ 5e14 rad/s for a molecule in seconds: order 21 passes "
    "1e308): measure time in a unit near the fastest period, or use "
    "diffrax.Dopri8(). simulate(..., throw=False) returns the trajectory up to there."
)


def last_finite_state(trajectory: Any) -> tuple[Any, np.ndarray] | None:
    """(t, flat state) of the last saved state that is finite, or None."""
    leaves = jax.tree_util.tree_leaves(trajectory.ys)
    times = np.asarray(trajectory.ts)
    rows = np.concatenate(
        [np.asarray(x).reshape(len(times), -1) for x in leaves], axis=1
    )
    kept = np.isfinite(times) & np.all(np.isfinite(rows), axis=1)
    if not kept.any():
        return None
    last = int(np.flatnonzero(kept)[-1])
    return times[last], rows[last]


def overflow_message(field: Any, t: Any, y: Any, args: Any, order: int) -> str | None:
    """The message for a non-finite Taylor run if its series at (t, y) overflows
    at `order` while the rates f(t, y) are finite; else None (another cause)."""
    y = np.asarray(y)
    rates = np.asarray(field(t, y, args))
    if not np.all(np.isfinite(rates)):
        return None
    series = np.asarray(
        taylor_coefficients(field, t, y, args, order=order, unroll=False)
    )
    sizes = np.max(np.abs(series.reshape(order + 1, -1)), axis=1)
    finite = np.isfinite(sizes)
    if finite.all():
        return None
    first_bad = int(np.flatnonzero(~finite)[0])
    scale = _time_scale(sizes[:first_bad])
    where = (
        "" if scale is None else f", time scale ρ ≈ {scale:.1e} of the run's time unit"
    )
    return (
        f"lj.Taylor produced a non-finite state: the Taylor series of the equations "
        f"overflows float64 at order {first_bad} of {order} (at t = {float(t):.6g}"
        f"{where}). Its coefficients grow like ρ⁻ᵏ, so a motion much faster "
        "than the time unit (a molecule's vibration in seconds) overflows at the "
        "orders a tight tolerance asks for. Measure time in a unit near ρ (e.g. "
        "femtoseconds for a molecule: rates and frequencies in that unit), loosen "
        "rtol/atol (a lower order), or use diffrax.Dopri8(). simulate(..., "
        "throw=False) returns the trajectory up to there."
    )


def _time_scale(sizes: np.ndarray) -> float | None:
    """ρ ≈ (‖y₀‖/‖yₖ‖)^(1/k) at the highest finite order k with ‖yₖ‖ > 0."""
    positive = np.flatnonzero(sizes[1:] > 0) + 1
    if len(positive) == 0 or sizes[0] == 0:
        return None
    k = int(positive[-1])
    return float((sizes[0] / sizes[k]) ** (1.0 / k))
