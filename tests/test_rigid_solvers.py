"""The Lie–Poisson splitting solvers and the projected baseline, as diffrax solvers.

Convergence order on nonlinear bodies (asymmetric free body; asymmetric heavy body
with gravity, which exercises the kicks), time reversibility, |L| and the unit
quaternion kept to round-off — for both free-body splits — the symmetric-top
split's exactness on symmetric bodies (the Earth's wobble to round-off), float32
runs, and the plumbing: diffrax's reversed-time wrapper, lagjax's fixed-step scan,
vmap and grad.
"""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax._core.precision import cast_floats
from lagjax._core.terms import RigidBodyTerm
from lagjax._integrate.fixed_step_loop import integrate_fixed_steps
from lagjax.rigid import (
    RigidBody,
    axis_angle_quaternion,
    quaternion_multiply,
    quaternion_to_matrix,
)
from lagjax.rigid.free_body import space_precession_rate, symmetric_precession_rate
from lagjax.scenes.rigid import EarthFreePrecession
from lagjax.solvers.lie_poisson import (
    QuaternionProjection,
    RigidBodyVerlet,
    RigidBodyYoshida4,
)
from tests.helpers import relative_close, tree_allclose

Q0 = axis_angle_quaternion(jnp.array([0.6, 0.0, 0.8]), 0.7)
OMEGA0 = jnp.array([0.3, 1.0, 0.2])


def gravity(rotation, t, mgl):
    # Centre of mass off every principal axis, so all three torque components act.
    return mgl * (rotation[2] @ jnp.array([0.3, -0.2, 1.0]))


FREE = RigidBody(jnp.array([1.0, 2.0, 3.0]))
HEAVY = RigidBody(jnp.array([1.0, 1.5, 0.7]), gravity)
BODIES = {"free": (FREE, None), "heavy": (HEAVY, jnp.asarray(2.0))}
SPLITS = ("symmetric-top", "axes")
SOLVERS = {"verlet": RigidBodyVerlet, "yoshida4": RigidBodyYoshida4}


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


@pytest.mark.parametrize("split", SPLITS)
@pytest.mark.parametrize("name", ["free", "heavy"])
@pytest.mark.parametrize("method", list(SOLVERS))
def test_convergence_order(method, name, split):
    body, args = BODIES[name]
    solver = SOLVERS[method](free_body=split)
    y0 = body.state_from_angular_velocity(Q0, OMEGA0)
    t1, steps = 4.0, (40, 80, 160, 320)
    reference = final_state(body, RigidBodyYoshida4(), y0, t1 / 4000, 4000, args)
    errors = [
        _error(final_state(body, solver, y0, t1 / n, n, args), reference) for n in steps
    ]
    slopes = -np.diff(np.log(errors)) / np.log(2)
    assert np.all(np.abs(slopes - solver.order(None)) < 0.2), (errors, slopes)
    assert errors[-1] > 1e-12  # above round-off, so the slopes measure truncation


@pytest.mark.parametrize("split", SPLITS)
@pytest.mark.parametrize("name", ["free", "heavy"])
@pytest.mark.parametrize("method", list(SOLVERS))
def test_time_reversible(method, name, split):
    body, args = BODIES[name]
    solver = SOLVERS[method](free_body=split)
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


@pytest.mark.parametrize("split", SPLITS)
@pytest.mark.parametrize("compensated", [True, False])
def test_invariants_to_round_off_over_long_runs(compensated, split):
    """10⁵ steps: exact rotations keep |L|, the space L and |q| to round-off. With
    Kahan compensation that round-off does not even accumulate (measured: 2e-16 after
    10⁶ steps, against a 5e-14 random walk without)."""
    tolerance = 2e-15 if compensated else 1e-13
    body = FREE
    y0 = body.state_from_angular_velocity(Q0, OMEGA0)
    solver = RigidBodyVerlet(compensated=compensated, free_body=split)
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


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
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

    @jax.jit
    def spins_and_gradient(omega):  # one compilation for the batch and the grad
        # A batch of starts in one vmapped run (here: central differences) ...
        shifts = jnp.concatenate([step * jnp.eye(3), -step * jnp.eye(3)])
        spins = jax.vmap(spin_after)(omega + shifts)
        # ... and reverse mode through the steps and the autodiff torque inside.
        return spins, jax.grad(spin_after)(omega)

    step = 1e-6
    spins, grad = spins_and_gradient(OMEGA0)
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


