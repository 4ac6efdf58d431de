"""Working precision: a float32 start gives a float32 run, end to end.

With x64 enabled, lagjax's own float64 pieces (times, scene parameters, stage and
Newton tolerances of 1e-14) used to promote a float32 state back to float64 or make
the run fail. Physics checks here: a float32 run of every scene is float32 and
agrees with the float64 run to float32 round-off over a short horizon, its energy
error is bounded at the float32 level over a long one, and float64 results are
unchanged by the policy.
"""

import math

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax._core.precision import cast_floats, reachable_tolerance, working_dtype
from lagjax.scenes import catalog
from lagjax.scenes.central import KeplerCartesian
from lagjax.scenes.pendulums import DoublePendulum, SimplePendulum
from lagjax.solvers.stage_iteration import StageIteration

EPS32 = float(np.finfo(np.float32).eps)


def _float32(tree):
    return cast_floats(jax.tree_util.tree_map(jnp.asarray, tree), jnp.float32)


def _flat(trajectory) -> np.ndarray:
    return np.concatenate(
        [
            np.ravel(np.asarray(leaf[-1], dtype=float))
            for leaf in jax.tree.leaves(trajectory.ys)
        ]
    )


def test_working_dtype_follows_the_state():
    assert working_dtype((1.0, 0.0)) == np.float64  # Python numbers: the default
    assert working_dtype((1, 0)) == np.float64  # integers are not an integer run
    assert working_dtype((jnp.float32(1), jnp.zeros(2, jnp.float32))) == np.float32
    assert working_dtype((jnp.float32(1), jnp.zeros(2))) == np.float64  # widest wins
    with pytest.raises(TypeError, match="real floating"):
        working_dtype((jnp.array(1 + 1j), 0.0))


def test_tolerances_are_floored_at_the_dtype_resolution():
    assert reachable_tolerance(1e-14, np.float64) == 1e-14
    assert reachable_tolerance(1e-3, np.float32) == 1e-3
    assert math.isclose(reachable_tolerance(1e-14, np.float32), 45 * EPS32)


# One scene per kind of run (splitting on a separable H, Gauss-Legendre on a derived
# Lagrangian, a rotating frame, a charge in fields, Euler angles, a projected
# constraint) in the default run; every scene under -m slow (each compiles twice,
# 52 compiles in all). The rolling constraint's kind of run is the knife edge below
# by default: the rolling disk's two compilations took 22 s of the file's 68.
REPRESENTATIVE_SCENES = {
    "harmonic-oscillator",
    "kepler-cartesian",
    "double-pendulum",
    "foucault-pendulum",
    "charge-in-uniform-fields",
    "heavy-symmetric-top",
    "cartesian-pendulum",
}


def _assert_float32_run_tracks_float64(wide, narrow, label):
    """float32 throughout, final state within float32 round-off of the float64 run."""
    assert all(leaf.dtype == jnp.float32 for leaf in jax.tree.leaves(narrow.ys))
    assert narrow.ts.dtype == jnp.float32
    expected, measured = _flat(wide), _flat(narrow)
    deviation = np.max(np.abs(measured - expected)) / np.max(np.abs(expected))
    assert deviation < 1e3 * EPS32, (label, deviation)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
@pytest.mark.parametrize(
    "name",
    [
        name
        if name in REPRESENTATIVE_SCENES
        else pytest.param(name, marks=pytest.mark.slow)
        for name in catalog()
    ],
)
def test_every_scene_runs_in_float32(name):
    """Default solver, 20 default steps: float32 throughout, within float32 round-off."""
    scene = catalog()[name]()
    t1 = 20 * scene.default_dt
    wide = lj.simulate(scene, scene.initial_state(), t1=t1, dt=scene.default_dt)
    narrow = lj.simulate(
        _float32(scene), _float32(scene.initial_state()), t1=t1, dt=scene.default_dt
    )
    _assert_float32_run_tracks_float64(wide, narrow, name)


