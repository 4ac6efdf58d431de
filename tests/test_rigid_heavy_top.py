"""The heavy symmetric top, two ways: its Euler-angle Lagrangian through `lj.simulate`
and the quaternion `RigidBody` with gravity.

Oracles: the exact steady-precession roots and their gyroscopic approximations,
the nutation bounds from the roots of the cubic f(u) (Goldstein §5.7), agreement of
the two formulations, and the gimbal-lock singularity of the Euler angles at θ = 0.
"""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax._core.terms import RigidBodyTerm
from lagjax.rigid import (
    euler_zxz_body_angular_velocity,
    euler_zxz_to_rotation,
    quaternion_to_matrix,
)
from lagjax.rigid.heavy_top import (
    gyroscopic_precession_rates,
    steady_precession_rates,
    turning_point_cubic,
)
from lagjax.scenes.rigid import HeavySymmetricTop
from lagjax.solvers.lie_poisson import QuaternionProjection, RigidBodyYoshida4

SAMPLES = 3001
TOLERANCE = dict(rtol=1e-12, atol=1e-12)


@eqx.filter_jit
def euler_angle_run(scene, t1):
    """The scene's Lagrangian in Euler angles, Tsit5 at tight tolerance."""
    ts = jnp.linspace(0.0, t1, SAMPLES)
    y0 = scene.initial_state()
    traj = lj.simulate(scene, y0, t1=t1, ts=ts, solver=diffrax.Tsit5(), **TOLERANCE)
    return traj.ts, traj.q, traj.qdot


@eqx.filter_jit
def quaternion_run(scene, t1, solver, dt):
    """The same top as a RigidBody on (quaternion, body momentum)."""
    ts = jnp.linspace(0.0, t1, SAMPLES)
    adaptive = dt is None
    solution = diffrax.diffeqsolve(
        RigidBodyTerm(scene.rigid_body()),
        solver,
        0.0,
        t1,
        dt,
        scene.initial_body_state(),
        args=scene,
        saveat=diffrax.SaveAt(ts=ts),
        stepsize_controller=diffrax.PIDController(**TOLERANCE)
        if adaptive
        else diffrax.ConstantStepSize(),
        max_steps=100_000,
    )
    return solution.ys


def _fast_top_smallness(scene):
    """ε = I1 Mgl cos θ / (I3 ω3)²: the gyroscopic approximations' relative error."""
    return scene.i1 * scene.mgl * jnp.cos(scene.theta0) / (scene.i3 * scene.spin) ** 2


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_steady_precession_slow_and_fast():
    base = HeavySymmetricTop()
    exact = jnp.stack(
        steady_precession_rates(base.i1, base.i3, base.mgl, base.spin, base.theta0)
    )
    scenes = jax.vmap(lambda rate: HeavySymmetricTop(phi_dot0=rate))(exact)
    ts, angles, _ = jax.vmap(euler_angle_run, in_axes=(0, None))(
        scenes, jnp.asarray(2.0)
    )
    # Started on a root, θ does not move and φ advances uniformly at that rate.
    assert np.max(jnp.abs(angles[:, :, 1] - base.theta0)) < 1e-9
    measured = (angles[:, -1, 0] - angles[:, 0, 0]) / ts[:, -1]
    assert np.allclose(measured, exact, rtol=1e-9, atol=0)
    # The gyroscopic forms Mgl/(I3ω3) and I3ω3/(I1 cos θ) are off by ε, as predicted.
    approximate = jnp.stack(
        gyroscopic_precession_rates(base.i1, base.i3, base.mgl, base.spin, base.theta0)
    )
    smallness = _fast_top_smallness(base)
    assert 1e-3 < smallness < 1e-2  # the fast-top regime
    relative = jnp.abs(exact / approximate - 1)
    assert np.all((relative > 0.9 * smallness) & (relative < 1.1 * smallness))


