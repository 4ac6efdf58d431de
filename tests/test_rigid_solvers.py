"""The Lie–Poisson splitting solvers and the projected baseline, as diffrax solvers.

Convergence order on nonlinear bodies (asymmetric free body; asymmetric heavy body
with gravity, which exercises the kicks), time reversibility, |L| and the unit
quaternion kept to round-off, and the plumbing: diffrax's reversed-time wrapper,
lagjax's fixed-step scan, vmap and grad.
"""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lagjax.fixed_step import integrate_fixed_steps
from lagjax.rigid import (
    RigidBody,
    RigidBodyTerm,
    axis_angle_quaternion,
    quaternion_to_matrix,
)
from lagjax.solvers.rigid import (
    QuaternionProjection,
    RigidBodyVerlet,
    RigidBodyYoshida4,
)
from tests.helpers import tree_allclose

Q0 = axis_angle_quaternion(jnp.array([0.6, 0.0, 0.8]), 0.7)
OMEGA0 = jnp.array([0.3, 1.0, 0.2])


def gravity(rotation, t, mgl):
    # Centre of mass off every principal axis, so all three torque components act.
    return mgl * (rotation[2] @ jnp.array([0.3, -0.2, 1.0]))


FREE = RigidBody(jnp.array([1.0, 2.0, 3.0]))
HEAVY = RigidBody(jnp.array([1.0, 1.5, 0.7]), gravity)
BODIES = {"free": (FREE, None), "heavy": (HEAVY, jnp.asarray(2.0))}


def final_state(body, solver, y0, dt, steps, args):
    """`steps` fixed steps of size dt (dt < 0 runs backwards); one compilation per
    solver, whatever dt and steps (both traced)."""
    return _final_state(body, solver, y0, jnp.asarray(dt), jnp.asarray(steps), args)


@eqx.filter_jit
def _final_state(body, solver, y0, dt, steps, args):
    term = RigidBodyTerm(body)

    def one_step(k, carry):
        y, state = carry
        t = k * dt
        y, _, _, state, _ = solver.step(term, t, t + dt, y, args, state, False)
        return y, state

    state = solver.init(term, 0.0, dt, y0, args)
    return jax.lax.fori_loop(0, steps, one_step, (y0, state))[0]


def _error(y, reference):
    return max(float(jnp.max(jnp.abs(a - b))) for a, b in zip(y, reference))


@pytest.mark.parametrize("name", ["free", "heavy"])
@pytest.mark.parametrize(
    "solver, steps",
    [
        (RigidBodyVerlet(), (40, 80, 160, 320)),
        (RigidBodyYoshida4(), (40, 80, 160, 320)),
    ],
    ids=["verlet", "yoshida4"],
)
def test_convergence_order(name, solver, steps):
    body, args = BODIES[name]
    y0 = body.state_from_angular_velocity(Q0, OMEGA0)
    t1 = 4.0
    reference = final_state(body, RigidBodyYoshida4(), y0, t1 / 4000, 4000, args)
    errors = [
        _error(final_state(body, solver, y0, t1 / n, n, args), reference) for n in steps
    ]
    slopes = -np.diff(np.log(errors)) / np.log(2)
    assert np.all(np.abs(slopes - solver.order(None)) < 0.2), (errors, slopes)
    assert errors[-1] > 1e-12  # above round-off, so the slopes measure truncation


@pytest.mark.parametrize("name", ["free", "heavy"])
@pytest.mark.parametrize(
    "solver", [RigidBodyVerlet(), RigidBodyYoshida4()], ids=["verlet", "yoshida4"]
)
def test_time_reversible(name, solver):
    body, args = BODIES[name]
    y0 = body.state_from_angular_velocity(Q0, OMEGA0)
    forward = final_state(body, solver, y0, 0.05, 200, args)
    assert _error(forward, y0) > 0.1
    back = final_state(body, solver, forward, -0.05, 200, args)
    assert tree_allclose(back, y0, rtol=0, atol=1e-13)


def test_reversed_time_through_diffeqsolve():
    """diffrax runs t1 < t0 through a wrapped term; the solver must see physical time."""
    body, args = BODIES["heavy"]
    y0 = body.state_from_angular_velocity(Q0, OMEGA0)
    solver = RigidBodyVerlet()
    forward = final_state(body, solver, y0, 0.05, 40, args)
    solution = diffrax.diffeqsolve(
        RigidBodyTerm(body), solver, 2.0, 0.0, -0.05, forward, args=args
    )
    assert solution.ys is not None
    back = jax.tree_util.tree_map(lambda x: x[-1], solution.ys)
    assert tree_allclose(back, y0, rtol=0, atol=1e-13)


