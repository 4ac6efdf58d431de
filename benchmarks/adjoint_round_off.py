r"""How exact is a float64 gradient through 10⁶ steps? The reversible adjoint, the
plain scan and forward mode against a long-double reference of the same map.

The case is `benchmarks.adjoints`' Kepler loss (e = 0.4, a loss on the final and
10 saved states, the gradient with respect to q0, p0 and μ). The reference runs the
same discrete map — the splitting's stage sizes c·h rounded to float64 as lagjax
forms them, h from `time_grid.grid_step` — in NumPy's long double (64-bit
mantissa, ε = 1.1e-19) with forward-mode tangents, so its own round-off lies ~2000×
below float64's. Every float64 gradient is then measured against it, not against
another float64 gradient:

- `scan` (JAX reverse mode through the stored trajectory: what diffrax's
  checkpointed autodiff computes too) and `scan-forward-mode` (`jax.jacfwd`, the
  tangents carried with the state through the same compensated sums): two
  "exact" float64 gradients.
- `reversible` (`checkpoint_bytes=0`: no checkpoints), `reversible-default`
  (the default budget) and `reversible-K` (`lj.ReversibleAdjoint(checkpoints=K)`):
  the states walked back by −h, restarted from the forward run's state every K
  steps.

Measured (Kepler, dt = 0.01, 10⁶ steps; relative error, max over components /
largest component):

| | Störmer–Verlet | Yoshida4 |
|---|---|---|
| scan (reverse mode) | 2.8e-10 | 1.2e-10 |
| scan, forward mode | 8.0e-12 | 7.7e-12 |
| scan, uncompensated solver | 4.4e-11 | 2.9e-10 |
| reversible, no checkpoints | 1.6e-9 | 5.9e-9 |
| reversible, K = 10⁴ | 1.8e-10 | 1.3e-9 |
| reversible, K = 10³ | 2.2e-11 | 2.2e-11 |
| reversible, K = 10² | 3.1e-12 | 6.8e-13 |
| reversible, default (`checkpoint_bytes` = 1 MiB: K = 10³ here) | 2.2e-11 | 2.2e-11 |

So the reverse-mode reference is itself 1–3e-10 from the exact gradient of its map
(the transposed Kahan sums do not compensate the cotangent, while forward mode's
tangents ride in the compensated sums): a gap below ~3e-10 between the reversible
adjoint and checkpointed autodiff cannot be certified against the latter; measure
against forward mode or this reference. The walk back itself: 10⁶ steps forth and
back return y0 to 1.2e-12 (Störmer–Verlet) and 2.3e-11 (Yoshida4), which the
shear of Kepler's flow turns into the 1e-9 gradient errors without checkpoints.

With `--bit-reversible` the run is `lj.BitReversible(solver)`'s, and the
reference linearizes the same table along that run's lattice states (its
derivative); 10⁶ steps:

| | Störmer–Verlet | Yoshida4 |
|---|---|---|
| scan (reverse mode) | 7.6e-11 | 7.8e-11 |
| scan, forward mode | 1.7e-10 | 3.0e-10 |
| reversible, no checkpoints (the default for it) | 9.8e-12 | 1.3e-11 |

The walk back is exact, so what is left is the cotangents' round-off, which its
compensated sums keep below the stored run's reverse mode.

Run: `python -m benchmarks.adjoint_round_off [--steps 1000000] [--solver Yoshida4]
[--checkpoints 10000 1000 100]` (the long-double loop takes ~1.5 min per 10⁶
Störmer–Verlet steps, ~5 min for Yoshida4); `--quick`: 10³ steps.

References: Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed.
(2006), §VIII.5 (round-off, Brouwer's law); Higham, *Accuracy and Stability of
Numerical Algorithms*, 2nd ed. (2002), §4.3 (compensated summation).
"""

from __future__ import annotations

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import lagjax as lj  # noqa: E402
from benchmarks.adjoints import (  # noqa: E402
    KEPLER,
    KEPLER_DT,
    KEPLER_START,
    kepler_loss,
)
from lagjax._integrate.time_grid import grid_step  # noqa: E402

LONG = np.longdouble


def _force_and_tangent(q, tangents, mu):
    """F = −μ q/|q|³ and its tangent along the (2, 5) tangents of q (and e_μ)."""
    x, y = q
    r2 = x * x + y * y
    inv_r3 = 1 / (r2 * np.sqrt(r2))
    inv_r5 = inv_r3 / r2
    jxx, jyy = -mu * (inv_r3 - 3 * x * x * inv_r5), -mu * (inv_r3 - 3 * y * y * inv_r5)
    jxy = 3 * mu * x * y * inv_r5
    e_mu = np.eye(5, dtype=LONG)[4]
    tx = jxx * tangents[0] + jxy * tangents[1] - x * inv_r3 * e_mu
    ty = jxy * tangents[0] + jyy * tangents[1] - y * inv_r3 * e_mu
    return np.array([-mu * x * inv_r3, -mu * y * inv_r3]), np.stack([tx, ty])


