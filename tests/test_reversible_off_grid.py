"""ReversibleAdjoint with save times between steps, and its checkpoint budget.

Off-grid saves are the continuous extension over the step each time falls in;
their cotangents enter the backward walk at that step. The oracles: the plain
scan's gradient (which stores every step and differentiates the same
interpolation) to round-off, and central finite differences of the run itself.
The checkpoint budget is checked as arithmetic (its spacing) and by its effect:
marks at the spacing it picks, the gradient unchanged.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax._integrate.reversible_adjoint import ROUND_OFF_SPACING, _marks
from lagjax._integrate.reversible_off_grid import off_grid_marks
from tests.test_reversible_adjoint import _kepler


def _relative_gap(a, b) -> float:
    a, b = jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)
    scale = max(float(jnp.max(jnp.abs(x))) for x in b)
    return max(float(jnp.max(jnp.abs(x - y))) for x, y in zip(a, b)) / scale


# Unevenly spaced, none on the grid of dt = 0.01; two in one step (4.2031, 4.2077)
# and one in the first step.
OFF_GRID_TS = np.array([0.004, 1.2345, 2.5, 4.2031, 4.2077, 7.77777, 9.9951])


def _off_grid_loss(adjoint, solver=None, steps=1000):
    system, _, _ = _kepler()

    def loss(y0, mu):
        run = lj.simulate(system, y0, t1=steps * 0.01, dt=0.01, ts=OFF_GRID_TS,
                          solver=solver or lj.Yoshida4(), args=mu, adjoint=adjoint)  # fmt: skip
        weights = jnp.linspace(0.5, 1.5, OFF_GRID_TS.size)
        return jnp.sum(weights * jnp.sin(run.ys[0][:, 0])) + 0.3 * jnp.sum(
            run.ys[1] ** 2
        )

    return loss


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_off_grid_saves_agree_with_the_plain_scan():
    _, y0, mu = _kepler()
    expected = jax.grad(_off_grid_loss(None), argnums=(0, 1))(y0, mu)
    # Checkpoints every 100 steps as well: marks at the brackets and between.
    for adjoint in (lj.ReversibleAdjoint(), lj.ReversibleAdjoint(checkpoints=100)):
        # Under jit too: the save times stay static there.
        gradient = jax.jit(jax.grad(_off_grid_loss(adjoint), argnums=(0, 1)))
        actual = gradient(y0, mu)
        assert _relative_gap(actual, expected) < 1e-12


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_off_grid_saves_are_the_plain_scans_and_match_finite_differences():
    _, y0, mu = _kepler()
    system = _kepler()[0]
    runs = [
        lj.simulate(
            system,
            y0,
            t1=10.0,
            dt=0.01,
            ts=OFF_GRID_TS,
            solver=lj.StormerVerlet(),
            args=mu,
            adjoint=adjoint,
        )
        for adjoint in (None, lj.ReversibleAdjoint())
    ]
    assert _relative_gap(runs[1].ys, runs[0].ys) < 1e-14
    loss = _off_grid_loss(lj.ReversibleAdjoint(), lj.StormerVerlet())
    derivative = jax.grad(loss, argnums=1)(y0, mu)
    eps = 1e-6
    difference = (loss(y0, mu + eps) - loss(y0, mu - eps)) / (2 * eps)
    assert abs(float(derivative - difference)) < 1e-7 * abs(float(derivative))


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
@pytest.mark.parametrize(
    "solver", [lj.Yoshida4(), lj.BitReversible(lj.Yoshida4()), lj.Yoshida6()]
)
def test_dense_output_cotangents_enter_at_every_step(solver):
    # Cubic (Yoshida4) and quintic (Yoshida6) Hermite extensions, evaluated
    # between steps: the reversible gradient is the stored run's.
    system, y0, mu = _kepler()
    between = jnp.array([0.333, 1.71, 2.777])

    def loss(y0, mu, adjoint):
        run = lj.simulate(system, y0, t1=3.0, dt=0.01, args=mu, solver=solver,
                          dense=True, adjoint=adjoint)  # fmt: skip
        q, p = jax.vmap(run.evaluate)(between)
        return jnp.sum(q[:, 0] ** 2) + p[-1, 1]

    stored = jax.grad(loss, argnums=(0, 1))(y0, mu, None)
    walked = jax.grad(loss, argnums=(0, 1))(y0, mu, lj.ReversibleAdjoint())
    assert _relative_gap(walked, stored) < 1e-13


def test_checkpoint_budget_spacing():
    adjoint = lj.ReversibleAdjoint()  # 1 MiB
    # Kepler, Yoshida4: state 32 B, compensation 32 B, force 16 B.
    assert adjoint.spacing(10**3, 80) is None  # the whole run: no checkpoints
    assert adjoint.spacing(10**6, 80) == ROUND_OFF_SPACING  # round-off floor
    assert adjoint.spacing(10**8, 80) == 7630  # the budget: ⌈10⁸·80 / 2²⁰⌉
    assert lj.ReversibleAdjoint(checkpoint_bytes=0).spacing(10**8, 80) is None
    assert lj.ReversibleAdjoint(checkpoints=7).spacing(10**3, 80) == 7
    with pytest.raises(ValueError, match="checkpoint_bytes"):
        lj.ReversibleAdjoint(checkpoint_bytes=-1)


def test_marks_keep_the_saves_and_space_the_checkpoints():
    # Saves every 1200 steps from 300: a divisor of 1200 near 1000 keeps the
    # marks uniform (600: within 2× of the spacing).
    saves = [300 + 1200 * i for i in range(5)]
    uniform = _marks(saves, 1000)
    assert uniform.gaps is None and uniform.every == 600
    assert set(saves) <= set(uniform.positions())
    # Saves every 1009 steps (a prime): no good divisor, marks irregular.
    saves = [1009 * i for i in range(1, 4)]
    irregular = _marks(saves, 1000)
    positions = irregular.positions()
    assert irregular.gaps is not None and set(saves) <= set(positions)
    assert max(np.diff(positions)) <= 1000
    assert list(off_grid_marks(np.array([5, 5, 2500]), 1000)) == [
        0,
        5,
        1000,
        2000,
        2500,
    ]


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_saves_on_the_grid_with_irregular_checkpoints():
    # Saves every 7 steps (a prime) with checkpoints every 5: no divisor of 7
    # near 5, so the marks are the saves and every 5th step, irregular.
    system, y0, mu = _kepler()
    ts = 0.07 * np.arange(1, 15)

    def loss(adjoint):
        def value(y0, mu):
            run = lj.simulate(system, y0, t1=1.0, dt=0.01, ts=ts, solver=lj.Yoshida4(),
                              args=mu, adjoint=adjoint)  # fmt: skip
            return jnp.sum(jnp.sin(run.ys[0])) + 0.3 * jnp.sum(run.ys[1] ** 2)

        return value

    assert _marks([7 * i for i in range(1, 15)], 5).gaps is not None
    expected = jax.grad(loss(None), argnums=(0, 1))(y0, mu)
    actual = jax.grad(loss(lj.ReversibleAdjoint(checkpoints=5)), argnums=(0, 1))(y0, mu)
    assert _relative_gap(actual, expected) < 1e-12
