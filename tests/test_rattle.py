"""RATTLE: order 2, symplectic on the constraint manifold, reversible, no drift."""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax._core.terms import RattleTerm
from lagjax.mechanics.constraints import Constraints
from lagjax.solvers.rattle import Rattle
from tests.helpers import relative_close

GRAVITY = 9.81


def cartesian_double_pendulum(q, qdot):
    """Two unit masses on unit rods; q = (x1, y1, x2, y2)."""
    return 0.5 * jnp.sum(qdot**2) - GRAVITY * (q[1] + q[3])


def rod_lengths(q):
    first, second = q[:2], q[2:] - q[:2]
    return jnp.stack([jnp.sum(first**2), jnp.sum(second**2)]) - 1.0


DOUBLE = lj.Lagrangian(cartesian_double_pendulum, constraints=rod_lengths)


def angle_double_pendulum(angles, rates):
    kinetic = (
        rates[0] ** 2
        + 0.5 * rates[1] ** 2
        + rates[0] * rates[1] * jnp.cos(angles[0] - angles[1])
    )
    return kinetic + GRAVITY * (2 * jnp.cos(angles[0]) + jnp.cos(angles[1]))


def to_cartesian(angles, rates):
    """(q, q̇) of the Cartesian double pendulum at angles from the downward vertical."""

    def positions(a):
        first = jnp.stack([jnp.sin(a[0]), -jnp.cos(a[0])])
        second = first + jnp.stack([jnp.sin(a[1]), -jnp.cos(a[1])])
        return jnp.concatenate([first, second])

    return jax.jvp(positions, (angles,), (rates,))


START = (jnp.array([2.0, 2.5]), jnp.array([0.3, -0.4]))
CHART = jnp.concatenate(START)


def chart(z):
    """(q, p) on the constraint manifold T*M from (θ1, θ2, θ̇1, θ̇2); M = 1 so p = q̇."""
    return to_cartesian(z[:2], z[2:])


@jax.jit
def rattle_final_state(dt):
    """RATTLE from START to t = 1 with step dt (one compile for every dt)."""
    solution = diffrax.diffeqsolve(
        RattleTerm(DOUBLE),
        Rattle(),
        0.0,
        1.0,
        dt,
        chart(CHART),
        stepsize_controller=diffrax.ConstantStepSize(),
        saveat=diffrax.SaveAt(t1=True),
        max_steps=512,
    )
    assert solution.ys is not None
    return jax.tree_util.tree_map(lambda x: x[-1], solution.ys)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_second_order_convergence_on_the_cartesian_double_pendulum():
    angles = lj.Lagrangian(angle_double_pendulum, quadratic_in_velocity=True)
    reference = lj.simulate(angles, START, t1=1.0, dt=0.002, solver=diffrax.Dopri8())
    expected_q, _ = to_cartesian(reference.q[-1], reference.qdot[-1])
    steps = np.array([0.02, 0.01, 0.005])
    errors = [
        float(jnp.max(jnp.abs(rattle_final_state(dt)[0] - expected_q))) for dt in steps
    ]
    slope = np.polyfit(np.log(steps), np.log(errors), 1)[0]
    assert abs(slope - 2.0) < 0.2


@jax.jit
def one_step(q, p, t0=0.0, t1=0.02):
    solver, term = Rattle(), RattleTerm(DOUBLE)
    state = solver.init(term, t0, t1, (q, p), None)
    (q1, p1), *_ = solver.step(term, t0, t1, (q, p), None, state, False)
    return q1, p1


def test_step_back_returns_to_start():
    q, p = chart(CHART)
    q1, p1 = one_step(q, p)
    q0, p0 = one_step(q1, p1, 0.02, 0.0)
    assert np.allclose(q0, q, atol=1e-13) and np.allclose(p0, p, atol=1e-13)
    assert float(jnp.max(jnp.abs(q1 - q))) > 1e-3  # it did move