@pytest.mark.parametrize("split", SPLITS)
def test_orientation_stays_orthonormal_over_a_million_steps(split):
    # The bound: ‖RᵀR − I‖ ≤ 1e-12 after 10⁶ Lie–Poisson steps (heavy top,
    # so the kicks and the free rotations both act on the orientation).
    heavy, args = BODIES["heavy"]
    y0 = heavy.state_from_angular_velocity(Q0, OMEGA0)
    solver = RigidBodyVerlet(free_body=split)
    q, _ = final_state(heavy, solver, y0, 0.01, 1_000_000, args)
    rotation = quaternion_to_matrix(q)
    defect = jnp.max(jnp.abs(rotation.T @ rotation - jnp.eye(3)))
    assert float(defect) <= 1e-12


def _symmetric_top(body, y0, t):
    """The free symmetric top in closed form: Π turns in the body about e3 at
    Ω = (I1 − I3)ω3/I1 (course text eq. 4.47), and the body turns about the fixed
    L at |L|/I1 (Landau & Lifshitz §33) and about its own e3 at Ω."""
    q0, momentum0 = y0
    rate = symmetric_precession_rate(body.moments, momentum0[2] / body.moments[2])
    c, s = jnp.cos(rate * t), jnp.sin(rate * t)
    p1, p2, p3 = momentum0
    momentum = jnp.stack([c * p1 + s * p2, -s * p1 + c * p2, p3])
    space = body.angular_momentum_space(*y0)
    about_space = axis_angle_quaternion(
        space / jnp.linalg.norm(space), space_precession_rate(body.moments, space) * t
    )
    about_figure = axis_angle_quaternion(jnp.array([0.0, 0.0, 1.0]), rate * t)
    q = quaternion_multiply(quaternion_multiply(about_space, q0), about_figure)
    return q, momentum


@pytest.mark.parametrize("method", list(SOLVERS))
@pytest.mark.parametrize("moments", [(1.0, 1.0, 1.8), (2.0, 2.0, 1.0)])
def test_symmetric_top_split_is_exact_for_a_symmetric_free_body(moments, method):
    """Oblate and prolate: the drift is the exact flow, so any step (here ωh = 0.75,
    80 steps) gives the closed form to round-off; McLachlan's axes split does not."""
    body = RigidBody(jnp.array(moments))
    y0 = body.state_from_angular_velocity(Q0, jnp.array([0.4, 0.1, 3.0]))
    h, steps = 0.25, 80
    q_exact, momentum_exact = _symmetric_top(body, y0, h * steps)

    def errors(split):
        solver = SOLVERS[method](free_body=split)
        q, momentum = final_state(body, solver, y0, h, steps, None)
        rotation = quaternion_to_matrix(q) - quaternion_to_matrix(q_exact)
        momentum_error = jnp.max(jnp.abs(momentum - momentum_exact))
        return (
            float(momentum_error / jnp.linalg.norm(y0[1])),
            float(jnp.max(jnp.abs(rotation))),
        )

    assert max(errors("symmetric-top")) < 1e-12, errors("symmetric-top")
    assert min(errors("axes")) > 1e-5, errors("axes")


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_earth_wobble_period_to_round_off_at_an_hour_step():
    """Euler's 305-day free wobble with h = 1 h (ωh = 0.26): the symmetric-top split
    is the exact flow of the Earth's symmetric body; the axes split's commutator
    errors, O((ωh)²)ω, swamp the slow precession Ω = ω/305."""
    earth = EarthFreePrecession()
    t1, ts = earth.default_t1, jnp.arange(0.0, earth.default_t1, 6 * 3600.0)
    # Jitted: one compilation serves both runs, instead of ~70 op-by-op dispatches.
    compiled_checks = eqx.filter_jit(earth.checks)

    def checks(split):
        trajectory = lj.simulate(
            earth.rigid_body(), earth.initial_body_state(), t1=t1, dt=3600.0, ts=ts,
            args=earth, solver=RigidBodyYoshida4(free_body=split),
        )  # fmt: skip
        return compiled_checks(trajectory)

    exact = checks("symmetric-top")
    measured, expected = exact["wobble period (days)"]
    assert 300 < float(measured) < 310  # the run spans a period of ~304 days
    assert relative_close(measured, expected, 1e-10), (measured, expected)
    assert relative_close(*exact["wobble angle"], 1e-10)
    assert relative_close(*exact["angular momentum"], 1e-12)
    measured, expected = checks("axes")["wobble period (days)"]
    assert not relative_close(measured, expected, 1e-3), (measured, expected)