@pytest.mark.parametrize("compensated", [True, False])
def test_invariants_to_round_off_over_long_runs(compensated):
    """10⁵ steps: exact rotations keep |L|, the space L and |q| to round-off. With
    Kahan compensation that round-off does not even accumulate (measured: 2e-16 after
    10⁶ steps, against a 5e-14 random walk without)."""
    tolerance = 2e-15 if compensated else 1e-13
    body = FREE
    y0 = body.state_from_angular_velocity(Q0, OMEGA0)
    solver = RigidBodyVerlet(compensated=compensated)
    q, momentum = final_state(body, solver, y0, 0.01, 100_000, None)
    assert abs(jnp.linalg.norm(momentum) / jnp.linalg.norm(y0[1]) - 1) < tolerance
    drift = body.angular_momentum_space(q, momentum) - body.angular_momentum_space(*y0)
    assert np.max(jnp.abs(drift)) < tolerance
    assert abs(jnp.linalg.norm(q) - 1) < tolerance
    # With gravity the vertical space component of L is still exactly conserved
    # (the torque is horizontal), and the energy error stays bounded, O(h²).
    heavy, args = BODIES["heavy"]
    q, momentum = final_state(heavy, solver, y0, 0.01, 100_000, args)
    vertical = heavy.angular_momentum_space(q, momentum)[2]
    assert abs(vertical - heavy.angular_momentum_space(*y0)[2]) < 10 * tolerance
    energy = heavy(q, momentum, 0.0, args)
    assert abs(energy / heavy(*y0, 0.0, args) - 1) < 1e-3


def test_projection_keeps_the_quaternion_unit():
    body = FREE
    y0 = body.state_from_angular_velocity(Q0, OMEGA0)

    def norm_drift(solver):
        solution = diffrax.diffeqsolve(
            RigidBodyTerm(body),
            solver,
            0.0,
            50.0,
            None,
            y0,
            stepsize_controller=diffrax.PIDController(rtol=1e-5, atol=1e-5),
        )
        assert solution.ys is not None
        return abs(float(jnp.linalg.norm(solution.ys[0][-1])) - 1)

    assert norm_drift(diffrax.Tsit5()) > 1e-7
    assert norm_drift(QuaternionProjection(diffrax.Tsit5())) < 1e-15
    assert isinstance(
        QuaternionProjection(diffrax.Tsit5()), diffrax.AbstractAdaptiveSolver
    )
    assert not isinstance(
        QuaternionProjection(diffrax.Euler()), diffrax.AbstractAdaptiveSolver
    )


def test_simulate_scan_path_vmap_and_grad():
    body, args = BODIES["heavy"]
    solver = RigidBodyVerlet(compensated=False)  # compiles fastest under grad

    def final(omega):  # the loop simulate uses for fixed steps, unchanged solvers
        y = body.state_from_angular_velocity(Q0, omega)
        return integrate_fixed_steps(
            RigidBodyTerm(body), solver, 0.0, 1.0, 0.01, y, args
        )

    y1, result, steps = final(OMEGA0)
    assert result == diffrax.RESULTS.successful and steps == 100
    expected = final_state(
        body, solver, body.state_from_angular_velocity(Q0, OMEGA0), 0.01, 100, args
    )
    assert tree_allclose(y1, expected, atol=1e-14)

    def spin_after(omega):
        return final(omega)[0][1][2]

    # A batch of starts in one vmapped run (here: central differences) ...
    step = 1e-6
    shifts = jnp.concatenate([step * jnp.eye(3), -step * jnp.eye(3)])
    spins = jax.vmap(spin_after)(OMEGA0 + shifts)
    # ... and reverse mode through the steps and the autodiff torque inside them.
    grad = jax.grad(spin_after)(OMEGA0)
    assert np.allclose(grad, (spins[:3] - spins[3:]) / (2 * step), rtol=1e-6)


def test_wrong_term_is_refused():
    with pytest.raises(ValueError):
        diffrax.diffeqsolve(
            diffrax.ODETerm(lambda t, y, args: y),
            RigidBodyVerlet(),
            0.0,
            1.0,
            0.1,
            (Q0, OMEGA0),
        )


def test_orientation_stays_orthonormal_over_a_million_steps():
    # The bound: ‖RᵀR − I‖ ≤ 1e-12 after 10⁶ Lie–Poisson steps (heavy top,
    # so the kicks and the free rotations both act on the orientation).
    heavy, args = BODIES["heavy"]
    y0 = heavy.state_from_angular_velocity(Q0, OMEGA0)
    q, _ = final_state(heavy, RigidBodyVerlet(), y0, 0.01, 1_000_000, args)
    rotation = quaternion_to_matrix(q)
    defect = jnp.max(jnp.abs(rotation.T @ rotation - jnp.eye(3)))
    assert float(defect) <= 1e-12
