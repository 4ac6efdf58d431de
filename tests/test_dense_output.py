"""Dense output: the state between steps keeps the method's order (`lagjax.solvers.hermite`).

Every fixed-step solver runs a nonlinear problem at two steps h and h/2 and is read
between its steps (mid-steps, off the grid) against a tight Dopri8 reference; the
log-log slope of the error is the order between steps: min(p, 4) for the cubic
Hermite extension (p ≤ 4), 6 for the quintic (p > 4).
"""

import functools

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.special_functions import complete_elliptic_k

PENDULUM = lj.SeparableHamiltonian(lambda p: 0.5 * p**2, lambda q: -jnp.cos(q))
PENDULUM_L = lj.Lagrangian(lambda q, qdot: 0.5 * qdot**2 + jnp.cos(q))
START = (jnp.asarray(2.0), jnp.asarray(0.0))
SPAN = 2.0


def spherical_pendulum(q, qdot):
    return 0.5 * jnp.sum(qdot**2) - q[2]


SPHERICAL = lj.Lagrangian(
    spherical_pendulum, constraints=lambda q: jnp.sum(q**2)[None] - 1.0
)
SPHERICAL_START = (
    jnp.array([jnp.sin(1.0), 0.0, -jnp.cos(1.0)]),
    jnp.array([0.0, 0.8, 0.0]),
)
BODY = lj.RigidBody(jnp.array([1.0, 2.0, 3.0]))
BODY_START = BODY.state_from_angular_velocity(
    jnp.array([1.0, 0.0, 0.0, 0.0]), jnp.array([0.3, 1.0, 0.2])
)

PROBLEMS = {
    "pendulum": (PENDULUM, START),
    "pendulum L": (PENDULUM_L, START),
    "spherical pendulum": (SPHERICAL, SPHERICAL_START),
    "free body": (BODY, BODY_START),
}
SLOW = pytest.mark.slow

# (problem, solver, coarse step, order between steps); the slow ones run in the
# long suite (each case compiles a dense diffrax loop: ~10 s on a loaded CPU).
CASES = {
    "StormerVerlet": ("pendulum", lj.StormerVerlet(), 0.1, 2),
    "Yoshida4": ("pendulum", lj.Yoshida4(), 0.1, 4),
    "Yoshida6": ("pendulum", lj.Yoshida6(), 0.1, 6),
    "GaussLegendre2": ("pendulum L", lj.GaussLegendre(stages=2), 0.1, 4),
    "BlanesMoan4": ("pendulum", lj.BlanesMoan4(), 0.1, 4, SLOW),
    "KahanLi8": ("pendulum", lj.KahanLi8(), 0.2, 6, SLOW),
    "SofSpa10": ("pendulum", lj.SofSpa10(), 0.4, 6, SLOW),
    "ImplicitMidpoint": ("pendulum L", lj.ImplicitMidpoint(), 0.1, 2, SLOW),
    "GaussLegendre3": ("pendulum L", lj.GaussLegendre(stages=3), 0.2, 6, SLOW),
    "VariationalMidpoint": ("pendulum L", lj.VariationalMidpoint(), 0.1, 2, SLOW),
    "Rattle": ("spherical pendulum", lj.Rattle(), 0.1, 2, SLOW),
    "RigidBodyVerlet": ("free body", lj.RigidBodyVerlet(), 0.1, 2, SLOW),
    "RigidBodyYoshida4": ("free body", lj.RigidBodyYoshida4(), 0.2, 4, SLOW),
}


def jacobi_sn_cn(u, m):
    """sn(u|m), cn(u|m) by the descending Landen (AGM) transformation
    (Abramowitz & Stegun 16.4)."""
    a, b, c = [1.0], np.sqrt(1.0 - m), [np.sqrt(m)]
    while abs(c[-1]) > 1e-17:
        a.append((a[-1] + b) / 2)
        c.append((a[-2] - b) / 2)
        b = np.sqrt(a[-2] * b)
    phi = 2.0 ** (len(a) - 1) * a[-1] * np.asarray(u)
    for n in range(len(a) - 1, 0, -1):
        phi = (phi + np.arcsin(c[n] / a[n] * np.sin(phi))) / 2
    return np.sin(phi), np.cos(phi)


class ExactPendulum:
    """θ(t), θ̇(t) of the unit pendulum released at rest from θ0 = 2:
    sin(θ/2) = k sn(K − t | k²), θ̇ = −2k cn(K − t | k²), k = sin(θ0/2)."""

    def evaluate(self, t):
        k = np.sin(float(START[0]) / 2)
        quarter = float(complete_elliptic_k(jnp.asarray(k**2)))
        sn, cn = jacobi_sn_cn(quarter - np.asarray(t), k**2)
        return 2 * np.arcsin(k * sn), -2 * k * cn


