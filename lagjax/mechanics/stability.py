r"""Spectral stability: classifying eigenvalues, and refusing points that do not rest.

Small oscillations and linearizations share two judgements.

**Stability of an eigenvalue** $\lambda$ of a linearized system
$\dot x = A x$ (a mode grows as $e^{\lambda t}$). With $s = \max_k|\lambda_k|$ the
spectrum's scale and a relative tolerance $\tau$:

- *unstable*: $\operatorname{Re}\lambda > \tau s$ (a growing solution);
- *marginal*: $|\lambda| \le \tau s$ (a zero eigenvalue: a symmetry, a conserved
  quantity, a neutral direction — linear analysis cannot decide, and solutions may
  drift linearly in time);
- *stable*: otherwise ($\operatorname{Re}\lambda \le \tau s$). For a conservative
  system this is an elliptic (purely imaginary) pair, which is *linear* (spectral)
  stability only: whether the nonlinear motion stays close is a KAM question
  (Arnold's theorem for the L4 point), not answered here.

A conservative system's spectrum is symmetric under $\lambda \to -\lambda$, so a
mode with $\operatorname{Re}\lambda < 0$ has a growing partner; `normal_modes`
therefore classifies its modes by $|\operatorname{Re}\lambda|$.

**Stationarity.** Linearizing about a point that is not an equilibrium gives
numbers that describe nothing (issue: a silent wrong result). The check converts the
residual rate $r = f(x_0)$ into the displacement it corresponds to against the
system's own rate scale $\sigma$ (a stiffness $\omega^2$ for accelerations, $\|A\|$
for first-order fields), $\delta = |r|/\sigma$, and refuses $\delta >
\text{tol}\cdot\max(|x_0|, 1)$ — a relative test for large coordinates, an absolute
one (in the units of the coordinates) near the origin.

References: Meirovitch, *Methods of Analytical Dynamics* (1970), §6.4–6.6;
Arnold, *Mathematical Methods of Classical Mechanics*, §25 and App. 7.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

STABLE, MARGINAL, UNSTABLE = 0, 1, 2
LABELS = ("stable", "marginal", "unstable")

# Relative size (to the spectrum's scale) below which a rate counts as zero. A double
# zero eigenvalue of a non-normal matrix splits by ~√eps ≈ 1.5e-8 in float64, so the
# threshold sits well above that and well below any physical rate ratio of interest.
EIGENVALUE_RTOL = 1e-6

# Default tolerance of the stationarity check (see the module docstring).
EQUILIBRIUM_TOL = 1e-8


def classify(eigenvalues: jax.Array, *, conservative: bool) -> jax.Array:
    """Stability code per eigenvalue: `STABLE`, `MARGINAL` or `UNSTABLE` (int array).

    `conservative=True` judges growth by |Re λ| (the spectrum is ±-symmetric).
    """
    eigenvalues = jnp.asarray(eigenvalues)
    size = jnp.abs(eigenvalues)
    scale = jnp.max(size, initial=0.0)
    threshold = EIGENVALUE_RTOL * scale
    rate = jnp.real(eigenvalues)
    growth = jnp.abs(rate) if conservative else rate
    # Written so that a NaN eigenvalue (or scale) lands on UNSTABLE, never STABLE.
    return jnp.where(
        size <= threshold,
        MARGINAL,
        jnp.where(growth <= threshold, STABLE, UNSTABLE),
    )


def verdict(codes: Any) -> str:
    """One word for the whole spectrum: unstable if any mode grows, else marginal if
    any is neutral, else stable. Needs concrete values (not inside `jax.jit`)."""
    worst = int(np.max(np.asarray(codes), initial=STABLE))
    return LABELS[worst]


def labels(codes: Any) -> tuple[str, ...]:
    """The stability codes as words (concrete values only)."""
    return tuple(LABELS[int(c)] for c in np.asarray(codes).ravel())


def is_concrete(*values: Any) -> bool:
    """True when no leaf is a tracer, so Python may branch on the values."""
    tracer = jax.core.Tracer  # pyright: ignore[reportAttributeAccessIssue]
    return not any(
        isinstance(leaf, tracer) for leaf in jax.tree_util.tree_leaves(values)
    )


def check_stationary(
    value: Any,
    residual: jax.Array,
    rate_scale: jax.Array,
    state: jax.Array,
    *,
    tol: float,
    what: str,
    remedy: str,
) -> Any:
    """Raise unless `residual` is negligible at `state` (see the module docstring).

    Returns `value` (with a run-time check attached when traced). `what` names the
    residual (e.g. "residual generalized force"); the message quotes its values when
    they are concrete.
    """
    size = jnp.linalg.norm(residual)
    displacement = jnp.where(size == 0, 0.0, size / rate_scale)
    allowed = tol * jnp.maximum(jnp.linalg.norm(state), 1.0)
    moving = ~(displacement <= allowed)  # NaN counts as moving
    if is_concrete(residual, rate_scale, state):
        if bool(moving):
            raise ValueError(
                f"This is not an equilibrium: the {what} is "
                f"{np.array2string(np.asarray(residual), precision=4)} (it would move "
                f"the point by about {float(displacement):.3g} in its coordinates, "
                f"more than the tolerance {float(allowed):.3g}). {remedy}"
            )
        return value
    return eqx.error_if(
        value,
        moving,
        f"This is not an equilibrium: the {what} is not zero. {remedy}",
    )
