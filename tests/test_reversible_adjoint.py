"""ReversibleAdjoint: reverse mode through fixed-step runs by stepping back with −h.

The oracle is the discrete map itself: Störmer–Verlet on the harmonic oscillator
is one 2×2 matrix per step, so the gradient of q_N is a row of Mᴺ and its
derivative in the stiffness a sum of matrix products; for every reversible solver
family the gradient agrees with the plain scan's (which stores every step) to
round-off; on a nonlinear pendulum with finite differences; saved states feed
their cotangents in at their times; round-off of the walk back in float32 is
bounded by checkpoints; non-reversible solvers are refused by name.
"""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.rigid import RigidBody, axis_angle_quaternion


def _relative_gap(a, b) -> float:
    a, b = jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)
    scale = max(float(jnp.max(jnp.abs(x))) for x in b)
    return max(float(jnp.max(jnp.abs(x - y))) for x, y in zip(a, b)) / scale


OSCILLATOR = lj.SeparableHamiltonian(
    lambda p: 0.5 * p**2, lambda q, t, k: 0.5 * k * q**2
)


def _verlet_matrix(h: float, k: float) -> np.ndarray:
    """One Störmer–Verlet step of q̈ = −k q as a matrix on (q, p)."""
    kick = np.array([[1.0, 0.0], [-0.5 * h * k, 1.0]])
    drift = np.array([[1.0, h], [0.0, 1.0]])
    return kick @ drift @ kick


def test_stormer_verlet_gradient_is_the_discrete_one_in_closed_form():
    h, k, steps = 0.01, 1.3, 1000
    y0, stiffness = (jnp.asarray(0.4), jnp.asarray(-0.2)), jnp.asarray(k)

    def final_q(y0, stiffness):
        run = lj.simulate(OSCILLATOR, y0, t1=steps * h, dt=h, args=stiffness,
                          solver=lj.StormerVerlet(), adjoint=lj.ReversibleAdjoint())  # fmt: skip
        return run.q[-1]

    grad_y0, grad_k = jax.grad(final_q, argnums=(0, 1))(y0, stiffness)
    step = _verlet_matrix(h, k)
    power = np.linalg.matrix_power(step, steps)
    # d(Mᴺ)/dk = Σⱼ Mʲ (dM/dk) Mᴺ⁻¹⁻ʲ, dM/dk from the exact product rule.
    kick = np.array([[1.0, 0.0], [-0.5 * h * k, 1.0]])
    drift = np.array([[1.0, h], [0.0, 1.0]])
    dkick = np.array([[0.0, 0.0], [-0.5 * h, 0.0]])
    dstep = dkick @ drift @ kick + kick @ drift @ dkick
    powers = [np.eye(2)]
    for _ in range(steps):
        powers.append(powers[-1] @ step)
    dpower = sum(powers[j] @ dstep @ powers[steps - 1 - j] for j in range(steps))
    start = np.array([0.4, -0.2])
    np.testing.assert_allclose([grad_y0[0], grad_y0[1]], power[0], rtol=0, atol=1e-12)
    assert abs(float(grad_k) - (dpower @ start)[0]) < 1e-12 * np.abs(dpower).max()


def _kepler():
    def potential(q, t, mu):
        return -mu / jnp.sqrt(jnp.sum(q**2))

    system = lj.SeparableHamiltonian(lambda p: 0.5 * jnp.sum(p**2), potential)
    y0 = (jnp.array([1.0, 0.0]), jnp.array([0.0, 1.2]))
    return system, y0, jnp.asarray(1.0)


def _pendulum_hamiltonian():
    system = lj.Hamiltonian(lambda q, p, t, g: 0.5 * p**2 - g * jnp.cos(q))
    return system, (jnp.asarray(1.0), jnp.asarray(0.2)), jnp.asarray(9.81)


def _pendulum_lagrangian():
    system = lj.Lagrangian(lambda q, qd, t, g: 0.5 * qd**2 + g * jnp.cos(q))
    return system, (jnp.asarray(1.0), jnp.asarray(0.2)), jnp.asarray(9.81)


def _rod(q):
    return jnp.sum(q**2, keepdims=True) - 1.0


def _cartesian_pendulum():
    system = lj.Lagrangian(
        lambda q, qd, t, g: 0.5 * jnp.sum(qd**2) - g * q[1], constraints=_rod
    )
    angle = 0.8
    q0 = jnp.array([jnp.sin(angle), -jnp.cos(angle)])
    return system, (q0, 0.3 * jnp.array([jnp.cos(angle), jnp.sin(angle)])), 9.81


def _heavy_top():
    def gravity(rotation, t, mgl):
        return mgl * (rotation[2] @ jnp.array([0.3, -0.2, 1.0]))

    body = RigidBody(jnp.array([1.0, 1.5, 0.7]), gravity)
    q0 = axis_angle_quaternion(jnp.array([0.6, 0.0, 0.8]), 0.7)
    y0 = body.state_from_angular_velocity(q0, jnp.array([0.3, 1.0, 0.2]))
    return body, y0, jnp.asarray(2.0)