@functools.cache
def reference(problem: str):
    if problem.startswith("pendulum"):
        return ExactPendulum()
    system, y0 = PROBLEMS[problem]
    return lj.simulate(
        system, y0, t1=SPAN, solver=diffrax.Dopri8(), rtol=1e-13, atol=1e-13, dense=True
    )


def off_grid_error(system, y0, solver, dt, exact) -> float:
    """Largest state error at the mid-steps (and a quarter in) of a dense run."""
    # One max_steps for both steps, so the second run reuses the compilation.
    run = lj.simulate(
        system, y0, t1=SPAN, dt=dt, solver=solver, dense=True, max_steps=64
    )
    times = (
        jnp.concatenate(
            [jnp.arange(0.5, SPAN / dt - 1, 1.0), jnp.arange(0.25, SPAN / dt - 1, 3.0)]
        )
        * dt
    )
    got, want = run.evaluate(times), exact.evaluate(times)
    return max(
        float(jnp.max(jnp.abs(jnp.asarray(a) - b)))
        for a, b in zip(jax.tree_util.tree_leaves(got), jax.tree_util.tree_leaves(want))
    )


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
@pytest.mark.parametrize(
    "name", [pytest.param(name, marks=case[4:]) for name, case in CASES.items()]
)
def test_order_between_steps(name):
    problem, solver, dt, order = CASES[name][:4]
    system, y0 = PROBLEMS[problem]
    exact = reference(problem)  # cached: one per problem
    errors = [off_grid_error(system, y0, solver, h, exact) for h in (dt, dt / 2)]
    slope = np.log2(errors[0] / errors[1])
    assert abs(slope - order) < 0.35, (errors, slope)


def test_linear_interpolation_is_replaced():
    """Before lagjax.solvers.hermite the fixed-step solvers interpolated linearly: 3.6e-6
    between steps against ~1e-9 at the steps. Yoshida6 at h = 0.01 now matches its
    grid accuracy between steps too."""
    exact = reference("pendulum")
    error = off_grid_error(PENDULUM, START, lj.Yoshida6(), 0.05, exact)
    assert error < 1e-9


def test_evaluate_speaks_the_callers_convention():
    """A Lagrangian run by GaussLegendre integrates (q, p); evaluate gives (q, q̇)."""
    mass = 2.0
    lagrangian = lj.Lagrangian(lambda q, qdot: 0.5 * mass * qdot**2 + jnp.cos(q))
    run = lj.simulate(
        lagrangian, START, t1=SPAN, dt=0.05, solver=lj.GaussLegendre(), dense=True
    )
    assert run.is_hamiltonian  # the integrated state is (q, p) ...
    q, qdot = run.evaluate(jnp.asarray(SPAN))
    assert np.isclose(q, run.q[-1], rtol=1e-12, atol=1e-12)
    assert np.isclose(qdot, run.p[-1] / mass, rtol=1e-12, atol=1e-12)  # ... not here


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_saveat_dense_and_off_grid_ts_use_the_extension():
    """SaveAt(dense=True) keeps the extension; ts off the grid are read from it."""
    exact = reference("pendulum")
    ts = jnp.array([0.123, 1.0, 1.777])
    run = lj.simulate(
        PENDULUM, START, t1=SPAN, dt=0.05, solver=lj.Yoshida6(),
        saveat=diffrax.SaveAt(ts=ts, dense=True),
    )  # fmt: skip
    q_exact, _ = exact.evaluate(ts)
    # Linear interpolation between steps would be off by ~1e-4 here.
    assert np.max(np.abs(run.q - q_exact)) < 1e-9
    assert np.max(np.abs(run.evaluate(ts)[0] - run.q)) < 1e-14


def test_evaluate_refuses_without_dense_output_and_outside_the_span():
    run = lj.simulate(PENDULUM, START, t1=SPAN, dt=0.1, solver=lj.Yoshida4())
    with pytest.raises(ValueError, match="dense=True"):
        run.evaluate(1.0)
    # The settings of the Yoshida4 order test: its compilation is reused.
    dense = lj.simulate(
        PENDULUM, START, t1=SPAN, dt=0.1, solver=lj.Yoshida4(), dense=True,
        max_steps=64,
    )  # fmt: skip
    with pytest.raises(Exception, match="outside the integrated span"):
        dense.evaluate(SPAN + 1.0)
