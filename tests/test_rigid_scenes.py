"""Rigid-body scenes: both formulations of each scene agree and meet its checks."""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax._core.terms import RigidBodyTerm
from lagjax.rigid import euler_zxz_to_rotation, quaternion_to_matrix
from lagjax.scenes.rigid import (
    DAY,
    SCENES,
    SIDEREAL_DAY,
    EarthFreePrecession,
    HeavySymmetricTop,
    TorqueFreeBody,
)
from lagjax.solvers.lie_poisson import QuaternionProjection, RigidBodyYoshida4
from tests.helpers import relative_close

SAMPLES = 1201


@eqx.filter_jit
def compiled_checks(scene, trajectory):
    """`scene.checks`, compiled whole: eager dispatch of its many small array
    expressions costs several times their compilation."""
    return scene.checks(trajectory)


@eqx.filter_jit
def euler_path(scene, t1):
    """The scene's Euler-angle Lagrangian, Tsit5 at tight tolerance."""
    ts = jnp.linspace(0.0, t1, SAMPLES)
    y0 = scene.initial_state()
    return lj.simulate(
        scene, y0, t1=t1, ts=ts, solver=diffrax.Tsit5(), rtol=1e-12, atol=1e-12
    )


@eqx.filter_jit
def body_path(scene, t1, dt):
    """The scene's RigidBody with Yoshida4, as the Trajectory simulate would give."""
    ts = jnp.linspace(0.0, t1, SAMPLES)
    solution = diffrax.diffeqsolve(
        RigidBodyTerm(scene.rigid_body()),
        RigidBodyYoshida4(),
        0.0,
        t1,
        dt,
        scene.initial_body_state(),
        args=scene,
        saveat=diffrax.SaveAt(ts=ts),
        max_steps=10_000,
    )
    assert solution.ys is not None
    return lj.Trajectory(
        ts=ts,
        ys=solution.ys,
        system=scene.rigid_body(),
        args=scene,
        run_stats={},
        result=solution.result,
        solver_name="RigidBodyYoshida4",
    )


@pytest.mark.slow  # 60 s of motion, two formulations
def test_dzhanibekov_scene_two_ways():
    scene = TorqueFreeBody()
    t1 = jnp.asarray(scene.default_t1)
    euler, body_run = euler_path(scene, t1), body_path(scene, t1, scene.default_dt)
    # θ swings to π/6 at each flip (L at 30° from e3 mid-flip) and back to π/2:
    # clear of gimbal lock throughout.
    assert np.isclose(np.min(euler.q[:, 1]), np.pi / 6, atol=0.01)
    assert np.max(euler.q[:, 1]) < np.pi / 2 + 0.01
    rotations = jax.vmap(euler_zxz_to_rotation)(euler.q)
    assert np.max(jnp.abs(rotations - quaternion_to_matrix(body_run.q))) < 1e-6
    # The flip time amplifies errors ~1000× (the wobble is 1e-3): Tsit5 at 1e-12 on
    # the angles measures the half period to 3e-8, Yoshida4 (h = 0.01) to 5e-10.
    for run, tolerance in ((euler, 1e-7), (body_run, 1e-9)):
        checks = scene.checks(run)
        assert set(checks) == {"half period", "energy", "angular momentum"}
        for name, (measured, expected) in checks.items():
            scale = float(jnp.max(jnp.abs(expected)))
            assert np.max(np.abs(measured - expected)) < tolerance * scale, name


@pytest.mark.parametrize("moments", [(2.0, 2.0, 1.0), (1.0, 1.0, 1.8)])
def test_symmetric_period_is_the_precession_period(moments):
    scene = TorqueFreeBody(moments=moments, omega0=(0.4, 0.1, 3.0))
    expected = 2 * np.pi / abs(scene.precession_rate())
    assert np.isclose(scene.period(), expected, rtol=1e-14)


def test_heavy_top_scene_checks_and_sweep():
    scene = HeavySymmetricTop(spin=10.0, theta0=0.8)
    checks = compiled_checks(scene, euler_path(scene, jnp.asarray(scene.default_t1)))
    # θ extremes over samples ~0.004 s apart: the bounds to the sampling error.
    assert np.isclose(*checks["theta min"], atol=1e-5)
    assert np.isclose(*checks["theta max"], atol=1e-5)
    assert np.allclose(*checks["spin"], rtol=1e-10)
    # Scenes are vmappable: a sweep of spins, the nutation narrowing as 1/ω3².
    spins = jnp.array([10.0, 20.0, 40.0])
    bounds = jax.jit(jax.vmap(lambda w: HeavySymmetricTop(spin=w).nutation_bounds()))(
        spins
    )
    widths = bounds[1] - bounds[0]
    assert np.all(widths > 0)
    assert np.allclose(widths[1:] / widths[:-1], 0.25, rtol=0.1)


def test_scene_conventions():
    for scene_class in SCENES:
        scene = scene_class()
        assert scene.default_t1 > 0 and scene.default_dt > 0
        assert scene_class.__doc__ is not None and scene_class.__doc__.strip()
        q0, qdot0 = scene.initial_state()
        assert jnp.shape(q0) == jnp.shape(qdot0) == (3,)
        assert np.isfinite(scene.system()(q0, qdot0, 0.0, scene))


def test_earth_wobble_period_is_euler_s_305_sidereal_days():
    """T = A/(C − A) sidereal days (course text eq. 4.47 with Earth's numbers)."""
    earth = EarthFreePrecession()
    expected = 305 * SIDEREAL_DAY / np.cos(1e-6)
    assert relative_close(earth.euler_period(), expected, 1e-13)
    assert 304 < float(earth.euler_period()) / DAY < 305  # ≈ 304.2 solar days


def _earth_checks_within(earth, trajectory, period_tolerance):
    checks = compiled_checks(earth, trajectory)
    measured, expected = checks["wobble period (days)"]
    assert relative_close(measured, expected, period_tolerance), (measured, expected)
    assert relative_close(*checks["wobble angle"], 1e-5)
    assert relative_close(*checks["angular momentum"], 1e-12)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_earth_free_precession_two_ways():
    """Over 400 days: Euler angles with the default GaussLegendre(2), h = 20 min
    (ωh = 0.09, period to ~3e-5), and quaternions with Dopri8 (the body-frame
    motion is a slow rotation of Π, integrated to round-off)."""
    earth = EarthFreePrecession()
    t1, ts = earth.default_t1, jnp.arange(0.0, earth.default_t1, 6 * 3600.0)
    euler = lj.simulate(earth, earth.initial_state(), t1=t1, dt=earth.default_dt, ts=ts)
    assert euler.solver_name == "GaussLegendre"
    _earth_checks_within(earth, euler, 1e-4)
    body = lj.simulate(
        earth.rigid_body(), earth.initial_body_state(), t1=t1, ts=ts, args=earth,
        solver=QuaternionProjection(diffrax.Dopri8()), rtol=1e-10, atol=1e-10,
    )  # fmt: skip
    _earth_checks_within(earth, body, 1e-12)
