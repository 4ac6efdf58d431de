"""Catalogue of bad calls to `simulate`: each refused before compiling, by name.

Every case asserts the error type and a message that names the problem (and,
where one exists, the remedy). None of these compiles a run: `check_simulate_inputs`
refuses them while the call is being made. Cases that need a run (integer y0)
check the result against the closed form.
"""

import math

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.scenes.oscillators import HarmonicOscillator
from lagjax.scenes.pendulums import SimplePendulum

OMEGA = 1.5


def oscillator_lagrangian():
    return lj.Lagrangian(
        lambda q, qd: 0.5 * jnp.sum(qd**2) - 0.5 * OMEGA**2 * jnp.sum(q**2)
    )


def oscillator_hamiltonian():
    return lj.SeparableHamiltonian(
        lambda p: 0.5 * jnp.sum(p**2), lambda q: 0.5 * OMEGA**2 * jnp.sum(q**2)
    )


LAG, HAM = oscillator_lagrangian(), oscillator_hamiltonian()
Y0 = (1.0, 0.0)
BODY = lj.RigidBody(jnp.array([1.0, 2.0, 3.0]))


def refused(kwargs, error, message, system=None, y0=Y0):
    """One catalogue entry: simulate(system, y0, **kwargs) raises error ~ message."""
    return pytest.param(system, y0, kwargs, error, message, id=message[:40])


SOLVER_CASES = [
    refused(dict(solver=diffrax.Tsit5), TypeError, "the class Tsit5, not an instance"),
    refused(dict(solver=lj.Yoshida4, dt=0.1), TypeError, r"pass Yoshida4\(\)"),
    refused(dict(solver="Tsit5"), TypeError, "not the string 'Tsit5'"),
    refused(dict(solver="yoshida4", dt=0.1), TypeError, "not the string"),
    refused(dict(solver=42), TypeError, "solver instance, got int"),
    refused(dict(solver=lambda t, y: y), TypeError, "solver instance, got function"),
    refused(dict(solver=diffrax.ODETerm(lambda t, y, a: y)), TypeError, "got ODETerm"),
    refused(dict(solver=diffrax.SPaRK(), dt=0.1), TypeError, "SPaRK is a stochastic"),
    refused(dict(solver=diffrax.ShARK(), dt=0.1), TypeError, "ShARK is a stochastic"),
    refused(dict(solver=diffrax.SRA1(), dt=0.1), TypeError, "SRA1 is a stochastic"),
    refused(dict(solver=diffrax.SEA(), dt=0.1), TypeError, "SEA is a stochastic"),
    refused(dict(solver=diffrax.ItoMilstein(), dt=0.1), TypeError, "ItoMilstein is a"),
    refused(
        dict(solver=diffrax.StratonovichMilstein(), dt=0.1),
        TypeError,
        "StratonovichMilstein is a stochastic",
    ),
    refused(dict(solver=diffrax.EulerHeun(), dt=0.1), TypeError, "EulerHeun is a"),
    refused(dict(solver=diffrax.KenCarp4()), TypeError, "KenCarp4 is an IMEX"),
    refused(dict(solver=diffrax.Sil3()), TypeError, "Sil3 is an IMEX"),
    refused(
        dict(solver=lj.RigidBodyVerlet(), dt=0.1),
        TypeError,
        "Lie–Poisson solver for a lagjax.RigidBody",
    ),
    refused(dict(solver=lj.Rattle(), dt=0.1), TypeError, "has no constraints"),
]

STEP_CASES = [
    refused(dict(max_steps=0), ValueError, "max_steps must be positive, got 0"),
    refused(dict(max_steps=-5), ValueError, "max_steps must be positive, got -5"),
    refused(dict(max_steps=1e5), TypeError, "max_steps must be a positive int"),
    refused(dict(max_steps=True), TypeError, "max_steps must be a positive int"),
    refused(dict(max_steps="100"), TypeError, "max_steps must be a positive int"),
]

