"""BitReversible: splitting on an integer lattice, undone to the last bit.

The oracles: a run walked back step by step returns to its start bit for bit
(integer arithmetic is invertible); the reversible adjoint, which keeps no
checkpoint for it, then gives the gradient of reverse mode through the stored
run to round-off, and exactly the gradient it gives with a checkpoint at every
step; the lattice run is the wrapped splitting up to the lattice's rounding
(the same orbit to ~1e-13, the method's order on a nonlinear problem); a state
leaving the lattice's range is refused by name.
"""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.solvers.splitting import AbstractSplittingSolver


def _potential(q, t, mu):
    return -mu / jnp.sqrt(jnp.sum(q**2))


KEPLER = lj.SeparableHamiltonian(lambda p: 0.5 * jnp.sum(p**2), _potential)
Y0 = (jnp.array([1.0, 0.0]), jnp.array([0.0, 1.2]))  # e = 0.44
MU = jnp.asarray(1.0)
H = 0.01  # not a power of two: the step times t0 + k·h are rounded


def _relative_gap(a, b) -> float:
    a, b = jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)
    scale = max(float(jnp.max(jnp.abs(x))) for x in b)
    return max(float(jnp.max(jnp.abs(x - y))) for x, y in zip(a, b)) / scale


@pytest.mark.parametrize(
    "method", [lj.StormerVerlet(), lj.Yoshida4(), lj.BlanesMoan4()]
)
def test_steps_back_undo_the_run_to_the_last_bit(method):
    solver = lj.BitReversible(method)
    terms, _, _ = KEPLER.integration(solver, Y0, 0.0, MU)
    state = solver.init(terms, 0.0, H, Y0, MU)
    steps = 500

    # Two separately compiled loops, as the run and the adjoint's walk are.
    @jax.jit
    def forward(y, state):
        def one(carry, k):
            y, state = carry
            y, _, _, state, _ = solver.step(
                terms, k * H, (k + 1) * H, y, MU, state, False
            )
            return (y, state), None

        return jax.lax.scan(one, (y, state), jnp.arange(steps))[0]

    @jax.jit
    def backward(y, state):
        def one(carry, k):
            y, state = carry
            y, _, _, state, _ = solver.step(
                terms, (k + 1) * H, k * H, y, MU, state, False
            )
            return (y, state), None

        return jax.lax.scan(one, (y, state), jnp.arange(steps)[::-1])[0]

    y1, state1 = forward(Y0, state)
    assert float(jnp.max(jnp.abs(y1[0] - Y0[0]))) > 0.1  # it went somewhere
    y_back, state_back = backward(y1, state1)
    for start, back in zip(jax.tree_util.tree_leaves(state[1]),
                           jax.tree_util.tree_leaves(state_back[1])):  # fmt: skip
        assert start.dtype == jnp.int64
        np.testing.assert_array_equal(back, start)
    lattice, (q_units, p_units) = state[0], state[1]
    np.testing.assert_array_equal(y_back[0], lattice.decode_q(q_units))
    np.testing.assert_array_equal(y_back[1], lattice.decode_p(p_units))


LATTICE_YOSHIDA4 = lj.BitReversible(lj.Yoshida4())


def _loss(y0, mu, adjoint, steps=1000, solver=LATTICE_YOSHIDA4):
    ts = np.linspace(steps * H / 4, steps * H, 4)
    run = lj.simulate(KEPLER, y0, t1=steps * H, dt=H, ts=ts, args=mu, solver=solver,
                      adjoint=adjoint)  # fmt: skip
    return jnp.sum(run.q[:, 0]) + run.p[-1, 1] ** 2


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_reversible_gradient_is_reverse_mode_through_the_stored_run():
    stored = jax.grad(_loss, argnums=(0, 1))(Y0, MU, None)
    walked = jax.grad(_loss, argnums=(0, 1))(Y0, MU, lj.ReversibleAdjoint())
    every_step = jax.grad(_loss, argnums=(0, 1))(
        Y0, MU, lj.ReversibleAdjoint(checkpoints=1)
    )
    assert _relative_gap(walked, stored) < 1e-12
    # No checkpoint and a checkpoint at every step walk through the same states:
    # only the cotangents' own round-off (compiled apart) may differ.
    assert _relative_gap(walked, every_step) < 1e-14


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_forward_mode_matches_reverse_mode_and_finite_differences():
    def final(mu):
        return _loss(Y0, mu, lj.ReversibleAdjoint(), steps=300)

    reverse = jax.grad(final)(MU)
    forward = jax.jacfwd(lambda mu: _loss(Y0, mu, diffrax.ForwardMode(), steps=300))(MU)
    eps = 1e-6
    difference = (final(MU + eps) - final(MU - eps)) / (2 * eps)
    assert abs(float(reverse - forward)) < 1e-10 * abs(float(reverse))
    assert abs(float(reverse - difference)) < 1e-6 * abs(float(reverse))