FAMILIES = {
    "Yoshida4": (_kepler, lj.Yoshida4(), 0.01),
    "BlanesMoan4-plain-sum": (_kepler, lj.BlanesMoan4(compensated=False), 0.01),
    "GaussLegendre": (_pendulum_hamiltonian, lj.GaussLegendre(stages=2), 0.01),
    "ImplicitMidpoint": (_pendulum_hamiltonian, lj.ImplicitMidpoint(), 0.01),
    "VariationalMidpoint": (_pendulum_lagrangian, lj.VariationalMidpoint(), 0.01),
    "Rattle": (_cartesian_pendulum, lj.Rattle(), 0.005),
    "RigidBodyYoshida4": (_heavy_top, lj.RigidBodyYoshida4(), 0.01),
}


def _loss(system, solver, dt, steps, adjoint, ts=None):
    def loss(y0, args):
        run = lj.simulate(system, y0, t1=steps * dt, dt=dt, solver=solver, ts=ts,
                          args=args, adjoint=adjoint)  # fmt: skip
        # Both halves of the state, weighted unevenly, and a parameter term.
        return jnp.sum(jnp.sin(run.ys[0])) + 0.3 * jnp.sum(run.ys[1] ** 2)

    return loss


# The three costliest to compile run in CI's second step (marker `integration`), so
# the default suite stays under 10 minutes; every family is checked in CI.
LONG_COMPILES = {"BlanesMoan4-plain-sum", "VariationalMidpoint", "RigidBodyYoshida4"}


@pytest.mark.integration  # ~45 s of compilations in all: CI's integration step
@pytest.mark.parametrize(
    "family",
    [
        pytest.param(name, marks=pytest.mark.integration)
        if name in LONG_COMPILES
        else name
        for name in FAMILIES
    ],
)
def test_agrees_with_the_plain_scan_for_every_reversible_family(family):
    make, solver, dt = FAMILIES[family]
    system, y0, args = make()
    steps = 1000
    plain = jax.grad(_loss(system, solver, dt, steps, None), argnums=(0, 1))
    reversible = jax.grad(
        _loss(system, solver, dt, steps, lj.ReversibleAdjoint()), argnums=(0, 1)
    )
    expected, actual = plain(y0, args), reversible(y0, args)
    assert _relative_gap(actual, expected) < 1e-12


def test_the_run_itself_is_the_plain_scan():
    system, y0, args = _kepler()
    runs = [
        lj.simulate(
            system,
            y0,
            t1=10.0,
            dt=0.01,
            args=args,
            adjoint=adjoint,
            solver=lj.Yoshida4(),
            ts=jnp.linspace(1.0, 10.0, 10),
        )
        for adjoint in (None, lj.ReversibleAdjoint())
    ]
    # The same step; XLA may fuse the loop bodies differently (last bits).
    assert _relative_gap(runs[1].ys, runs[0].ys) < 1e-14


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_saved_states_feed_their_cotangents_in_at_their_times():
    system, y0, args = _kepler()
    ts = jnp.linspace(0.5, 12.0, 24)  # every 50 steps from step 50, run of 1200
    plain = jax.grad(_loss(system, lj.StormerVerlet(), 0.01, 1200, None, ts))
    expected = plain(y0, args)
    for adjoint in (lj.ReversibleAdjoint(), lj.ReversibleAdjoint(checkpoints=20)):
        reversible = jax.grad(
            _loss(system, lj.StormerVerlet(), 0.01, 1200, adjoint, ts)
        )
        assert _relative_gap(reversible(y0, args), expected) < 1e-12


@pytest.mark.integration  # ~20 s to compile on the loaded machine: CI's second step
def test_stage_walk_with_a_driven_potential_and_a_save_at_the_start():
    # A time-dependent V(q, t) makes every kick's time count, and a save at t0
    # (no step before it) leaves the first kick of the run pulled back alone.
    system = lj.SeparableHamiltonian(
        lambda p: 0.5 * p**2,
        lambda q, t, k: 0.5 * k * q**2 + 0.3 * q**3 * jnp.cos(1.7 * t),
    )
    y0, args = (jnp.asarray(0.6), jnp.asarray(-0.1)), jnp.asarray(1.4)
    ts = jnp.linspace(0.0, 2.0, 11)  # every 20 steps from step 0
    expected = jax.grad(_loss(system, lj.Yoshida4(), 0.01, 200, None, ts),
                        argnums=(0, 1))(y0, args)  # fmt: skip
    adjoint = lj.ReversibleAdjoint()
    actual = jax.grad(_loss(system, lj.Yoshida4(), 0.01, 200, adjoint, ts),
                      argnums=(0, 1))(y0, args)  # fmt: skip
    assert _relative_gap(actual, expected) < 1e-12


