"""A tolerance run of a gravitating two-body system picks the logarithmic
Hamiltonian (`lagjax._integrate.geometric_choice`): which systems get it, and
that it keeps the tolerance on Kepler's problem."""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax._integrate.geometric_choice import geometric_default


def kepler(eccentricity=0.99):
    return lj.scenes.KeplerCartesian(eccentricity=eccentricity)


def chosen(system, y0, rtol, args=None):
    return geometric_default(system, y0, 0.0, None, args, rtol)


def test_a_kepler_scene_at_tight_tolerance_gets_time_transformed_kahan_li():
    scene = kepler()
    solver, ds = chosen(scene, scene.initial_state(), 1e-12)
    assert solver.name == "TimeTransformed(KahanLi8)"
    # ds/(2|E|τ) is the dimensionless step; the same orbit scaled up (a = 4, so
    # |E| / 4, τ × 8) takes the same number of steps per period: ds × 2.
    wide = lj.scenes.KeplerCartesian(eccentricity=0.99, semi_major_axis=4.0)
    _, wide_ds = chosen(wide, wide.initial_state(), 1e-12)
    np.testing.assert_allclose(wide_ds, 2 * ds, rtol=1e-12)
    # a tighter tolerance, a smaller step
    assert chosen(scene, scene.initial_state(), 1e-14)[1] < ds


def test_the_current_default_stays_where_time_transformed_is_not_measured_better():
    scene = kepler()
    y0 = scene.initial_state()
    assert chosen(scene, y0, 1e-6) is None  # loose: Tsit5 stays
    three = lj.scenes.PythagoreanThreeBody()  # encounters: Dopri8 was quicker
    assert chosen(three, three.initial_state(), 1e-12) is None
    plain = lj.SeparableHamiltonian(  # the same physics, undeclared
        lambda p: p @ p / 2, lambda q: -1 / jnp.sqrt(q @ q)
    )
    assert chosen(plain, y0, 1e-12) is None
    unbound = (y0[0], 2 * y0[1])  # E > 0: the rule is calibrated on ellipses
    assert chosen(scene, unbound, 1e-12) is None


def test_under_a_transformation_the_default_stays_dopri8():
    # jit, vmap and grad trace y0: Dopri8's run differentiates in reverse mode
    # without a max_steps, the time-transformed while loop does not.
    scene = kepler()
    q0, p0 = scene.initial_state()
    picks = []
    jax.make_jaxpr(lambda q: picks.append(chosen(scene, (q, p0), 1e-12)) or q)(q0)
    assert picks == [None]


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_kepler_at_tight_tolerance_keeps_the_energy_and_the_orbit():
    scene = kepler(0.99)
    rtol = 1e-12
    ts = jnp.linspace(0.5, 3 * 2 * jnp.pi, 25)  # three periods, pericentres too
    run = lj.simulate(scene, scene.initial_state(), t1=float(ts[-1]), ts=ts,
                      rtol=rtol, atol=rtol)  # fmt: skip
    assert run.stats["solver"] == "TimeTransformed(KahanLi8)"
    start = scene.energy()
    assert float(jnp.max(jnp.abs(run.energy() / start - 1))) <= rtol
    expected, _ = scene.orbit_state(ts)
    np.testing.assert_allclose(run.q, expected, atol=1e-9)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_a_named_solver_opts_out():
    scene = kepler(0.5)
    run = lj.simulate(scene, scene.initial_state(), t1=1.0, rtol=1e-12,
                      atol=1e-12, solver=diffrax.Dopri8())  # fmt: skip
    assert run.stats["solver"] == "Dopri8"