def test_default_adjoint_keeps_no_checkpoint_for_an_exact_walk():
    adjoint = lj.ReversibleAdjoint()
    assert adjoint.spacing(10**6, 80, exact=True) is None
    assert adjoint.spacing(10**6, 80) == 1000
    assert lj.ReversibleAdjoint(checkpoints=50).spacing(10**6, 80, exact=True) == 50


def _pendulum():
    return lj.SeparableHamiltonian(lambda p: 0.5 * p**2, lambda q: -jnp.cos(q))


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_the_lattice_run_is_the_splitting_up_to_rounding_and_keeps_its_order():
    pendulum, y0 = _pendulum(), (jnp.asarray(1.2), jnp.asarray(0.0))
    reference = lj.simulate(pendulum, y0, t1=4.0, dt=1e-3, solver=lj.Yoshida6())
    errors = []
    for dt in (0.2, 0.1):
        lattice = lj.simulate(pendulum, y0, t1=4.0, dt=dt,
                              solver=lj.BitReversible(lj.Yoshida4()))  # fmt: skip
        floating = lj.simulate(pendulum, y0, t1=4.0, dt=dt, solver=lj.Yoshida4())
        assert abs(float(lattice.q[-1] - floating.q[-1])) < 1e-13
        errors.append(abs(float(lattice.q[-1] - reference.q[-1])))
    order = np.log2(errors[0] / errors[1])
    assert 3.6 < order < 4.4, order


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_vmap_over_initial_states():
    q0s = jnp.array([[1.0, 0.0], [0.8, 0.1], [1.2, -0.1]])

    def final(q0):
        run = lj.simulate(KEPLER, (q0, Y0[1]), t1=1.0, dt=H, args=MU,
                          solver=lj.BitReversible(lj.StormerVerlet()))  # fmt: skip
        return run.q[-1]

    batched = jax.vmap(final)(q0s)
    for q0, row in zip(q0s, batched):
        np.testing.assert_array_equal(final(q0), row)


def test_a_state_leaving_the_lattice_is_refused_by_name():
    solver = lj.BitReversible(lj.StormerVerlet(), q_range=1.5)  # the orbit reaches 2.6
    with pytest.raises(Exception, match="BitReversible state leaving its integer"):
        lj.simulate(KEPLER, Y0, t1=5.0, dt=H, args=MU, solver=solver)


class _Lopsided(AbstractSplittingSolver):
    kick_coefficients = (0.25, 0.75)
    drift_coefficients = (1.0,)
    nominal_order = 1
    compensated: bool = False


def test_bad_arguments_are_refused_by_name():
    with pytest.raises(ValueError, match="palindromic"):
        lj.BitReversible(_Lopsided())
    with pytest.raises(TypeError, match="splitting table"):
        lj.BitReversible(lj.GaussLegendre())  # pyright: ignore[reportArgumentType]
    with pytest.raises(ValueError, match="q_range"):
        lj.BitReversible(lj.Yoshida4(), q_range=0.0)
    with pytest.raises(ValueError, match="headroom"):
        lj.BitReversible(lj.Yoshida4(), headroom=0.5)


def test_without_x64_it_is_refused_by_name():
    pendulum = _pendulum()
    with jax.enable_x64(False), pytest.raises(ValueError, match="jax_enable_x64"):
        lj.simulate(pendulum, (jnp.asarray(1.0), jnp.asarray(0.0)), t1=0.1,
                    dt=0.01, solver=lj.BitReversible(lj.StormerVerlet()))  # fmt: skip
