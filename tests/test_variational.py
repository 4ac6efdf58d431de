"""VariationalMidpoint: order, symplecticity, reversibility, discrete Noether."""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax._core.terms import LagrangianTerm


def double_pendulum(q, qd):
    kinetic = qd[0] ** 2 + 0.5 * qd[1] ** 2 + qd[0] * qd[1] * jnp.cos(q[0] - q[1])
    return kinetic + 9.81 * (2 * jnp.cos(q[0]) + jnp.cos(q[1]))


def central_force_polar(q, qd):
    # L = ½(ṙ² + r²θ̇²) + 1/r: θ is cyclic, so p_θ = r²θ̇ is conserved.
    r = q[0]
    return 0.5 * (qd[0] ** 2 + r**2 * qd[1] ** 2) + 1.0 / r


LAG = lj.Lagrangian(double_pendulum, quadratic_in_velocity=True)
Y0 = (jnp.array([2.0, 2.5]), jnp.zeros(2))


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_second_order_convergence_on_double_pendulum():
    reference = lj.simulate(
        LAG, Y0, t1=1.0, solver=diffrax.Dopri8(), rtol=1e-13, atol=1e-13
    )
    steps = jnp.array([0.02, 0.01, 0.005])
    errors = [
        float(
            jnp.max(
                jnp.abs(
                    lj.simulate(
                        LAG, Y0, t1=1.0, dt=float(dt), solver=lj.VariationalMidpoint()
                    ).q[-1]
                    - reference.q[-1]
                )
            )
        )
        for dt in steps
    ]
    slope = np.polyfit(np.log(steps), np.log(errors), 1)[0]
    assert abs(slope - 2.0) < 0.2


def _one_step(q, p, h=0.05):
    solver = lj.VariationalMidpoint()
    term = LagrangianTerm(LAG)
    state = solver.init(term, 0.0, h, (q, p), None)
    (q1, p1), *_ = solver.step(term, 0.0, h, (q, p), None, state, False)
    return q1, p1


def test_one_step_is_symplectic():
    q, p = jnp.array([1.1, -0.7]), jnp.array([0.4, 2.0])
    # Compiled whole: tracing the stage solve eagerly, op by op, is slower.
    defect = jax.jit(lambda q, p: lj.symplectic_defect(_one_step, q, p))(q, p)
    assert float(defect) < 1e-12


def test_step_back_returns_to_start():
    q, p = jnp.array([1.1, -0.7]), jnp.array([0.4, 2.0])
    q1, p1 = _one_step(q, p, 0.05)
    solver, term = lj.VariationalMidpoint(), LagrangianTerm(LAG)
    state = solver.init(term, 0.05, 0.0, (q1, p1), None)
    (q0, p0), *_ = solver.step(term, 0.05, 0.0, (q1, p1), None, state, False)
    assert np.allclose(q0, q, atol=1e-13) and np.allclose(p0, p, atol=1e-13)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_discrete_noether_and_bounded_energy():
    lag = lj.Lagrangian(central_force_polar, quadratic_in_velocity=True)
    y0 = (jnp.array([0.4, 0.0]), jnp.array([0.0, 5.0]))  # r²θ̇ = 0.8, e ≈ 0.36
    ts = jnp.linspace(0.0, 200.0, 401)
    traj = lj.simulate(
        lag, y0, t1=200.0, dt=0.002, solver=lj.VariationalMidpoint(), ts=ts
    )
    p_theta = traj.p[:, 1]
    assert float(jnp.max(jnp.abs(p_theta - 0.8))) < 1e-12
    energy = traj.energy()
    error = jnp.abs(energy - energy[0])
    half = len(ts) // 2
    assert float(jnp.max(error)) < 1e-4
    assert float(jnp.max(error[half:])) <= 2.0 * float(jnp.max(error[:half]))


def test_rejects_hamiltonian_system():
    import pytest

    ham = lj.Hamiltonian(lambda q, p: 0.5 * p**2 + 0.5 * q**2)
    with pytest.raises(ValueError, match="discretizes a Lagrangian"):
        lj.simulate(ham, (1.0, 0.0), dt=0.1, solver=lj.VariationalMidpoint())


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_vmap_matches_loop():
    q0s = jnp.stack([jnp.array([0.5, 0.1]) * k for k in range(1, 5)])

    def final(q0):
        return lj.simulate(
            LAG, (q0, jnp.zeros(2)), t1=0.5, dt=0.01, solver=lj.VariationalMidpoint()
        ).q[-1]

    batched = jax.vmap(final)(q0s)
    looped = jnp.stack([final(q) for q in q0s])
    assert np.allclose(batched, looped, atol=1e-13)
