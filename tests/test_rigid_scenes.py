"""Rigid-body scenes: both formulations of each scene agree and meet its checks."""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import lagjax as lj
from lagjax.rigid import RigidBodyTerm, euler_zxz_to_rotation, quaternion_to_matrix
from lagjax.scenes.rigid import HeavySymmetricTop, TorqueFreeBody
from lagjax.solvers.rigid import RigidBodyYoshida4

TS = jnp.linspace(0.0, 6.0, 601)


@eqx.filter_jit
def euler_path(scene):
    """The scene's Euler-angle Lagrangian, Tsit5 at tight tolerance."""
    return lj.simulate(
        scene,
        scene.initial_state(),
        t1=6.0,
        ts=TS,
        solver=diffrax.Tsit5(),
        rtol=1e-12,
        atol=1e-12,
    )


@eqx.filter_jit
def body_path(scene):
    """The scene's RigidBody with Yoshida4, as the Trajectory simulate would give."""
    solution = diffrax.diffeqsolve(
        RigidBodyTerm(scene.rigid_body()),
        RigidBodyYoshida4(),
        0.0,
        6.0,
        1e-3,
        scene.initial_body_state(),
        args=scene,
        saveat=diffrax.SaveAt(ts=TS),
        max_steps=6001,
    )
    assert solution.ys is not None
    return lj.Trajectory(
        ts=TS,
        ys=solution.ys,
        system=scene.rigid_body(),  # type: ignore[arg-type]  (wiring pending)
        args=scene,
        run_stats={},
        result=solution.result,
        solver_name="RigidBodyYoshida4",
    )


def test_torque_free_scene_two_ways():
    scene = TorqueFreeBody()
    euler, body_run = euler_path(scene), body_path(scene)
    assert np.min(euler.q[:, 1]) > 0.2 and np.max(euler.q[:, 1]) < np.pi - 0.2
    rotations = jax.vmap(euler_zxz_to_rotation)(euler.q)
    assert np.max(jnp.abs(rotations - quaternion_to_matrix(body_run.q))) < 1e-8
    for run, tolerance in ((euler, 1e-10), (body_run, 1e-9)):
        for name, (measured, expected) in scene.checks(run).items():
            assert np.allclose(measured, expected, rtol=tolerance, atol=tolerance), name


def test_heavy_top_scene_checks_and_sweep():
    scene = HeavySymmetricTop(spin=10.0, theta0=0.8)
    checks = scene.checks(euler_path(scene))
    # θ extremes over samples 0.01 apart: the bounds to the sampling error.
    assert np.isclose(*checks["theta_min"], atol=1e-4)
    assert np.isclose(*checks["theta_max"], atol=1e-4)
    assert np.isclose(*checks["spin(t1)"], rtol=1e-10)
    # Scenes are vmappable: a sweep of spins, nutation narrowing as 1/ω3².
    spins = jnp.array([10.0, 20.0, 40.0])
    bounds = jax.vmap(lambda w: HeavySymmetricTop(spin=w).nutation_bounds())(spins)
    widths = bounds[1] - bounds[0]
    assert np.all(widths > 0)
    assert np.allclose(widths[1:] / widths[:-1], 0.25, rtol=0.1)
