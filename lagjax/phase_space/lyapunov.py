r"""The full Lyapunov spectrum by tangent maps and QR re-orthonormalisation.

Carry an orthonormal basis $Q_0$ of the 2n-dimensional phase space along the orbit:
over each interval $\tau$ the exact tangent map $\Phi_\tau'(y_k)$ (`jax.jvp`
through `lj.simulate`) stretches it, and a QR factorisation
$\Phi_\tau'(y_k)\,Q_k = Q_{k+1} R_{k+1}$ restores orthonormality (Benettin et al.
1980). The exponents are the mean logarithmic stretch rates of the QR diagonal,

$$ \lambda_i(t_K) = \frac{1}{t_K} \sum_{k=1}^{K} \ln |R_k|_{ii}. $$

The re-orthonormalisation keeps the columns from collapsing onto the most unstable
direction, so every exponent, not only the largest, is resolved. For a Hamiltonian
flow they come in pairs $\lambda_i = -\lambda_{2n+1-i}$ and sum to zero; with a
symplectic solver $\det \Phi'_\tau = 1$, so $\sum_i \ln |R_k|_{ii} = 0$ to
round-off at every interval. The running estimate $\lambda(t_K)$ at every
renormalisation is kept for convergence diagnostics.

**References:** Benettin, Galgani, Giorgilli & Strelcyn, Meccanica 15, 9 and 21
(1980); Shimada & Nagashima, Prog. Theor. Phys. 61, 1605 (1979); Skokos, Lect. Notes
Phys. 790, 63 (2010), "The Lyapunov characteristic exponents and their computation".
"""

from __future__ import annotations

from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp

from lagjax.phase_space.flow import interval_count, phase_flow, resolve_interval


class LyapunovSpectrum(eqx.Module):
    """The Lyapunov spectrum of one orbit and its running estimate.

    - `exponents`: the 2n exponents at t1, largest first (1/time units).
    - `ts`: the renormalisation times τ, 2τ, …, t1.
    - `running`: the estimate at each of `ts` (shape `(len(ts), 2n)`, each row
      largest first) — plot it against `ts` to judge convergence.
    - `final_state`: the flat phase-space state at t1.
    """

    exponents: jax.Array
    ts: jax.Array
    running: jax.Array
    final_state: jax.Array


def tangent_map(advance, y: jax.Array, basis: jax.Array):
    """(Φ(y), Φ'(y)·basis): the flow and the images of the basis columns."""

    def push(direction):
        return jax.jvp(advance, (y,), (direction,))

    moved, images = jax.vmap(push, in_axes=1, out_axes=(None, 1))(basis)
    return moved, images


def lyapunov_spectrum(
    system: Any,
    y0: tuple[Any, Any],
    t1: float,
    *,
    dt: float | None = None,
    solver: diffrax.AbstractSolver | None = None,
    args: Any = None,
    renormalize_every: float | None = None,
    rtol: float = 1e-10,
    atol: float = 1e-10,
    basis: jax.Array | None = None,
) -> LyapunovSpectrum:
    """The Lyapunov spectrum of the orbit from `y0` over [0, t1] (Benettin's method).

    **Arguments:**
    - `system`: an autonomous `Lagrangian`, Hamiltonian or scene.
    - `y0`: `(q0, qdot0)` for a Lagrangian, `(q0, p0)` for a Hamiltonian; the
      spectrum is that of the flow on this flat state (2n exponents).
    - `t1`: the horizon, a whole multiple of `renormalize_every`.
    - `dt`, `solver`, `args`, `rtol`, `atol`: as in `lj.simulate` (`dt` None:
      adaptive, differentiated with diffrax's `ForwardMode`).
    - `renormalize_every`: τ, a whole number of steps; default up to 10 steps
      (t1/1000 adaptive). Keep $e^{\\lambda_1\\tau}$ far below 1/ε.
    - `basis`: the initial orthonormal basis (columns); default the identity.

    **Returns:** a `LyapunovSpectrum` (`.exponents`, `.running`, `.ts`).
    """
    flow, flat0 = phase_flow(
        system, y0, dt=dt, solver=solver, args=args, rtol=rtol, atol=atol
    )
    t1 = float(t1)
    interval = resolve_interval(renormalize_every, flow.dt, t1)
    count = interval_count(t1, interval, "renormalize_every")
    size = flat0.shape[0]
    basis = jnp.eye(size, dtype=flat0.dtype) if basis is None else jnp.asarray(basis)
    if basis.shape != (size, size):
        raise ValueError(
            f"basis must be a ({size}, {size}) matrix of column vectors, one per "
            f"phase-space direction; got shape {basis.shape}."
        )
    return _benettin(flow, flat0, basis, interval, count)


@eqx.filter_jit
def _benettin(flow, flat0, basis, interval, count) -> LyapunovSpectrum:
    """The QR scan over `count` intervals (jit-compiled once per system and shape)."""
    size = flat0.shape[0]

    def advance(y):
        return flow.advance(y, interval)

    def renormalize(carry, _):
        y, frame, log_sum = carry
        y, images = tangent_map(advance, y, frame)
        frame, upper = jnp.linalg.qr(images)
        log_sum = log_sum + jnp.log(jnp.abs(jnp.diagonal(upper)))
        return (y, frame, log_sum), log_sum

    start = (flat0, basis, jnp.zeros(size, dtype=flat0.dtype))
    (final, _, _), log_sums = jax.lax.scan(renormalize, start, None, length=count)
    ts = interval * jnp.arange(1, count + 1, dtype=flat0.dtype)
    running = -jnp.sort(-log_sums / ts[:, None], axis=1)
    return LyapunovSpectrum(
        exponents=running[-1], ts=ts, running=running, final_state=final
    )
