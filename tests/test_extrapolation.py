"""Gragg–Bulirsch–Stoer extrapolation of the time-transformed leapfrog
(`lagjax.solvers.extrapolation`): its order on a nonlinear problem, the step
control (a refused first step, the orbit kept), energy and both momenta on the
Pythagorean three-body problem, refusals by name."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.flatten_util import ravel_pytree

import lagjax as lj
from lagjax.mechanics.particles import total_angular_momentum, total_momentum
from lagjax.scenes.pythagorean import PythagoreanThreeBody
from lagjax.solvers.extrapolation import GraggBulirschStoer
from lagjax.solvers.time_transformed import extended_state


def perturbed_kepler() -> lj.SeparableHamiltonian:
    """Kepler with a 1/r³ term: precessing orbits, no closed form."""
    return lj.SeparableHamiltonian(
        lambda p: p @ p / 2,
        lambda q: -1 / jnp.sqrt(q @ q) - 0.01 / jnp.sqrt(q @ q) ** 3,
    )


def _stepper(columns: int):
    """ds ↦ one extrapolated step of the logarithmic leapfrog from e = 0.6's
    pericentre (the extended state flattened) and its error estimate."""
    solver = GraggBulirschStoer(substeps=tuple(range(1, columns + 1)))
    system = perturbed_kepler()
    terms = lj.TimeTransformed(solver).terms(system)
    y0 = (jnp.array([0.4, 0.0]), jnp.array([0.0, 2.0]))
    start = extended_state(system, y0, 0.0, None)

    @jax.jit
    def step(ds):
        state = solver.init(terms, 0.0, ds, start, None)
        y1, error, *_ = solver.step(terms, 0.0, ds, start, None, state, False)
        return ravel_pytree(y1)[0], jnp.abs(ravel_pytree(error)[0])

    return step


@pytest.mark.parametrize(
    "columns",
    [2, pytest.param(3, marks=pytest.mark.integration)],  # 3: compiles 4.7 s
)
def test_local_error_has_order_two_k_plus_one(columns):
    """k columns: order 2k, so one step errs by O(ds^(2k+1)); the reference is
    the sixteenth-order tableau, and the error estimate is of the next lower
    order, O(ds^(2k−1))."""
    steps = np.array([0.4, 0.2, 0.1])
    errors, estimates = [], []
    step, reference_step = _stepper(columns), _stepper(8)
    for ds in steps:
        y1, estimate = step(ds)
        reference, _ = reference_step(ds)
        errors.append(float(jnp.abs(y1 - reference).max()))
        estimates.append(float(estimate.max()))
    slope = np.polyfit(np.log(steps), np.log(errors), 1)[0]
    assert abs(slope - (2 * columns + 1)) <= 0.4, (errors, slope)
    estimate_slope = np.polyfit(np.log(steps), np.log(estimates), 1)[0]
    assert abs(estimate_slope - (2 * columns - 1)) <= 0.4, (estimates, slope)
    assert np.all(np.array(estimates) > np.array(errors))  # it bounds the error


@pytest.mark.integration  # compile-heavy (5 s): CI runs it in its integration step
def test_a_too_long_first_step_is_refused_and_the_orbit_kept():
    """Kepler e = 0.9 from pericentre with a first fictitious step of half a
    period: refused and shrunk; the energy and the timing (Kepler's equation)
    kept to the tolerance over three periods."""
    e, period = 0.9, 2 * np.pi
    kepler = lj.SeparableHamiltonian(
        lambda p: p @ p / 2, lambda q: -1 / jnp.sqrt(q @ q)
    )
    y0 = (jnp.array([1 - e, 0.0]), jnp.array([0.0, np.sqrt((1 + e) / (1 - e))]))
    ts = np.array([0.0, period, 2 * period, 3 * period])
    gbs = GraggBulirschStoer(substeps=(1, 2, 3, 4), rtol=1e-12, atol=1e-12)
    solver = lj.TimeTransformed(gbs)
    traj = lj.simulate(kepler, y0, t1=ts[-1], dt=3.0, ts=ts, solver=solver)
    assert int(traj.stats["num_rejected_steps"]) >= 1
    assert int(traj.stats["num_steps"]) < 200
    energy = np.asarray(traj.energy())
    assert np.abs(energy / -0.5 - 1).max() <= 1e-12
    # Back at pericentre after each period: the timing along the orbit.
    pericentre = np.stack([np.full(4, 1 - e), np.zeros(4)], axis=1)
    assert np.abs(np.asarray(traj.q) - pericentre).max() <= 1e-9
    assert float(traj.stats["time_residual"]) <= 1e-13 * ts[-1]


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_pythagorean_first_encounters_keep_energy_and_momenta():
    """Through the first close encounter (t ≈ 1.9, separation 1e-2): energy to
    1e-12 of its value, total and angular momentum at zero to round-off."""
    scene = PythagoreanThreeBody()
    ts = jnp.linspace(0.0, 3.0, 7)
    solver = lj.TimeTransformed(GraggBulirschStoer(rtol=1e-13, atol=1e-13))
    traj = lj.simulate(scene, scene.initial_state(), t1=3.0, dt=0.1, ts=ts,
                       solver=solver)  # fmt: skip
    energy = np.asarray(traj.energy())
    assert np.abs(energy / float(scene.energy()) - 1).max() <= 1e-12
    assert float(jnp.max(jnp.abs(total_momentum(traj.p)))) < 1e-12
    assert float(jnp.max(jnp.abs(total_angular_momentum(traj.q, traj.p)))) < 1e-12
    assert float(jnp.max(jnp.abs(traj.q[-1] - traj.q[0]))) > 0.5  # it moved


def test_refusals_name_the_problem():
    for substeps in ((2,), (1, 3, 2), (0, 1, 2), (1.0, 2.0)):
        with pytest.raises(ValueError, match="substeps"):
            GraggBulirschStoer(substeps=substeps)
    with pytest.raises(ValueError, match="rtol"):
        GraggBulirschStoer(rtol=0.0)
    with pytest.raises(ValueError, match="atol"):
        GraggBulirschStoer(atol=-1e-12)