@pytest.mark.parametrize("split", SPLITS)
@pytest.mark.parametrize("name", ["free", "heavy"])
def test_float32_run_stays_float32(name, split):
    """All coefficients (rates, the isotropic turn, kicks) follow the state's dtype;
    the run agrees with float64 to float32 round-off and, free, keeps |Π| at that
    level."""
    body, args = BODIES[name]
    y0 = body.state_from_angular_velocity(Q0, OMEGA0)
    solver = RigidBodyYoshida4(free_body=split)

    def run(y, system, arguments):
        return lj.simulate(system, y, t1=1.0, dt=0.01, solver=solver, args=arguments)

    narrow = run(*cast_floats((y0, body, args), jnp.float32))
    wide = run(y0, body, args)
    assert all(leaf.dtype == jnp.float32 for leaf in jax.tree.leaves(narrow.ys))
    eps32 = float(np.finfo(np.float32).eps)
    for a, b in zip(narrow.ys, wide.ys):
        assert relative_close(a, b, 100 * eps32), float(jnp.max(jnp.abs(a - b)))
    if name == "free":
        norm = jnp.linalg.norm(narrow.ys[1][-1].astype(float))
        assert abs(norm / jnp.linalg.norm(y0[1]) - 1) < 10 * eps32


@pytest.mark.parametrize("split", SPLITS)
def test_body_at_rest_stays_at_rest_with_finite_gradients(split):
    """Π = 0: the isotropic turn's axis Π/|Π| is never formed (sinc form), so no NaN,
    in the values or in reverse mode."""
    solver, term = RigidBodyYoshida4(free_body=split), RigidBodyTerm(FREE)
    weights = jnp.array([0.0, 1.0, 2.0, 3.0])

    def final(momentum):  # three steps; a static trip count, so reverse mode goes
        y = (Q0, momentum)  # through the loop, and the step is compiled once
        state = solver.init(term, 0.0, 0.1, y, None)

        def one_step(k, carry):
            y, state = carry
            t = 0.1 * k
            y, _, _, state, _ = solver.step(term, t, t + 0.1, y, None, state, False)
            return y, state

        y = jax.lax.fori_loop(0, 3, one_step, (y, state))[0]
        return y[0] @ weights, y

    # One compilation for the values and the gradient.
    gradient, (q, momentum) = jax.jit(jax.grad(final, has_aux=True))(jnp.zeros(3))
    assert np.array_equal(q, Q0) and np.array_equal(momentum, jnp.zeros(3))
    assert np.all(np.isfinite(gradient)) and np.any(gradient != 0)


def test_unknown_free_body_split_is_refused():
    with pytest.raises(ValueError, match="free_body"):
        RigidBodyVerlet(free_body="mclachlan")