TIME_CASES = [
    refused(dict(t1=math.nan), ValueError, "t1 = nan is not a finite number"),
    refused(dict(t1=math.inf), ValueError, "t1 = inf is not a finite number"),
    refused(dict(t1=-math.inf), ValueError, "t1 = -inf is not a finite"),
    refused(dict(t0=math.nan), ValueError, "t0 = nan is not a finite number"),
    refused(dict(t1=np.float64("nan")), ValueError, "t1 = nan"),
    refused(dict(t1=jnp.asarray(jnp.nan)), ValueError, "t1 = nan"),
    refused(dict(dt=math.nan), ValueError, "dt = nan is not a finite number"),
    refused(dict(dt=math.inf), ValueError, "dt = inf is not a finite number"),
    refused(dict(dt=0.0), ValueError, "dt must be a finite non-zero number"),
    refused(dict(dt=0), ValueError, "dt must be a finite non-zero number"),
    refused(dict(dt=-0.0), ValueError, "dt must be a finite non-zero number"),
    refused(dict(dt=1e-300), ValueError, r"means 1e\+300 steps"),
    refused(dict(dt=5e-324), ValueError, "steps, more than 1e"),
    refused(dict(dt=1e-12, t1=1e4), ValueError, r"means 1e\+16 steps"),
    refused(dict(t1="10"), TypeError, "t1 must be a real number"),
    refused(dict(t1=jnp.ones(2)), ValueError, "t1 must be a scalar"),
    refused(dict(dt=True), TypeError, "dt must be a real number"),
    refused(dict(t1=1j), TypeError, "t1 must be a real number"),
]

SAVE_TIME_CASES = [
    refused(
        dict(ts=[0.0, math.nan, 1.0]), ValueError, r"ts\[1\] = nan is not a finite"
    ),
    refused(dict(ts=[0.0, math.inf]), ValueError, r"ts\[1\] = inf is not a finite"),
    refused(dict(ts=[0.0, 20.0]), ValueError, r"ts\[1\] = 20.0 lies outside"),
    refused(dict(ts=[-1.0, 1.0]), ValueError, r"ts\[0\] = -1.0 lies outside"),
    refused(dict(ts=[0.5, 0.2]), ValueError, "ts must be sorted, increasing"),
    refused(
        dict(ts=[-0.5, -0.2], t1=-1.0), ValueError, r"sorted, decreasing \(t1 < t0\)"
    ),
    refused(dict(ts=[0.5], t1=-1.0), ValueError, "lies outside"),
    refused(dict(ts=np.ones((2, 2))), ValueError, "non-empty 1-D array"),
    refused(dict(ts=[]), ValueError, "non-empty 1-D array"),
    refused(dict(ts="soon"), TypeError, "ts must be an array of times"),
]

STATE_CASES = [
    refused({}, TypeError, "y0 must be a pair.*got a float", y0=1.0),
    refused({}, TypeError, "got a tuple of length 3", y0=(1.0, 0.0, 0.0)),
    refused({}, TypeError, "got a tuple of length 1", y0=(1.0,)),
    refused({}, TypeError, r"array of shape \(2,\)", y0=jnp.ones(2)),
    refused({}, TypeError, "got a dict", y0={"q": 1.0, "qdot": 0.0}),
    refused({}, TypeError, "got a NoneType", y0=None),
    refused(
        {},
        ValueError,
        r"same shapes, got \(2,\) and \(3,\)",
        y0=(jnp.ones(2), jnp.ones(3)),
    ),
    refused({}, ValueError, "same structure", y0=((1.0, 2.0), jnp.ones(2))),
    refused({}, ValueError, r"y0\[0\] contains a non-finite", y0=(math.nan, 0.0)),
    refused({}, ValueError, r"y0\[1\] contains a non-finite", y0=(0.0, math.inf)),
    refused({}, TypeError, "float16.*refused", y0=(jnp.float16(1), jnp.float16(0))),
    refused({}, TypeError, "bfloat16", y0=(jnp.ones((), jnp.bfloat16),) * 2),
    refused({}, TypeError, "complex numbers", y0=(1.0 + 1j, 0.0)),
    refused({}, TypeError, "booleans", y0=(True, False)),
    refused({}, ValueError, "no numbers", y0=((), ())),
]

