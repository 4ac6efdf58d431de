"""sin and cos in operations that XLA's CPU backend vectorizes.

XLA's CPU code calls libm for `jnp.sin` and `jnp.cos`, one call per element: a
sine over a tile of 32 members is 32 scalar calls, which the vector unit never
sees. The Taylor batch loop evaluates the sines and cosines of its graph at
every step; there they took 16 % of the run (double pendulum ×1024 to t = 10 at
tol 1e-12, `perf`, core 1). Computed here from multiplications and additions,
the run took 0.80× the time (fastest of 15 runs interleaved in one process,
core 1, the other core busy; medians 0.90×); one trajectory's, 0.98–1.02×.

The method is the classical one: Cody & Waite's reduction n = round(2x/π),
r = x − n π/2 with π/2 in parts whose products by n are exact, r kept as a
double-double r_hi + r_lo; then minimax polynomials for sin and cos on
[−π/4, π/4] in r_hi, r_lo entering to first order; the quadrant n mod 4 picks
which and the sign. Within 1 ulp of glibc (`tests/test_vector_sincos.py`). Past
|x| = 2¹⁹ π/2, where the parts' products stop being exact, a batch falls back to
`jnp.sin`/`jnp.cos` as a whole (one branch for the batch, not per element;
under `jax.vmap` the branch becomes a select and both sides run).

References: W. J. Cody and W. Waite, "Software Manual for the Elementary
Functions", Prentice-Hall (1980), ch. 8; the minimax coefficients and the
parts of π/2 as tabulated in Sun's fdlibm (1993); T. J. Dekker, Numer. Math. 18
(1971) (exact sums).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

TWO_OVER_PI = 6.36619772367581382433e-01
# π/2 ≈ PIO2[0] + PIO2[1] + PIO2[2] + PIO2[3]; the first three have 33
# significant bits, so n · PIO2[i] is exact for |n| < 2²⁰.
PIO2 = (
    1.57079632673412561417e00,
    6.07710050630396597660e-11,
    2.02226624871116645580e-21,
    8.47842766036889956997e-32,
)
# sin r = r + r³ Σ S[i] r²ⁱ,  cos r = 1 − r²/2 + r⁴ Σ C[i] r²ⁱ  on |r| ≤ π/4.
S = (-1.66666666666666324348e-01, 8.33333333332248946124e-03, -1.98412698298579493134e-04,
     2.75573137070700676789e-06, -2.50507602534068634195e-08, 1.58969099521155010221e-10)  # fmt: skip
C = (4.16666666666666019037e-02, -1.38888888888741095749e-03, 2.48015872894767294178e-05,
     -2.75573143513906633035e-07, 2.08757232129817482790e-09, -1.13596475577881948265e-11)  # fmt: skip
BOUND = 2.0**19 * 1.5707963267948966


def _horner(coefficients: tuple, z: jax.Array) -> jax.Array:
    result = jnp.full_like(z, coefficients[-1])
    for c in coefficients[-2::-1]:
        result = c + z * result
    return result


def _reduced(x: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
    """(n, r_hi, r_lo): x = n π/2 + r_hi + r_lo to ~2⁻¹⁰⁰ relative, |r| ≲ π/4."""
    n = jnp.round(x * TWO_OVER_PI)
    r = x - n * PIO2[0]  # exact (Sterbenz: x and n·PIO2[0] within a factor 2)
    w = -n * PIO2[1]
    hi = r + w  # Knuth's two-sum: hi + lo = r + w exactly
    v = hi - r
    lo = (r - (hi - v)) + (w - v)
    lo = lo - n * PIO2[2] - n * PIO2[3]  # far below r's last bit: rounding harmless
    r_hi = hi + lo
    return n, r_hi, lo - (r_hi - hi)


def _on_quadrants(x: jax.Array) -> tuple[jax.Array, jax.Array]:
    n, r, r_lo = _reduced(x)
    z = r * r
    sin = r + (r * z * _horner(S, z) + r_lo * (1.0 - 0.5 * z))
    half = 0.5 * z
    w = 1.0 - half  # 1 − z/2 with its rounding error carried (Kahan)
    cos = w + (((1.0 - w) - half) + (z * z * _horner(C, z) - r * r_lo))
    quadrant = jnp.mod(n, 4.0)
    sin_x = jnp.where(quadrant == 0, sin, jnp.where(quadrant == 1, cos, -sin))
    sin_x = jnp.where(quadrant == 3, -cos, sin_x)
    cos_x = jnp.where(quadrant == 0, cos, jnp.where(quadrant == 1, -sin, -cos))
    cos_x = jnp.where(quadrant == 3, sin, cos_x)
    return sin_x, cos_x


def sin_cos(x: jax.Array) -> tuple[jax.Array, jax.Array]:
    """(sin x, cos x) elementwise, float64, vectorizable (module docstring)."""
    x = jnp.asarray(x)
    if x.dtype != jnp.float64:
        return jnp.sin(x), jnp.cos(x)
    libm = lambda x: (jnp.sin(x), jnp.cos(x))
    return jax.lax.cond(jnp.all(jnp.abs(x) < BOUND), _on_quadrants, libm, x)
