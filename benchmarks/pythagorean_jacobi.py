r"""The Pythagorean three-body problem in Jacobi coordinates, for the extrapolated run.

In the scene's barycentric coordinates every separation is a difference
$q_i - q_j$ of positions of size 1–20, rounded to $\varepsilon|q|$: at the closest
encounters ($r_{ij} \approx 4\cdot10^{-4}$) that is a relative error of
$\varepsilon|q|/r_{ij} \approx 2500\,\varepsilon$ in the force and in the
log-Hamiltonian the time-transformed run keeps, and it sets the energy error of
`TimeTransformed(GraggBulirschStoer)` below tolerances of about 1e-13
(`benchmarks/close_encounters.py --extrapolation`). All of the problem's close
encounters are between the bodies of masses 4 and 5, so Jacobi coordinates with
that pair inside make its separation a variable of the integration:

$$\mathbf r = \mathbf q_3 - \mathbf q_2,\qquad
\mathbf R = \mathbf q_1 - \frac{m_2\mathbf q_2 + m_3\mathbf q_3}{m_2 + m_3},\qquad
H = \frac{|\mathbf P_r|^2}{2\mu_r} + \frac{|\mathbf P_R|^2}{2\mu_R}
- \frac{m_2 m_3}{r} - \frac{m_1 m_2}{|\mathbf R + \frac{m_3}{m_{23}}\mathbf r|}
- \frac{m_1 m_3}{|\mathbf R - \frac{m_2}{m_{23}}\mathbf r|},$$

with $\mu_r = m_2m_3/m_{23}$, $\mu_R = m_1m_{23}/M$, the centre of mass at rest at
the origin (G = 1). The map is a canonical point transformation, H stays separable,
and `measures` takes the states back to the scene's coordinates. A general code
chains the closest pairs as they change (Mikkola & Aarseth 1993); here one pair
suffices.

References: Mikkola & Aarseth, *An implementation of N-body chain
regularization*, Celest. Mech. 57, 439 (1993); Mikkola & Tanikawa, MNRAS 310,
745 (1999).
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

import lagjax as lj


def reduced_masses(masses: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
    """(μ_r, μ_R, m₂₃) for the inner pair (bodies 2, 3) and the outer body 1."""
    m1, m2, m3 = masses[0], masses[1], masses[2]
    inner = m2 + m3
    return m2 * m3 / inner, m1 * inner / (m1 + inner), inner


def kinetic(p: jax.Array, t: jax.Array, masses: jax.Array) -> jax.Array:
    mu_r, mu_big, _ = reduced_masses(masses)
    return p[0] @ p[0] / (2 * mu_r) + p[1] @ p[1] / (2 * mu_big)


def potential(q: jax.Array, t: jax.Array, masses: jax.Array) -> jax.Array:
    m1, m2, m3 = masses[0], masses[1], masses[2]
    _, _, inner = reduced_masses(masses)
    r, big = q[0], q[1]
    to_2, to_3 = big + (m3 / inner) * r, big - (m2 / inner) * r
    return -(
        m2 * m3 / jnp.sqrt(r @ r)
        + m1 * m2 / jnp.sqrt(to_2 @ to_2)
        + m1 * m3 / jnp.sqrt(to_3 @ to_3)
    )


JACOBI_SYSTEM = lj.SeparableHamiltonian(kinetic, potential)


def to_jacobi(q: jax.Array, masses: jax.Array) -> jax.Array:
    """Positions (3, 2) → (r, R) (2, 2)."""
    m2, m3 = masses[1], masses[2]
    centre = (m2 * q[1] + m3 * q[2]) / (m2 + m3)
    return jnp.stack([q[2] - q[1], q[0] - centre])


def from_jacobi(q: np.ndarray, p: np.ndarray, masses: np.ndarray) -> tuple:
    """(r, R), (P_r, P_R), shaped (..., 2, 2) → barycentric q, p (..., 3, 2)."""
    m1, m2, m3 = masses
    inner, total = m2 + m3, m1 + m2 + m3
    r, big, p_r, p_big = q[..., 0, :], q[..., 1, :], p[..., 0, :], p[..., 1, :]
    centre = -m1 / total * big  # of the inner pair; the barycentre at the origin
    positions = [inner / total * big, centre - m3 / inner * r, centre + m2 / inner * r]
    momenta = [p_big, -m2 / inner * p_big - p_r, -m3 / inner * p_big + p_r]
    return np.stack(positions, -2), np.stack(momenta, -2)


def jacobi_run(scene, ts: np.ndarray, solver, ds: float, jit: bool) -> Callable:
    """`run() -> (q, p)` in the scene's coordinates at the times `ts`: `simulate`
    of `JACOBI_SYSTEM` from the scene's start (at rest), eager or inside `jax.jit`."""
    masses = jnp.asarray(scene.masses)
    q0 = to_jacobi(scene.initial_state()[0], masses)
    start = (q0, jnp.zeros_like(q0))

    def go(start):
        traj = lj.simulate(JACOBI_SYSTEM, start, t1=float(ts[-1]), ts=ts, dt=ds,
                           solver=solver, args=masses)  # fmt: skip
        return traj.q, traj.p, traj.stats["num_steps"], traj.stats["num_rejected_steps"]

    go = jax.jit(go) if jit else go

    def run():
        q, p, steps, rejected = jax.block_until_ready(go(start))
        run.steps, run.rejected = int(steps), int(rejected)  # pyright: ignore
        return from_jacobi(np.asarray(q), np.asarray(p), np.asarray(masses))

    return run
