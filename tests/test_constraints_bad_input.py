"""Bad constraints get an error that names the problem, never a silent wrong force."""

import jax
import jax.numpy as jnp
import pytest

import lagjax as lj
from lagjax.mechanics.constraints import Constraints
from tests.helpers import assert_singular_verdicts


def free_particle(q, qdot):
    return 0.5 * jnp.sum(qdot**2) - 9.81 * q[1]


def squared_length(q):
    # Degenerate at the origin: its gradient G = q vanishes there.
    return 0.5 * (q[0] ** 2 + q[1] ** 2 - 1.0)


def test_rank_deficient_jacobian_raises_on_values_and_poisons_inside_jit():
    # Under a trace the default verdict is NaN (one select in a fused step), never
    # a finite acceleration; check=True keeps the run-time error inside jit.
    lag = lj.Lagrangian(free_particle, constraints=squared_length)
    assert_singular_verdicts(lag, jnp.zeros(2), jnp.zeros(2), "rank-deficient")


def test_regular_constraints_inside_jit_are_not_poisoned():
    # On the unit circle at (1, 0) moving at 0.5 along y: the rod's pull gives the
    # centripetal −v²/r along x, and gravity is all tangential there.
    lag = lj.Lagrangian(free_particle, constraints=squared_length)
    q, v = jnp.array([1.0, 0.0]), jnp.array([0.0, 0.5])
    traced = jax.jit(lag.acceleration)(q, v)
    assert jnp.allclose(traced, jnp.array([-0.25, -9.81]), rtol=0, atol=1e-13)


def test_redundant_constraints_raise():
    lag = lj.Lagrangian(
        free_particle, constraints=lambda q: jnp.stack([q[0] - 1.0, 2 * q[0] - 2.0])
    )
    with pytest.raises(Exception, match="rank-deficient"):
        jax.block_until_ready(lag.multipliers(jnp.ones(2), jnp.zeros(2)))


def test_simulate_from_a_degenerate_state_names_the_constraint():
    # q = 0 is both off the circle (g = -1/2) and where its Jacobian vanishes: the
    # start is refused first, with the residual.
    lag = lj.Lagrangian(free_particle, constraints=squared_length)
    with pytest.raises(
        Exception, match=r"violates the constraints: max \|g\(q0, t0\)\| = 0.5"
    ):
        run = lj.simulate(lag, (jnp.zeros(2), jnp.zeros(2)), t1=0.1, dt=0.01)
        jax.block_until_ready(run.q)


def test_constraint_returning_a_matrix_is_rejected():
    lag = lj.Lagrangian(free_particle, constraints=lambda q: jnp.outer(q, q))
    with pytest.raises(ValueError, match="scalar or a 1-D array"):
        lag.acceleration(jnp.ones(2), jnp.zeros(2))


def test_constraint_returning_integers_is_rejected():
    lag = lj.Lagrangian(free_particle, constraints=lambda q: jnp.int32(1))
    with pytest.raises(ValueError, match="real floats"):
        lag.acceleration(jnp.ones(2), jnp.zeros(2))


def test_more_constraints_than_coordinates_is_rejected():
    lag = lj.Lagrangian(free_particle, constraints=lambda q: jnp.concatenate([q, q]))
    with pytest.raises(ValueError, match="4 constraints on 2 coordinates"):
        lag.acceleration(jnp.ones(2), jnp.zeros(2))


def test_constraint_must_be_callable_and_nonempty():
    with pytest.raises(TypeError, match="must be callable"):
        lj.Lagrangian(free_particle, constraints=3.0)
    with pytest.raises(ValueError, match="needs a holonomic or a velocity"):
        Constraints()
    with pytest.raises(ValueError, match="baumgarte_rate"):
        Constraints(squared_length, baumgarte_rate=-1.0)


def test_multipliers_of_an_unconstrained_system():
    with pytest.raises(ValueError, match="no constraints"):
        lj.Lagrangian(free_particle).multipliers(jnp.ones(2), jnp.zeros(2))


@pytest.mark.parametrize("solver", [lj.GaussLegendre(stages=2), lj.StormerVerlet()])
def test_solvers_that_would_ignore_the_constraints_are_refused(solver):
    lag = lj.Lagrangian(free_particle, constraints=squared_length)
    y0 = (jnp.array([1.0, 0.0]), jnp.zeros(2))
    with pytest.raises(ValueError, match="does not enforce constraints"):
        lj.simulate(lag, y0, t1=0.1, dt=0.01, solver=solver)


def test_projection_onto_degenerate_constraints_raises_on_values_and_poisons_in_jit():
    from lagjax.solvers.projection import project_onto_constraints

    lag = lj.Lagrangian(free_particle, constraints=squared_length)
    q, qdot = jnp.zeros(2), jnp.array([0.3, 0.0])
    with pytest.raises(Exception, match="rank-deficient"):
        jax.block_until_ready(project_onto_constraints(lag, q, qdot, 0.0, None))
    (_, projected), _ = jax.jit(
        lambda q, v: project_onto_constraints(lag, q, v, 0.0, None)
    )(q, qdot)
    assert bool(jnp.all(jnp.isnan(projected)))
