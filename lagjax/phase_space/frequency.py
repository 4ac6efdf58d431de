r"""Fundamental frequencies of a sampled signal: Laskar's frequency analysis (NAFF).

A quasi-periodic signal $f(t) = \sum_k a_k e^{i\omega_k t}$ sampled on
$[0, T]$ is decomposed term by term. The windowed inner product

$$ \langle f, e^{i\omega t}\rangle = \frac1T \int_0^T f(t)\,\chi(t)\,
   e^{-i\omega t}\,dt, \qquad \chi(t) = 1 - \cos(2\pi t/T) $$

(the Hann window, mean 1) is largest near a frequency of the signal: its FFT gives
the peak to one bin, and the maximum of $|\langle f, e^{i\omega t}\rangle|^2$ is
then found to round-off as the zero of its derivative (bisection on
`jax.grad`, inside ±1 bin, where the Hann main lobe is two bins wide). With the Hann
window the frequency error falls as $T^{-4}$ instead of the plain FFT's $T^{-1}$.
The amplitudes of all terms found so far are fitted together (least squares in the
windowed inner product, Laskar's Gram–Schmidt step) and removed before the next
term is sought; at the end each frequency is refined once more on the signal with
all the other terms removed. A real signal is analysed as one: each term is a pair
$a e^{i\omega t} + \bar a e^{-i\omega t}$ with ω > 0 (its power is that of the
projection on cos ωt and sin ωt together, so the mirror term does not pull the
peak), and its mean is removed first.

**References:** Laskar, Icarus 88, 266 (1990); Laskar, Froeschlé & Celletti,
Physica D 56, 253 (1992); Laskar, "Frequency map analysis and quasiperiodic
decompositions", in *Hamiltonian Systems and Fourier Analysis* (2005).
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

_BISECTIONS = 60  # halves a two-bin bracket to below round-off


class Frequencies(eqx.Module):
    """The terms a e^{iωt} of a signal, strongest first.

    - `omegas`: angular frequencies (rad per time unit; > 0 for a real signal).
    - `amplitudes`: complex a; a real signal's term is a e^{iωt} + conj, i.e.
      2|a| cos(ωt + arg a).
    """

    omegas: jax.Array
    amplitudes: jax.Array


def _weights(count: int, dtype) -> jax.Array:
    """Trapezoid weights times the Hann window, normalised to sum to 1."""
    phase = 2 * jnp.pi * jnp.arange(count, dtype=dtype) / (count - 1)
    weights = (1 - jnp.cos(phase)).at[0].multiply(0.5).at[-1].multiply(0.5)
    return weights / jnp.sum(weights)


def _basis(omegas: jax.Array, times: jax.Array, real: bool) -> jax.Array:
    """Columns e^{iωt} (and e^{-iωt} and the constant for a real signal)."""
    columns = jnp.exp(1j * times[:, None] * omegas[None, :])
    if real:
        constant = jnp.ones((times.shape[0], 1), dtype=columns.dtype)
        columns = jnp.concatenate([constant, columns, jnp.conj(columns)], axis=1)
    return columns


def _fit(signal, times, weights, omegas, real):
    """Amplitudes of the basis columns by weighted least squares, and the residual."""
    basis = _basis(omegas, times, real)
    if basis.shape[1] == 0:
        return jnp.zeros((0,), dtype=signal.dtype), signal
    gram = jnp.einsum("t,ti,tj->ij", weights, jnp.conj(basis), basis)
    projections = jnp.einsum("t,ti,t->i", weights, jnp.conj(basis), signal)
    amplitudes = jnp.linalg.solve(gram, projections)
    residual = signal - basis @ amplitudes
    return amplitudes, jnp.real(residual) if real else residual


def _power(signal, times, weights, omega, real):
    """The windowed energy of `signal` along e^{iωt} (real: along cos ωt, sin ωt)."""
    if not real:
        return jnp.abs(jnp.sum(weights * signal * jnp.exp(-1j * omega * times))) ** 2
    # The term's mirror image e^{-iωt} is part of it: project on the pair.
    pair = jnp.stack([jnp.cos(omega * times), jnp.sin(omega * times)], axis=1)
    gram = jnp.einsum("t,ti,tj->ij", weights, pair, pair)
    projections = jnp.einsum("t,ti,t->i", weights, pair, signal)
    return jnp.real(jnp.vdot(projections, jnp.linalg.solve(gram, projections)))


def _refine(residual, times, weights, guess, spacing, real):
    """The maximum of the windowed power within one bin of `guess`."""
    slope = jax.grad(lambda omega: _power(residual, times, weights, omega, real))

    def halve(_, bracket):
        low, high = bracket
        middle = 0.5 * (low + high)
        rising = slope(middle) > 0
        return jnp.where(rising, middle, low), jnp.where(rising, high, middle)

    low, high = jax.lax.fori_loop(
        0, _BISECTIONS, halve, (guess - spacing, guess + spacing)
    )
    return 0.5 * (low + high)


def _peak(residual, weights, spacing, real):
    """The FFT bin of the windowed residual's largest term, as an angular frequency."""
    count = residual.shape[0]
    spectrum = jnp.abs(jnp.fft.fft(residual * weights))
    bins = jnp.fft.fftfreq(count) * count
    if real:
        spectrum = jnp.where(bins > 0, spectrum, 0.0)
    return bins[jnp.argmax(spectrum)] * spacing