def test_symplectic_on_the_constraint_manifold():
    """The symplectic form pulled back to the 4-dimensional manifold is preserved.

    With tangent vectors from a chart of T*M, ω(DΦ ξ, DΦ η) = ω(ξ, η) for the
    Jacobian DΦ of one step; the 8-dimensional (q, p) is not symplectic as a whole.
    """

    def form(tangents_q, tangents_p):
        return tangents_q.T @ tangents_p - tangents_p.T @ tangents_q

    tangent_q, tangent_p = jax.jacfwd(chart)(CHART)
    step_tangent_q, step_tangent_p = jax.jit(jax.jacfwd(lambda z: one_step(*chart(z))))(
        CHART
    )
    before, after = form(tangent_q, tangent_p), form(step_tangent_q, step_tangent_p)
    assert float(jnp.max(jnp.abs(before))) > 0.1
    assert float(jnp.max(jnp.abs(after - before))) < 1e-12


def _residuals(run):
    q, p = run.q[-1], run.p[-1]
    hidden = jax.jvp(rod_lengths, (q,), (p,))[1]  # ġ = G M⁻¹ p with M = 1
    return float(jnp.max(jnp.abs(rod_lengths(q)))), float(jnp.max(jnp.abs(hidden)))


@pytest.mark.parametrize(
    "steps",
    [
        pytest.param(10**5, marks=pytest.mark.integration),  # default-suite time
        pytest.param(10**6, marks=pytest.mark.slow),
    ],
    ids=["1e5", "1e6"],
)
def test_constraints_stay_at_round_off_over_many_steps(steps):
    # Round-off would show as growth with the step count: 10⁵ steps by default,
    # the full 10⁶ (500 s of chaotic motion) in the slow run.
    dt = 0.005
    run = lj.simulate(DOUBLE, chart(CHART), t1=steps * dt, dt=dt, solver=Rattle())
    position, velocity = _residuals(run)
    assert position < 1e-13 and velocity < 1e-13
    energy0 = DOUBLE.energy(*chart(CHART))
    assert relative_close(run.energy()[-1], energy0, 1e-2)  # bounded, not drifting


def test_rheonomic_constraint_bead_on_rotating_wire():
    from lagjax.scenes.rotating import BeadOnRotatingWire

    scene = BeadOnRotatingWire()
    omega, t1 = scene.angular_velocity, scene.default_t1

    def on_wire(q, t):
        return q[0] * jnp.sin(omega * t) - q[1] * jnp.cos(omega * t)

    lag = lj.Lagrangian(lambda q, qd: 0.5 * jnp.sum(qd**2), constraints=on_wire)
    r0, v0 = scene.initial_state()
    y0 = (jnp.stack([r0, 0.0]), jnp.stack([v0, omega * r0]))
    run = lj.simulate(lag, y0, t1=t1, dt=1e-3, solver=Rattle())
    q = run.q[-1]
    radius = q[0] * jnp.cos(omega * t1) + q[1] * jnp.sin(omega * t1)
    assert relative_close(radius, scene.radius(t1), 1e-5)  # O(dt²) = 1e-6 · C
    assert abs(float(on_wire(q, t1))) < 1e-15


def test_rattle_refuses_what_it_cannot_integrate():
    y0 = (jnp.array([1.0, 0.0]), jnp.zeros(2))
    rolling = lj.Lagrangian(
        lambda q, qd: 0.5 * jnp.sum(qd**2),
        constraints=Constraints(velocity=lambda q, qd: qd[0] - q[1] * qd[1]),
    )
    with pytest.raises(ValueError, match="needs a Lagrangian with holonomic"):
        lj.simulate(rolling, y0, t1=0.1, dt=0.01, solver=Rattle())
    forced = lj.Lagrangian(
        lambda q, qd: 0.5 * jnp.sum(qd**2),
        force=lambda q, qd: -qd,
        constraints=lambda q: q[0] - 1.0,
    )
    with pytest.raises(ValueError, match="generalized force"):
        lj.simulate(forced, y0, t1=0.1, dt=0.01, solver=Rattle())


def test_rattle_refuses_a_varying_mass_matrix():
    # RATTLE reads M once; a q-dependent M must be an error, not a wrong trajectory.
    lag = lj.Lagrangian(
        lambda q, v: 0.5 * (1 + q[0] ** 2) * v[0] ** 2 + 0.5 * v[1] ** 2 - q[1],
        constraints=lambda q: q[0] ** 2 + q[1] ** 2 - 1.0,
    )
    with pytest.raises(Exception, match="constant mass matrix"):
        lj.simulate(
            lag,
            (jnp.array([0.6, 0.8]), jnp.zeros(2)),
            t1=0.1,
            dt=0.01,
            solver=lj.Rattle(),
        )
