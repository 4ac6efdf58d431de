r"""Fast chaos indicators of one orbit: MEGNO and the fast Lyapunov indicator.

Both follow one deviation vector δ(t) along the orbit by the exact tangent map
(`jax.jvp` through `lj.simulate`), renormalised every interval τ so that only its
logarithmic growth $\ell(t) = \ln\lVert\delta(t)\rVert$ ($\lVert\delta(0)\rVert = 1$)
is carried.

**MEGNO** (Cincotta & Simó 2000), the Mean Exponential Growth factor of Nearby
Orbits, weights the stretch rate by time,

$$ Y(t) = \frac{2}{t}\int_0^t \frac{\dot\delta\cdot\delta}{\lVert\delta\rVert^2}
   \,s\,ds = 2\,\ell(t) - \frac{2}{t}\int_0^t \ell(s)\,ds, \qquad
   \langle Y\rangle(t) = \frac1t \int_0^t Y(s)\,ds, $$

(the second form by parts, evaluated with the trapezoidal rule on the τ grid). For a
quasi-periodic orbit δ grows linearly (ℓ ≈ ln t) and ⟨Y⟩ → 2; for a stable periodic
(isochronous) one ⟨Y⟩ → 0; for a chaotic orbit ℓ ≈ λt and ⟨Y⟩ ≈ λt/2.

**FLI** (Froeschlé, Lega & Gonczi 1997), the fast Lyapunov indicator, is
$\mathrm{FLI}(t) = \sup_{s \le t} \ell(s)$: ~ln t on regular orbits, ~λt on
chaotic ones. The finite-time largest Lyapunov exponent ℓ(t)/t comes for free.

Every quantity is a scalar of one orbit: `jax.vmap` over a grid of initial states
maps the phase space (a MEGNO map).

**References:** Cincotta & Simó, Astron. Astrophys. Suppl. Ser. 147, 205 (2000);
Cincotta, Giordano & Simó, Physica D 182, 151 (2003); Froeschlé, Lega & Gonczi,
Celest. Mech. Dyn. Astron. 67, 41 (1997); Maffione et al., Celest. Mech. Dyn.
Astron. 111, 285 (2011) (a comparison of indicators).
"""

from __future__ import annotations

from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp

from lagjax.phase_space.flow import interval_count, phase_flow, resolve_interval


class ChaosIndicators(eqx.Module):
    """MEGNO ⟨Y⟩, the fast Lyapunov indicator and ℓ(t1)/t1 of one orbit at t1."""

    megno: jax.Array
    fli: jax.Array
    lyapunov: jax.Array


def chaos_indicators(
    system: Any,
    y0: tuple[Any, Any],
    t1: float,
    *,
    dt: float | None = None,
    solver: diffrax.AbstractSolver | None = None,
    args: Any = None,
    renormalize_every: float | None = None,
    deviation: Any = None,
    rtol: float = 1e-10,
    atol: float = 1e-10,
) -> ChaosIndicators:
    """MEGNO, FLI and the finite-time largest exponent of the orbit from `y0`.

    **Arguments:** as `lyapunov_spectrum`, and `deviation`: the initial deviation
    vector on the flat state (normalised here); default all components equal, a
    direction generic for most orbits. Vmappable over `y0` (a MEGNO map).

    **Returns:** a `ChaosIndicators` (`.megno`, `.fli`, `.lyapunov`).
    """
    flow, flat0 = phase_flow(
        system, y0, dt=dt, solver=solver, args=args, rtol=rtol, atol=atol
    )
    t1 = float(t1)
    interval = resolve_interval(renormalize_every, flow.dt, t1)
    count = interval_count(t1, interval, "renormalize_every")
    if deviation is None:
        deviation = jnp.ones_like(flat0)
    deviation = jnp.asarray(deviation, dtype=flat0.dtype)
    if deviation.shape != flat0.shape:
        raise ValueError(
            f"deviation must be a flat vector of the state's size {flat0.shape}; "
            f"got shape {deviation.shape}."
        )
    deviation = deviation / jnp.linalg.norm(deviation)

    return _follow_deviation(flow, flat0, deviation, interval, count)


@eqx.filter_jit
def _follow_deviation(flow, flat0, deviation, interval, count) -> ChaosIndicators:
    """One renormalised deviation vector along the orbit, and its indicators."""
    t1 = interval * count
    zero = jnp.zeros((), dtype=flat0.dtype)

    def advance(y):
        return flow.advance(y, interval)

    def renormalize(carry, k):
        y, direction, log_norm, log_integral, megno_integral, megno_before, fli = carry
        y, stretched = jax.jvp(advance, (y,), (direction,))
        length = jnp.linalg.norm(stretched)
        grown = log_norm + jnp.log(length)
        log_integral = log_integral + 0.5 * interval * (log_norm + grown)
        t = k * interval
        megno = 2 * grown - 2 * log_integral / t
        megno_integral = megno_integral + 0.5 * interval * (megno_before + megno)
        carry = (y, stretched / length, grown, log_integral, megno_integral, megno,
                 jnp.maximum(fli, grown))  # fmt: skip
        return carry, None

    start = (flat0, deviation, zero, zero, zero, zero, zero)
    steps = jnp.arange(1, count + 1, dtype=flat0.dtype)
    final, _ = jax.lax.scan(renormalize, start, steps)
    _, _, log_norm, _, megno_integral, _, fli = final
    return ChaosIndicators(megno=megno_integral / t1, fli=fli, lyapunov=log_norm / t1)


def megno(system: Any, y0: tuple[Any, Any], t1: float, **kwargs: Any) -> jax.Array:
    """MEGNO ⟨Y⟩(t1) of the orbit from `y0` (keywords as `chaos_indicators`)."""
    return chaos_indicators(system, y0, t1, **kwargs).megno


def fast_lyapunov_indicator(
    system: Any, y0: tuple[Any, Any], t1: float, **kwargs: Any
) -> jax.Array:
    """FLI(t1) = max over the renormalisation times of ln‖δ‖ (as `chaos_indicators`)."""
    return chaos_indicators(system, y0, t1, **kwargs).fli