def _concrete(x: jax.Array) -> bool:
    try:
        np.asarray(x)
    except jax.errors.TracerArrayConversionError:
        return False
    return True


def fundamental_frequencies(
    ts: jax.Array, signal: jax.Array, terms: int = 1
) -> Frequencies:
    """The `terms` strongest frequencies of `signal` sampled at equally spaced `ts`.

    **Arguments:**
    - `ts`: equally spaced sample times (e.g. `traj.ts` of a run saved on a grid).
    - `signal`: real or complex samples, e.g. `traj.q`, or `q - 1j * p`, which
      turns clockwise in the (q, p) plane as an oscillator does, so that its
      leading frequency is positive.
    - `terms`: how many frequencies to extract, strongest first.

    A frequency is resolved once T spans several of its periods; two terms need to
    differ by more than a couple of bins, 2π/T. Under `jit` `terms` is static.

    **Returns:** `Frequencies` (`.omegas`, `.amplitudes`).
    """
    ts, signal = jnp.asarray(ts), jnp.asarray(signal)
    if ts.ndim != 1 or signal.shape != ts.shape or ts.shape[0] < 8:
        raise ValueError(
            "ts and signal must be 1-D arrays of the same length (at least 8 "
            f"samples); got shapes {ts.shape} and {signal.shape}. Analyse one "
            "coordinate at a time."
        )
    if terms < 1:
        raise ValueError(f"terms must be at least 1, got {terms}")
    if _concrete(ts):
        steps = np.diff(np.asarray(ts))
        if np.ptp(steps) > 1e-6 * np.abs(steps).mean():
            raise ValueError("ts must be equally spaced (save on a uniform grid).")
    return _analyse(ts, signal, terms)


@functools.partial(jax.jit, static_argnums=2)
def _analyse(ts: jax.Array, signal: jax.Array, terms: int) -> Frequencies:
    real = not jnp.iscomplexobj(signal)
    times = ts - ts[0]
    duration = times[-1]
    weights = _weights(ts.shape[0], times.dtype)
    spacing = 2 * jnp.pi / (duration * ts.shape[0] / (ts.shape[0] - 1))
    omegas = jnp.zeros((0,), dtype=times.dtype)
    _, residual = _fit(signal, times, weights, omegas, real)  # the mean, if real
    for _ in range(terms):
        guess = _peak(residual, weights, spacing, real)
        omega = _refine(residual, times, weights, guess, spacing, real)
        omegas = jnp.append(omegas, omega)
        amplitudes, residual = _fit(signal, times, weights, omegas, real)
    # Each term again, with every other term removed: no leakage from the others.
    for index in range(terms):
        others = jnp.delete(omegas, index)
        _, alone = _fit(signal, times, weights, others, real)
        omega = _refine(alone, times, weights, omegas[index], spacing, real)
        omegas = omegas.at[index].set(omega)
    amplitudes, _ = _fit(signal, times, weights, omegas, real)
    if real:
        amplitudes = amplitudes[1 : 1 + terms]
    return Frequencies(omegas=omegas, amplitudes=amplitudes)