def _knife_edge_on_a_slope():
    """A knife edge (skate) on a plane tilted by 0.3 rad, q = (x, y, θ), x downhill.

    L = ½(ẋ² + ẏ²) + ½θ̇² + g sin(0.3) x, and the blade only moves along itself:
    ẏ cos θ − ẋ sin θ = 0, a nonholonomic constraint like the rolling disk's.
    """

    def lagrangian(q, qdot):
        return 0.5 * jnp.sum(qdot**2) + 9.81 * jnp.sin(0.3) * q[0]

    def along_the_blade(q, qdot):
        return qdot[1] * jnp.cos(q[2]) - qdot[0] * jnp.sin(q[2])

    return lj.Lagrangian(
        lagrangian, constraints=lj.Constraints(velocity=along_the_blade)
    )


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_nonholonomic_run_in_float32():
    """The rolling disk's kind of run (velocity constraints, the default constraint
    projection) at a fraction of its compile time: float32 throughout, within
    float32 round-off of float64."""
    heading = 0.4
    start = (
        jnp.array([0.0, 0.0, heading]),
        jnp.array([np.cos(heading), np.sin(heading), 1.5]),
    )
    knife_edge = _knife_edge_on_a_slope()
    wide = lj.simulate(knife_edge, start, t1=0.2, dt=0.01)
    narrow = lj.simulate(knife_edge, _float32(start), t1=0.2, dt=0.01)
    assert narrow.stats["solver"] == "ConstraintProjection"
    _assert_float32_run_tracks_float64(wide, narrow, "knife edge")


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
@pytest.mark.parametrize(
    "solver",
    [
        diffrax.Tsit5(),
        # The slowest to compile (an adaptive implicit solver, twice): the slow run.
        pytest.param(diffrax.Kvaerno5(), marks=pytest.mark.slow),
        lj.GaussLegendre(stages=3),
        lj.VariationalMidpoint(),
    ],
    ids=["Tsit5", "Kvaerno5", "GaussLegendre3", "VariationalMidpoint"],
)
def test_double_pendulum_in_float32_with_saving(solver):
    """Adaptive (diffrax loop, saved ts) and implicit fixed-step runs stay float32."""
    scene = DoublePendulum()
    dt = None if isinstance(solver, diffrax.AbstractAdaptiveSolver) else 0.01
    ts = jnp.linspace(0.0, 1.0, 5)
    kwargs = dict(t1=1.0, dt=dt, solver=solver, ts=ts, rtol=1e-5, atol=1e-5)
    wide = lj.simulate(scene, scene.initial_state(), **kwargs)
    narrow = lj.simulate(_float32(scene), _float32(scene.initial_state()), **kwargs)
    assert narrow.ts.dtype == narrow.q.dtype == jnp.float32
    assert narrow.energy().dtype == narrow.p.dtype == jnp.float32
    deviation = np.max(np.abs(np.asarray(narrow.q, float) - np.asarray(wide.q)))
    assert deviation < 1e-4, deviation  # the rtol of the adaptive runs


def test_float32_energy_error_stays_at_round_off_level():
    """Kepler e = 0.6, Yoshida4, 100 periods in float32: bounded, no drift.

    At h = T/1000 the truncation part of the energy error is ~1e-9, so what is
    measured at every step is float32 round-off; with compensated summation it stays
    within a few hundred ε₃₂ over the 10⁵ steps instead of growing with them.
    """
    orbit = KeplerCartesian(eccentricity=0.6)
    period, steps = float(orbit.period()), 100_000
    trajectory = lj.simulate(
        _float32(orbit), _float32(orbit.initial_state()), t1=100 * period,
        dt=period / 1000, solver=lj.Yoshida4(), max_steps=steps + 2,
        saveat=diffrax.SaveAt(steps=True),
    )  # fmt: skip
    saved = np.isfinite(np.asarray(trajectory.ts))
    energy = np.asarray(trajectory.energy(), dtype=float)[saved]
    assert energy.size >= steps
    error = np.abs(energy - energy[0]) / abs(energy[0])
    assert np.max(error) < 200 * EPS32, np.max(error)
    half = energy.size // 2
    first, second = np.max(error[:half]), np.max(error[half:])
    assert second < 4 * first + 20 * EPS32, (first, second)


def test_float32_gradient_through_a_run():
    """∂q(t)/∂θ₀ by reverse mode in float32 matches float64 to float32 accuracy."""

    def final_angle(scene, angle):
        return lj.simulate(scene, (angle, 0 * angle), t1=0.5, dt=0.01).q[-1]

    # Jitted: eagerly, the forward and the backward pass compile separately, and the
    # bookkeeping around them piece by piece.
    gradient = eqx.filter_jit(jax.grad(final_angle, argnums=1))
    narrow = gradient(_float32(SimplePendulum()), jnp.float32(0.3))
    wide = gradient(SimplePendulum(), jnp.asarray(0.3))
    assert narrow.dtype == jnp.float32 and wide.dtype == jnp.float64
    assert abs(float(narrow) - float(wide)) < 1e3 * EPS32 * abs(float(wide)) + 1e-5


def test_float64_runs_are_untouched_by_the_policy():
    """A float64 run with float32 parameters is float64 (parameters are widened)."""
    scene = _float32(SimplePendulum())
    trajectory = lj.simulate(scene, (0.3, 0.0), t1=1.0, dt=0.01)
    reference = lj.simulate(SimplePendulum(), (0.3, 0.0), t1=1.0, dt=0.01)
    assert trajectory.q.dtype == jnp.float64
    # the float32 parameter g = 9.81 differs from 9.81 by ~1e-7 relative
    assert abs(float(trajectory.q[-1] - reference.q[-1])) < 1e-6


def test_stage_iteration_reaches_the_float32_floor():
    """Z = cos Z in float32: converges to the float32 root, state in float32."""
    import optimistix as optx

    solution = optx.fixed_point(
        lambda z, _: jnp.cos(z),
        StageIteration(rtol=1e-14, atol=1e-14),
        jnp.float32(1.0),
        max_steps=200,
    )
    assert solution.value.dtype == jnp.float32
    assert abs(float(solution.value) - 0.7390851332151607) < 100 * EPS32