def test_gradient_in_a_parameter_matches_finite_differences():
    system = lj.SeparableHamiltonian(
        lambda p: 0.5 * p**2, lambda q, t, g: -g * jnp.cos(q)
    )
    y0, gravity = (jnp.asarray(2.0), jnp.asarray(0.5)), jnp.asarray(9.81)
    solver, dt, steps = lj.Yoshida4(), 0.01, 2000

    def angle(g):
        run = lj.simulate(system, y0, t1=steps * dt, dt=dt, solver=solver, args=g,
                          adjoint=lj.ReversibleAdjoint())  # fmt: skip
        return run.q[-1]

    eps = 1e-5
    difference = (angle(gravity + eps) - angle(gravity - eps)) / (2 * eps)
    derivative = jax.grad(angle)(gravity)
    assert abs(float(derivative - difference)) < 1e-6 * abs(float(derivative))


@pytest.mark.integration  # long compile: CI's second step
def test_batched_gradients():
    system, y0, _ = _kepler()
    loss = _loss(system, lj.Yoshida4(), 0.01, 300, lj.ReversibleAdjoint())
    batch = jnp.array([0.9, 1.0, 1.1])
    batched = jax.vmap(jax.grad(loss, argnums=1), in_axes=(None, 0))(y0, batch)
    one_by_one = [jax.grad(loss, argnums=1)(y0, mu) for mu in batch]
    np.testing.assert_allclose(batched, one_by_one, rtol=1e-13)


@pytest.mark.integration  # long compile: CI's second step
def test_checkpoints_bound_the_round_off_of_the_walk_back_in_float32():
    # Uncompensated float32: each step back commits the round-off of a step, so
    # the reconstructed states drift from the forward run's; restarting from the
    # forward run's state every 10 steps keeps the drift to 10 steps' worth.
    # Measured against the plain scan's float32 gradient: 6.7e-3 without
    # checkpoints, 5.8e-4 with (1.7e-3 is the plain scan's own gap to float64).
    system, y0, args = _kepler()
    y0 = jax.tree_util.tree_map(lambda x: x.astype(jnp.float32), y0)
    args = args.astype(jnp.float32)
    solver, dt, steps = lj.StormerVerlet(compensated=False), 0.01, 20_000
    expected = jax.grad(_loss(system, solver, dt, steps, None), argnums=(0, 1))(
        y0, args
    )
    gaps = []
    for checkpoints in (None, 10):
        adjoint = lj.ReversibleAdjoint(checkpoints=checkpoints)
        actual = jax.grad(_loss(system, solver, dt, steps, adjoint), argnums=(0, 1))(
            y0, args
        )
        gaps.append(_relative_gap(actual, expected))
    assert gaps[1] < gaps[0] / 4
    assert gaps[1] < 2e-3


@pytest.mark.parametrize("solver", [diffrax.Tsit5(), diffrax.Euler()])
def test_non_reversible_solvers_are_refused_by_name(solver):
    system, y0, args = _kepler()
    system = lj.Hamiltonian(lambda q, p, t, mu: system(q, p, t, mu))
    with pytest.raises(ValueError, match=type(solver).__name__) as error:
        lj.simulate(system, y0, t1=1.0, dt=0.01, solver=solver, args=args,
                    adjoint=lj.ReversibleAdjoint())  # fmt: skip
    for name in ("StormerVerlet", "Yoshida4", "GaussLegendre", "Rattle"):
        assert name in str(error.value)


def test_runs_it_cannot_walk_back_are_refused():
    system, y0, args = _kepler()
    adjoint = lj.ReversibleAdjoint()
    with pytest.raises(ValueError, match="fixed-step"):
        lj.simulate(system, y0, t1=1.0, solver=lj.Yoshida4(), args=args,
                    adjoint=adjoint)  # fmt: skip
    with pytest.raises(ValueError, match="SaveAt"):
        lj.simulate(system, y0, t1=1.0, dt=0.01, saveat=diffrax.SaveAt(steps=True),
                    solver=lj.Yoshida4(), args=args, adjoint=adjoint)  # fmt: skip
    with pytest.raises(ValueError, match="positive"):
        lj.ReversibleAdjoint(checkpoints=0)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
@pytest.mark.parametrize(
    "solver", [lj.StormerVerlet(), lj.BitReversible(lj.StormerVerlet())]
)
def test_a_system_without_array_parameters(solver):
    # No args and no array in the system: the parameters' cotangent is an empty
    # tree, which the compensated sums of the walk must pass through.
    kepler = lj.SeparableHamiltonian(
        lambda p: 0.5 * jnp.sum(p**2), lambda q: -1 / jnp.sqrt(jnp.sum(q**2))
    )
    start = (jnp.array([1.0, 0.0]), jnp.array([0.0, 1.2]))

    def final_x(start, adjoint):
        run = lj.simulate(
            kepler, start, t1=1.0, dt=0.01, solver=solver, adjoint=adjoint
        )
        return run.q[-1, 0]

    walked = jax.grad(final_x)(start, lj.ReversibleAdjoint())
    stored = jax.grad(final_x)(start, None)
    assert _relative_gap(walked, stored) < 1e-13