def _refined_extrema(ts, values, kind):
    """Times and values of the interior extrema: vertex of the parabola through the
    three samples around each (error ~ (ω Δt)⁴, not the (ω Δt)² of the samples)."""
    sign = 1 if kind == "max" else -1
    v = sign * np.asarray(values)
    index = 1 + np.nonzero((v[1:-1] > v[:-2]) & (v[1:-1] >= v[2:]))[0]
    left, middle, right = v[index - 1], v[index], v[index + 1]
    curvature = left - 2 * middle + right
    offset = 0.5 * (left - right) / curvature
    step = ts[1] - ts[0]
    peak = middle - 0.25 * (left - right) * offset
    return np.asarray(ts)[index] + offset * step, sign * peak


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_released_fast_top_nutation_bounds_and_rates():
    scene = HeavySymmetricTop()
    ts, angles, _ = euler_angle_run(scene, jnp.asarray(3.0))
    ts, theta, phi = np.asarray(ts), np.asarray(angles[:, 1]), np.asarray(angles[:, 0])
    theta_min, theta_max = scene.nutation_bounds()
    # θ nods between the two roots of f(u) in [−1, 1].
    max_times, maxima = _refined_extrema(ts, theta, "max")
    _, minima = _refined_extrema(ts, theta, "min")
    assert len(maxima) >= 8 and len(minima) >= 8
    assert np.allclose(maxima, theta_max, rtol=0, atol=5e-10)
    assert np.allclose(minima, theta_min, rtol=0, atol=5e-10)
    assert theta_max - theta_min > 1e-3
    # Fast top: nutation at ≈ I3ω3/I1, mean precession at ≈ Mgl/(I3ω3), both to O(ε).
    smallness = float(_fast_top_smallness(scene))
    nutation = 2 * np.pi / np.mean(np.diff(max_times))
    assert abs(nutation / (scene.i3 * scene.spin / scene.i1) - 1) < 3 * smallness
    mean_precession = np.diff(np.interp(max_times[[0, -1]], ts, phi))[0] / np.ptp(
        max_times
    )
    slow, _ = gyroscopic_precession_rates(
        scene.i1, scene.i3, scene.mgl, scene.spin, scene.theta0
    )
    assert abs(mean_precession / slow - 1) < 2 * smallness


def test_turning_point_cubic_vanishes_at_the_start():
    scene = HeavySymmetricTop(phi_dot0=0.7, theta_dot0=0.0)
    coefficients = turning_point_cubic(
        scene.i1, scene.i3, scene.mgl, *scene.initial_state()
    )
    assert abs(jnp.polyval(coefficients, jnp.cos(scene.theta0))) < 1e-12
    moving = HeavySymmetricTop(phi_dot0=0.7, theta_dot0=0.3)
    coefficients = turning_point_cubic(
        moving.i1, moving.i3, moving.mgl, *moving.initial_state()
    )
    # f(u0) = u̇0² = (sin θ0 θ̇0)².
    expected = (jnp.sin(moving.theta0) * moving.theta_dot0) ** 2
    assert np.isclose(jnp.polyval(coefficients, jnp.cos(moving.theta0)), expected)


GENERIC_TOP = dict(
    i1=1.0, i3=0.6, mgl=2.0, theta0=1.0, spin=6.0, phi_dot0=0.5, theta_dot0=0.3
)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
@pytest.mark.parametrize(
    "solver, dt, tolerance",
    [
        (QuaternionProjection(diffrax.Tsit5()), None, 1e-8),
        (RigidBodyYoshida4(), 1e-3, 1e-6),
    ],
    ids=["adaptive", "yoshida4"],
)
def test_euler_angle_and_quaternion_paths_agree(solver, dt, tolerance):
    scene = HeavySymmetricTop(**GENERIC_TOP)
    _, angles, rates = euler_angle_run(scene, jnp.asarray(5.0))
    q, momentum = quaternion_run(scene, jnp.asarray(5.0), solver, dt)
    from_angles = jax.vmap(euler_zxz_to_rotation)(angles)
    assert np.ptp(angles[:, 1]) > 0.2  # a large nutation, far from gimbal lock
    assert np.max(jnp.abs(quaternion_to_matrix(q) - from_angles)) < tolerance
    omega = momentum / scene.rigid_body().moments
    from_rates = jax.vmap(euler_zxz_body_angular_velocity)(angles, rates)
    assert np.max(jnp.abs(omega - from_rates)) < 100 * tolerance


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_gimbal_lock_is_a_clear_error_in_euler_angles_only():
    scene = HeavySymmetricTop()
    lagrangian = scene.system()
    rates = jnp.array([0.0, 0.0, 40.0])
    for theta in (0.0, 1e-9):
        with pytest.raises(RuntimeError, match=r"singular.*gimbal lock"):
            lagrangian.acceleration(jnp.array([0.0, theta, 0.0]), rates, 0.0, scene)
    near = lagrangian.acceleration(jnp.array([0.0, 1e-3, 0.0]), rates, 0.0, scene)
    assert np.all(np.isfinite(near))
    upright = HeavySymmetricTop(theta0=0.0)
    with pytest.raises(RuntimeError, match=r"non-finite.*gimbal lock"):
        lj.simulate(
            upright, upright.initial_state(), t1=0.01, dt=1e-3, solver=diffrax.Tsit5()
        )
    traj = lj.simulate(
        upright,
        upright.initial_state(),
        t1=0.01,
        dt=1e-3,
        solver=diffrax.Tsit5(),
        throw=False,
    )
    assert not traj.stats["finite"]
    # The quaternion form has no such point: the upright (sleeping) top just spins.
    q, momentum = quaternion_run(upright, jnp.asarray(1.0), RigidBodyYoshida4(), 1e-3)
    assert np.max(jnp.abs(quaternion_to_matrix(q)[:, 2, 2] - 1)) < 1e-14
    assert np.allclose(momentum[:, 2], upright.i3 * upright.spin, rtol=1e-14)