def lattice_states(steps: int, solver: lj.BitReversible) -> np.ndarray:
    """The (q, p) before every step of `kepler_loss`'s run with a `BitReversible`
    solver and after the last, as float64 (the points its steps are linearized
    at)."""
    h = grid_step(0.0, steps * KEPLER_DT, KEPLER_DT)
    y0 = (KEPLER_START[:2], KEPLER_START[2:])
    mu = jnp.asarray(1.0)
    terms, _, _ = KEPLER.integration(solver, y0, 0.0, mu)
    state = solver.init(terms, 0.0, h, y0, mu)

    @jax.jit
    def run(y, state):
        def one(carry, k):
            y, state = carry
            y1, _, _, state, _ = solver.step(
                terms, k * h, (k + 1) * h, y, mu, state, False
            )
            return (y1, state), jnp.concatenate(y)

        (last, _), before = jax.lax.scan(one, (y, state), jnp.arange(steps))
        return jnp.concatenate([before, jnp.concatenate(last)[None]])

    first = (state[0].decode_q(state[1][0]), state[0].decode_p(state[1][1]))
    return np.asarray(run(first, state))


def long_double_gradient(steps: int, solver, along=None) -> np.ndarray:
    """d loss / d(q0, p0, μ) of `kepler_loss` in long double, forward mode; with
    `along` (states before each step, `lattice_states`), the tangents of the map
    linearized at those states (a `BitReversible` run's derivative)."""
    h = grid_step(0.0, steps * KEPLER_DT, KEPLER_DT)
    kicks = (np.asarray(solver.kick_coefficients) * h).astype(LONG)
    drifts = (np.asarray(solver.drift_coefficients) * h).astype(LONG)
    every, mu = steps // 10, LONG(1.0)
    start = np.asarray(KEPLER_START, dtype=np.float64).astype(LONG)
    q, p = start[:2].copy(), start[2:].copy()
    tangent = np.eye(5, dtype=LONG)
    dq, dp = tangent[:2].copy(), tangent[2:4].copy()
    force, dforce = _force_and_tangent(q, dq, mu)
    gradient = np.zeros(5, dtype=LONG)
    for k in range(steps):
        if along is not None:
            q, p = along[k, :2].astype(LONG), along[k, 2:].astype(LONG)
            force, dforce = _force_and_tangent(q, dq, mu)
        for kick, drift in zip(kicks, drifts):
            p, dp = p + kick * force, dp + kick * dforce
            q, dq = q + drift * p, dq + drift * dp
            force, dforce = _force_and_tangent(q, dq, mu)
        p, dp = p + kicks[-1] * force, dp + kicks[-1] * dforce
        if (k + 1) % every == 0:  # the saves: Σ x + 0.1 Σ (p_x + p_y)
            gradient += dq[0] + LONG(0.1) * (dp[0] + dp[1])
    if along is not None:  # q(t1) on the lattice, as the run saves it
        q = along[steps, :2].astype(LONG)
    return gradient + 2 * q[1] * dq[1]  # + y(t1)²


def float64_gradients(steps: int, solver_name: str, checkpoints,
                      bit_reversible: bool = False) -> dict:  # fmt: skip
    solver = getattr(lj, solver_name)
    argument = jnp.concatenate([KEPLER_START, jnp.array([1.0])])
    if bit_reversible:
        lattice = lj.BitReversible(solver())
        variants = {
            "scan": (jax.grad, lattice, None),
            "scan-forward-mode": (jax.jacfwd, lattice, None),
            "reversible (no checkpoints)": (jax.grad, lattice, lj.ReversibleAdjoint()),
        }
        checkpoints = ()
    else:
        variants = {
            "scan": (jax.grad, solver(), None),
            "scan-forward-mode": (jax.jacfwd, solver(), None),
            "scan-uncompensated": (jax.grad, solver(compensated=False), None),
            "reversible": (
                jax.grad,
                solver(),
                lj.ReversibleAdjoint(checkpoint_bytes=0),
            ),
            "reversible-default": (jax.grad, solver(), lj.ReversibleAdjoint()),
        }
    for every in checkpoints:
        adjoint = lj.ReversibleAdjoint(checkpoints=every)
        variants[f"reversible-K{every}"] = (jax.grad, solver(), adjoint)
    return {
        name: np.asarray(
            jax.jit(d(lambda x, s=s, a=a: kepler_loss(x, steps, s, a)))(argument)
        )
        for name, (d, s, a) in variants.items()
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=10**6)
    parser.add_argument("--solver", default="StormerVerlet")
    parser.add_argument(
        "--checkpoints", type=int, nargs="*", default=[10**4, 10**3, 100]
    )
    parser.add_argument("--bit-reversible", action="store_true",
                        help="lj.BitReversible(solver): the reference linearizes "
                        "along its lattice states")  # fmt: skip
    parser.add_argument("--quick", action="store_true", help="CI size: 10^3 steps")
    options = parser.parse_args()
    if options.quick:
        options.steps, options.checkpoints = 1000, [100]
    start = time.perf_counter()
    method = getattr(lj, options.solver)()
    along = (
        lattice_states(options.steps, lj.BitReversible(method))
        if options.bit_reversible
        else None
    )
    reference = long_double_gradient(options.steps, method, along)
    print(f"long-double reference: {time.perf_counter() - start:.0f} s")
    scale = np.max(np.abs(reference))
    print(f"Kepler e = 0.4, {options.solver}, {options.steps} steps of {KEPLER_DT}")
    print(f"{'variant':28s} {'error vs long double':>21s} {'gap to scan':>12s}")
    gradients = float64_gradients(
        options.steps, options.solver, options.checkpoints, options.bit_reversible
    )
    for name, gradient in gradients.items():
        error = np.max(np.abs(gradient.astype(LONG) - reference)) / scale
        gap = np.max(np.abs(gradient - gradients["scan"])) / scale
        print(f"{name:28s} {float(error):21.1e} {float(gap):12.1e}")


if __name__ == "__main__":
    main()
