"""The torque-free rigid body: precession, the Dzhanibekov flip, Poinsot.

Physics is the oracle: the course text's precession rate Ω = (I1 − I3) ω3 / I1
(eq. 4.47–4.52), the space cone rate |L|/I1, the elliptic-integral period of the
asymmetric body (Landau & Lifshitz §37), and Poinsot's construction (course text
§4.8.1). Runs: an adaptive Tsit5 with quaternion projection at tight tolerance, and
the Lie–Poisson splittings.
"""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lagjax._core.terms import RigidBodyTerm
from lagjax.rigid import (
    RigidBody,
    axis_angle_quaternion,
    quaternion_to_matrix,
)
from lagjax.rigid.free_body import (
    free_body_period,
    invariable_plane_distance,
    space_precession_rate,
    symmetric_precession_rate,
)
from lagjax.solvers.lie_poisson import (
    QuaternionProjection,
    RigidBodyVerlet,
    RigidBodyYoshida4,
)
from lagjax.special_functions import (
    complete_elliptic_k,
    complete_elliptic_k_from_complement,
)

SAMPLES = 2001
Q0 = axis_angle_quaternion(jnp.array([0.6, 0.0, 0.8]), 0.7)


@eqx.filter_jit
def adaptive_run(body, y0, t1):
    """Tsit5 + projection at rtol = atol = 1e-12, saved at SAMPLES equal times."""
    ts = jnp.linspace(0.0, t1, SAMPLES)
    solution = diffrax.diffeqsolve(
        RigidBodyTerm(body),
        QuaternionProjection(diffrax.Tsit5()),
        0.0,
        t1,
        None,
        y0,
        saveat=diffrax.SaveAt(ts=ts),
        stepsize_controller=diffrax.PIDController(rtol=1e-12, atol=1e-12),
        max_steps=200_000,
    )
    return ts, solution.ys


@eqx.filter_jit
def fixed_run(body, solver, y0, dt, steps_per_sample):
    """SAMPLES states of a fixed-step run, one every `steps_per_sample` steps."""
    term = RigidBodyTerm(body)

    def one_step(carry, _):
        t, y, state = carry
        y, _, _, state, _ = solver.step(term, t, t + dt, y, None, state, False)
        return (t + dt, y, state), None

    def one_sample(carry, _):
        carry, _ = jax.lax.scan(one_step, carry, None, length=steps_per_sample)
        return carry, carry[1]

    state = solver.init(term, 0.0, dt, y0, None)
    start = (jnp.zeros_like(dt), y0, state)
    _, ys = jax.lax.scan(one_sample, start, None, length=SAMPLES - 1)
    ys = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a[None], b]), y0, ys)
    return dt * steps_per_sample * jnp.arange(SAMPLES), ys


def test_complete_elliptic_k_by_agm():
    assert np.isclose(complete_elliptic_k(0.0), np.pi / 2, rtol=1e-15)
    # Abramowitz & Stegun Table 17.1: K(1/2) = 1.85407 46773 01372.
    assert np.isclose(complete_elliptic_k(0.5), 1.8540746773013719, rtol=1e-15)
    # Against Gauss–Legendre quadrature of the defining integral.
    nodes, weights = np.polynomial.legendre.leggauss(200)
    phis = np.pi / 4 * (nodes + 1)
    for m in (0.3, 0.9, 0.99):
        integral = np.pi / 4 * np.sum(weights / np.sqrt(1 - m * np.sin(phis) ** 2))
        assert np.isclose(complete_elliptic_k(m), integral, rtol=1e-13)
    # Logarithmic limit at the separatrix, from the complementary parameter k'²:
    # K = ln(4/k') + (k'²/4)(ln(4/k') − 1) + O(k'⁴ ln k').
    k_prime = 1e-6
    log_term = np.log(4 / k_prime)
    near_one = complete_elliptic_k_from_complement(k_prime**2)
    assert np.isclose(near_one, log_term + k_prime**2 / 4 * (log_term - 1), rtol=1e-15)
    assert np.allclose(
        jax.vmap(complete_elliptic_k)(jnp.array([0.0, 0.5])),
        [np.pi / 2, 1.8540746773013719],
    )


