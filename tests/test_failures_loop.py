"""Catalogue of failures only the integration loop can see: blow-ups, partial
results with throw=False, sweeps with a failing member, starts off the constraints.

A run that fails must say so — a `result` that is not successful, an error naming
the cause with throw=True — and with throw=False return what it computed up to the
failure. None of these may come back as a successful run.
"""

import math

import diffrax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.cli import main
from lagjax.scenes.chains import FermiPastaUlamChain
from lagjax.scenes.constrained import CartesianPendulum, RollingDisk

STIFF = lj.SeparableHamiltonian(lambda p: 0.5 * p**2, lambda q: 5e3 * q**2)
# ω = 100: Störmer–Verlet is stable for h·ω < 2, here h·ω = 3.


def test_symplectic_blow_up_raises():
    with pytest.raises(Exception, match=r"(?i)diverg|energy|non-finite"):
        lj.simulate(STIFF, (1.0, 0.0), t1=3.0, dt=0.03, solver=lj.StormerVerlet())


def test_symplectic_blow_up_is_flagged_with_throw_false():
    run = lj.simulate(
        STIFF, (1.0, 0.0), t1=3.0, dt=0.03, solver=lj.StormerVerlet(), throw=False
    )
    assert run.result != diffrax.RESULTS.successful


def test_explicit_runge_kutta_beyond_its_stability_limit_is_flagged():
    # Tsit5's real stability interval is ≈ [−3.5, 0]; h·ω = 10 leaves it.
    run = lj.simulate(
        STIFF, (1.0, 0.0), t1=3.0, dt=0.1, solver=diffrax.Tsit5(), throw=False
    )
    assert run.result != diffrax.RESULTS.successful


def test_saved_blow_up_is_flagged_and_keeps_the_good_part():
    ts = jnp.linspace(0.0, 3.0, 31)
    run = lj.simulate(
        STIFF,
        (1.0, 0.0),
        t1=3.0,
        dt=0.03,
        ts=ts,
        solver=lj.StormerVerlet(),
        throw=False,
    )
    assert run.result != diffrax.RESULTS.successful
    assert bool(jnp.isfinite(run.q[0]))


def test_command_line_step_far_too_large_fails(capsys):
    code = main(["run", "simple-pendulum", "--solver", "Tsit5", "--dt", "100",
                 "--t1", "1000"])  # fmt: skip
    assert code != 0
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.startswith("lagjax: error:")


def test_fixed_step_failure_with_throw_false_returns_the_partial_run():
    # L linear in q̇ at q = 0: the mass matrix q² vanishes when the run reaches q = 0.
    lag = lj.Lagrangian(lambda q, qd: 0.5 * q**2 * qd**2 - 0.5 * q**2)
    ts = jnp.linspace(0.0, 5.0, 51)
    run = lj.simulate(
        lag, (1.0, -1.0), t1=5.0, dt=0.01, ts=ts, solver=diffrax.Heun(), throw=False
    )
    assert run.result != diffrax.RESULTS.successful
    assert bool(jnp.isfinite(run.q[0])) and float(run.q[0]) == 1.0


def test_sweep_with_one_failing_member_keeps_the_others():
    y0s = (jnp.array([1.0, 1.0, 1.0]), jnp.array([0.0, 0.0, 0.0]))
    systems = lj.SeparableHamiltonian(
        lambda p: 0.5 * p**2, lambda q, t, k: 0.5 * k * q**2
    )
    # Stiffness 1e4 at dt = 0.03 blows up; 1 and 4 do not.
    run = lj.sweep(
        systems,
        y0s,
        jnp.array([1.0, 1e4, 4.0]),
        t1=3.0,
        dt=0.03,
        solver=lj.StormerVerlet(),
        throw=False,
    )
    assert float(run.q[0, -1]) == pytest.approx(math.cos(3.0), abs=1e-2)
    assert float(run.q[2, -1]) == pytest.approx(math.cos(6.0), abs=1e-2)
    results = np.asarray(run.result._value)
    assert results[1] != 0 and results[0] == 0 and results[2] == 0


def test_start_off_the_holonomic_constraint_is_refused():
    scene = CartesianPendulum()
    q, qdot = scene.initial_state()
    with pytest.raises(Exception, match=r"(?i)constraint.*residual|violat"):
        lj.simulate(scene, (1.5 * q, qdot), t1=1.0, dt=0.01)


def test_slipping_start_of_the_rolling_disk_is_refused():
    scene = RollingDisk()
    q, rates = scene.initial_state()
    with pytest.raises(Exception, match=r"(?i)constraint|slip|violat"):
        lj.simulate(scene, (q, rates.at[0].add(0.5)), t1=0.1, dt=0.01)


def test_stiff_stage_failure_names_newton():
    # FPU at h·ω = 1.5: the fixed-point stage iteration stops at its limit.
    scene = FermiPastaUlamChain()
    hamiltonian = lj.Hamiltonian(lambda q, p, t, s: scene.system()(q, p, t, s))
    with pytest.raises(Exception, match=r"root_finder=optimistix\.Newton"):
        lj.simulate(
            hamiltonian,
            scene.initial_state(),
            t1=3.0,
            dt=1.5 / float(scene.frequency),
            solver=lj.ImplicitMidpoint(),
            args=scene,
        )