SYSTEM_CASES = [
    refused({}, TypeError, "plain function.*lagjax.Lagrangian", system=lambda q, v: v),
    refused(
        {},
        TypeError,
        r"class HarmonicOscillator.*HarmonicOscillator\(\)",
        system=HarmonicOscillator,
    ),
    refused({}, TypeError, "must be a lagjax system.*got NoneType", system="none"),
    refused({}, TypeError, "must be a lagjax system.*got str", system="pendulum"),
    refused({}, TypeError, "must be a lagjax system.*got dict", system={"L": 1}),
]

RIGID_CASES = [
    refused({}, ValueError, "quaternion is zero", BODY, (jnp.zeros(4), jnp.ones(3))),
    refused(
        {},
        ValueError,
        "quaternion is not finite",
        BODY,
        (jnp.full(4, jnp.nan), jnp.ones(3)),
    ),
    refused(
        {},
        ValueError,
        r"shape \(4,\).*got shapes \(3,\)",
        BODY,
        (jnp.ones(3), jnp.ones(3)),
    ),
    refused(
        {},
        ValueError,
        r"got shapes \(4,\) and \(2,\)",
        BODY,
        (jnp.ones(4), jnp.ones(2)),
    ),
]


@pytest.mark.parametrize(
    "system, y0, kwargs, error, message",
    SOLVER_CASES
    + STEP_CASES
    + TIME_CASES
    + SAVE_TIME_CASES
    + STATE_CASES
    + SYSTEM_CASES
    + RIGID_CASES,
)
def test_simulate_refuses_before_compiling(system, y0, kwargs, error, message):
    if system is None:
        system = HAM if kwargs.get("solver") is lj.Yoshida4 else LAG
    if system == "none":
        system = None
    kwargs = dict(t1=1.0) | kwargs
    with pytest.raises(error, match=message):
        lj.simulate(system, y0, **kwargs)


@pytest.mark.parametrize("system", [LAG, HAM], ids=["lagrangian", "hamiltonian"])
def test_integer_y0_is_converted_not_refused(system):
    # Documented: (1, 0) starts the same run as (1.0, 0.0). Closed form cos(ωt).
    trajectory = lj.simulate(system, (1, 0), t1=1.0, dt=1e-2, solver=lj.GaussLegendre())
    assert jnp.issubdtype(trajectory.q.dtype, jnp.floating)
    assert abs(float(trajectory.q[-1]) - math.cos(OMEGA)) < 1e-8


def test_scene_y0_of_the_wrong_size_is_refused():
    scene = SimplePendulum()
    with pytest.raises(ValueError, match=r"SimplePendulum's state has shapes"):
        lj.simulate(scene, (jnp.ones(2), jnp.ones(2)), t1=1.0)
    with pytest.raises(TypeError, match=r"y0 must be a pair.*\(q0, p0\)"):
        lj.simulate(scene, scene.initial_state()[0], t1=1.0)


def test_tracer_times_are_not_checked_but_structures_are():
    # Under jit the values are unknown: the call compiles; a bad structure does not.
    run = jax.jit(lambda t1: lj.simulate(LAG, Y0, t1=t1, dt=0.1).q)
    assert abs(float(run(1.0)[-1]) - math.cos(OMEGA)) < 1e-3
    with pytest.raises(TypeError, match="y0 must be a pair"):
        jax.jit(lambda q: lj.simulate(LAG, q, t1=1.0).q)(jnp.ones(2))