def _unwrapped_angle(x, y):
    return np.unwrap(np.arctan2(np.asarray(y), np.asarray(x)))


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
@pytest.mark.parametrize(
    "moments", [(2.0, 2.0, 1.0), (1.0, 1.0, 1.8)], ids=["prolate", "oblate"]
)
def test_symmetric_body_precesses_at_the_course_rate(moments):
    body = RigidBody(jnp.array(moments))
    y0 = body.state_from_angular_velocity(Q0, jnp.array([0.4, 0.1, 3.0]))
    ts, (q, momentum) = adaptive_run(body, y0, jnp.asarray(20.0))
    omega = momentum / body.moments
    # Body cone: (ω1, ω2) turns about e3 at −Ω (ω̇1 = Ω ω2, ω̇2 = −Ω ω1).
    phase = _unwrapped_angle(omega[:, 0], omega[:, 1])
    rate = -(phase[-1] - phase[0]) / ts[-1]
    expected = symmetric_precession_rate(body.moments, omega[0, 2])
    assert abs(rate / expected - 1) < 1e-8
    cone = omega[:, 2] / jnp.linalg.norm(omega, axis=1)
    assert np.ptp(cone) < 1e-10
    # ω and L keep their angle (both body components; L = I ω).
    cosine = (
        jnp.sum(omega * momentum, 1)
        / jnp.linalg.norm(omega, axis=1)
        / jnp.linalg.norm(momentum, axis=1)
    )
    assert np.ptp(cosine) < 1e-10
    # Space cone: the symmetry axis turns about the fixed L at |L|/I1.
    space_momentum = jax.vmap(body.angular_momentum_space)(q, momentum)
    direction = space_momentum[0] / jnp.linalg.norm(space_momentum[0])
    across = jnp.cross(direction, jnp.array([1.0, 0.0, 0.0]))
    across = across / jnp.linalg.norm(across)
    symmetry_axis = quaternion_to_matrix(q)[:, :, 2]
    space_phase = _unwrapped_angle(
        symmetry_axis @ across, symmetry_axis @ jnp.cross(direction, across)
    )
    space_rate = (space_phase[-1] - space_phase[0]) / ts[-1]
    assert (
        abs(space_rate / space_precession_rate(body.moments, space_momentum[0]) - 1)
        < 1e-8
    )
    assert np.ptp(symmetry_axis @ direction) < 1e-10
    assert np.max(jnp.abs(space_momentum - space_momentum[0])) < 1e-10


def _flip_times(ts, component):
    """Zero crossings of a sampled signal: the root of the cubic through the four
    samples around each sign change (a straight line would be off by ~1e-6 here)."""
    ts, component = np.asarray(ts), np.asarray(component)
    index = np.nonzero(np.sign(component[1:]) != np.sign(component[:-1]))[0]
    roots = []
    for i in index:
        window = slice(i - 1, i + 3)
        cubic = np.polyfit(ts[window] - ts[i], component[window], 3)
        candidates = np.roots(cubic)
        real = candidates[np.abs(candidates.imag) < 1e-12].real
        inside = real[(real >= 0) & (real <= ts[i + 1] - ts[i])]
        roots.append(ts[i] + inside[0])
    return np.array(roots)


ASYMMETRIC = jnp.array([1.0, 2.0, 3.0])
NEAR_INTERMEDIATE = jnp.array([1e-3, 1.0, 1e-3])


@pytest.mark.parametrize(
    "method",
    [pytest.param("adaptive", marks=pytest.mark.integration), "yoshida4"],
)  # the adaptive run in CI's integration step (default-suite time)
def test_dzhanibekov_flip_period_is_the_elliptic_value(method):
    body = RigidBody(ASYMMETRIC)
    y0 = body.state_from_angular_velocity(
        jnp.array([1.0, 0.0, 0.0, 0.0]), NEAR_INTERMEDIATE
    )
    if method == "adaptive":
        ts, (_, momentum) = adaptive_run(body, y0, jnp.asarray(80.0))
    else:
        ts, (_, momentum) = fixed_run(
            body, RigidBodyYoshida4(), y0, jnp.asarray(0.01), 4
        )
    flips = _flip_times(ts, momentum[:, 1])
    assert len(flips) == 3  # held for ~27 s, then turned over within ~2 s, each time
    period = free_body_period(
        body.moments, body.kinetic_energy(y0[1]), jnp.sum(y0[1] ** 2)
    )
    # The intermediate component changes sign twice per period of ω.
    assert np.allclose(np.diff(flips) / (period / 2), 1.0, rtol=1e-8, atol=0)
    # Between flips it is (almost) fully reversed.
    assert np.min(momentum[:, 1]) < -0.99 * y0[1][1]


@pytest.mark.parametrize("axis", [0, 2], ids=["smallest", "largest"])
def test_rotation_about_the_extreme_axes_is_stable(axis):
    body = RigidBody(ASYMMETRIC)
    omega0 = jnp.full(3, 1e-3).at[axis].set(1.0)
    y0 = body.state_from_angular_velocity(jnp.array([1.0, 0.0, 0.0, 0.0]), omega0)
    _, (_, momentum) = fixed_run(body, RigidBodyVerlet(), y0, jnp.asarray(0.01), 4)
    omega = momentum / body.moments
    transverse = jnp.delete(omega, axis, axis=1)
    # Over 80 s (the intermediate axis flips three times in that span) the
    # perturbation only circles: it stays of its initial size, the spin keeps its sign.
    assert np.max(jnp.abs(transverse)) < 5e-3
    assert np.min(omega[:, axis]) > 0.99


def test_lie_poisson_conservation_on_an_asymmetric_body():
    body = RigidBody(ASYMMETRIC)
    y0 = body.state_from_angular_velocity(Q0, jnp.array([0.3, 1.0, 0.2]))
    _, (q, momentum) = fixed_run(body, RigidBodyVerlet(), y0, jnp.asarray(0.01), 10)
    # |L| and the space L to round-off over 2·10⁴ steps of exact rotations.
    norms = jnp.linalg.norm(momentum, axis=1)
    assert np.max(jnp.abs(norms / norms[0] - 1)) < 5e-15
    space = jax.vmap(body.angular_momentum_space)(q, momentum)
    assert np.max(jnp.abs(space - space[0])) < 5e-14
    assert np.max(jnp.abs(jnp.linalg.norm(q, axis=1) - 1)) < 5e-15
    # Energy: an O(h²) oscillation that does not drift (first half ≈ second half).
    energy = jax.vmap(body.kinetic_energy)(momentum)
    error = jnp.abs(energy / energy[0] - 1)
    half = SAMPLES // 2
    assert 1e-7 < np.max(error) < 1e-4
    assert np.max(error[half:]) < 1.5 * np.max(error[:half])


def test_poinsot_construction():
    body = RigidBody(ASYMMETRIC)
    y0 = body.state_from_angular_velocity(Q0, jnp.array([0.3, 1.0, 0.2]))
    _, (q, momentum) = adaptive_run(body, y0, jnp.asarray(20.0))
    energy0 = body.kinetic_energy(y0[1])
    space_momentum0 = body.angular_momentum_space(*y0)
    rho = (momentum / body.moments) / jnp.sqrt(2 * energy0)
    # ρ stays on the inertia ellipsoid ρᵀ I ρ = 1 ...
    assert np.max(jnp.abs(jnp.sum(body.moments * rho**2, axis=1) - 1)) < 1e-10
    # ... whose tangent plane there, normal to the fixed L, is the invariable plane
    # at the constant distance √(2T)/|L| from the fixed point.
    rho_space = jnp.einsum("tij,tj->ti", quaternion_to_matrix(q), rho)
    distance = rho_space @ (space_momentum0 / jnp.linalg.norm(space_momentum0))
    expected = invariable_plane_distance(energy0, space_momentum0)
    assert np.max(jnp.abs(distance - expected)) < 1e-10
    assert np.ptp(jnp.linalg.norm(rho_space, axis=1)) > 0.05  # ρ itself does move
