"""The Taylor integrator (lagjax.taylor): coefficients, order, accuracy,
conservation, transformations and refusals."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.experimental import jet

import lagjax as lj
from lagjax.taylor import RESULTS, Taylor, taylor_coefficients, taylor_integrate
from lagjax.taylor.step import compensated_advance, horner, order_from_tolerance
from tests.helpers import lie_coefficients

G = 9.81


def _double_pendulum_lagrangian(q, qdot, t, args):
    (a, b), (wa, wb) = q, qdot
    kinetic = wa**2 + 0.5 * wb**2 + wa * wb * jnp.cos(a - b)
    return kinetic + 2 * G * jnp.cos(a) + G * jnp.cos(b)


LAGRANGIAN = lj.Lagrangian(_double_pendulum_lagrangian)


def double_pendulum(t, y, args):
    q, qdot = y[:2], y[2:]
    return jnp.concatenate([qdot, LAGRANGIAN.acceleration(q, qdot, t, args)])


def pendulum(t, y, args):
    return jnp.stack([y[1], -args * jnp.sin(y[0])])


Y0 = jnp.array([0.5, 0.3, 0.1, -0.2])


def _jet_coefficients(f, y0, order):
    """The same by jax.experimental.jet, one order at a time."""
    derivatives = [f(y0)]
    for _k in range(2, order + 1):
        _, series = jet.jet(f, (y0,), (derivatives,))
        derivatives.append(series[-1])
    return jnp.stack(
        [y0] + [d / math.factorial(k) for k, d in enumerate(derivatives, 1)]
    )


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
@pytest.mark.parametrize(
    "unroll, scalar",
    [pytest.param(True, False, marks=pytest.mark.slow), (False, False), (False, True)],
)
def test_coefficients_match_jet_and_nested_jvp(unroll, scalar):
    f = lambda y: double_pendulum(0.0, y, None)
    coefficients = jax.jit(
        lambda y0: taylor_coefficients(
            double_pendulum, 0.0, y0, order=6, unroll=unroll, scalar=scalar
        )
    )
    ours = coefficients(Y0)
    # order 6: jet's nested series compile in seconds (order 8 took most of a minute)
    by_jet = jax.jit(lambda y0: _jet_coefficients(f, y0, 6))(Y0)
    by_jvp = jax.jit(lambda y0: lie_coefficients(f, y0, 3))(Y0)
    scale = jnp.max(jnp.abs(by_jet), axis=1, keepdims=True)
    assert jnp.max(jnp.abs(ours - by_jet) / scale) < 1e-13
    assert jnp.max(jnp.abs(ours[:4] - by_jvp) / scale[:4]) < 1e-13


def _many_primitives(t, y, args):
    a, b = y[0], y[1]
    return (
        jnp.stack(
            [
                jnp.exp(0.3 * a) * jnp.log(2.0 + b) + jnp.sqrt(1.5 + a) / (2.0 + b**2),
                jnp.tan(0.2 * a)
                - jnp.tanh(b)
                + (1.2 + a) ** 1.7
                + jax.lax.rsqrt(2.0 + b),
                jnp.abs(a - 3.0)
                + jnp.maximum(b, -5.0)
                + jnp.expm1(0.1 * b)
                + jnp.log1p(0.5 + 0.1 * a)
                + a**-2
                + jnp.cbrt(4.0 + b)
                + t * a,
            ]
        )[:2]
        + jnp.array([[1.0, 0.2], [0.1, 1.0]]) @ y
    )


def test_coefficients_of_every_rule_match_nested_jvp():
    from lagjax.taylor.coefficients import lower_vector_field
    from lagjax.taylor.tape import supports

    y0 = jnp.array([0.7, -0.4])
    ours = jax.jit(lambda y: taylor_coefficients(_many_primitives, 0.0, y, order=5))(y0)
    # The scalar graph of one trajectory, its orders on the tape.
    graph, _ = lower_vector_field(_many_primitives, 0.0, y0, None, scalar=True)
    assert graph.scalar and supports(graph)
    by_tape = jax.jit(
        lambda y: taylor_coefficients(
            _many_primitives, 0.0, y, order=5, unroll=False, scalar=True
        )
    )(y0)

    # Time enters explicitly: extend the state with t to use the autonomous reference.
    def extended(z):
        return jnp.concatenate([_many_primitives(z[2], z[:2], None), jnp.ones(1)])

    z0 = jnp.concatenate([y0, jnp.zeros(1)])
    reference = jax.jit(lambda z: lie_coefficients(extended, z, 5))(z0)
    assert jnp.allclose(ours, reference[:, :2], rtol=1e-12, atol=1e-13)
    assert jnp.allclose(by_tape, reference[:, :2], rtol=1e-12, atol=1e-13)


def test_unsupported_primitive_is_refused_by_name():
    def field(t, y, args):
        return jax.scipy.special.erf(y)

    with pytest.raises(NotImplementedError, match="'erf'"):
        taylor_coefficients(field, 0.0, jnp.ones(2), order=4)


@pytest.mark.parametrize("name", ["rtol", "atol"])
@pytest.mark.parametrize("value", [0.0, -1e-9, float("nan")])
def test_bad_tolerances_are_refused_by_name(name, value):
    tolerances = {"rtol": 1e-12, "atol": 1e-12, name: value}
    with pytest.raises(ValueError, match=name):
        taylor_integrate(pendulum, jnp.ones(2), 0.0, 1.0, args=1.0, **tolerances)
    with pytest.raises(ValueError, match=name):
        Taylor(**tolerances)


def test_order_rule():
    assert order_from_tolerance(1e-12) == 15
    assert order_from_tolerance(1e-15) == 19
    assert Taylor(rtol=1e-15, atol=1e-15).resolved_order == 19


def _fixed_steps(f, y0, h, n, order):
    def body(_, y):
        return horner(taylor_coefficients(f, 0.0, y, order=order, unroll=False), h)

    return jax.lax.fori_loop(0, n, body, y0)


def test_compensated_advance_keeps_increments_below_the_last_bit():
    """A thousand increments of 1e-17 on y = 1 (each below half an ulp): a plain
    sum keeps 1.0; the compensated state ends at 1 + 1e-14 to round-off."""
    coeffs = lambda y: jnp.stack([y, jnp.full(1, 1e-17)])
    assert float(horner(coeffs(jnp.ones(1)), 1.0)[0]) == 1.0  # plain: lost

    def step(_, state):
        return compensated_advance(coeffs(state[0]), jnp.asarray(1.0), state[1])

    y, y_low = jax.jit(
        lambda: jax.lax.fori_loop(0, 1000, step, (jnp.ones(1), jnp.zeros(1)))
    )()
    total = np.longdouble(float(y[0])) + np.longdouble(float(y_low[0]))
    assert abs(float(total - (1 + np.longdouble(1e-14)))) < 1e-27
    assert abs(float(y[0]) - (1 + 1e-14)) <= 2.3e-16  # the high part moved too


def test_order_of_the_method_on_the_pendulum():
    y0 = jnp.array([1.2, 0.0])
    f = lambda t, y, args: pendulum(t, y, 1.0)
    exact = _fixed_steps(f, y0, 0.01, 200, 16)
    steps = np.array([8, 16, 32])
    errors = [
        float(jnp.max(jnp.abs(_fixed_steps(f, y0, 2.0 / n, n, 4) - exact)))
        for n in steps
    ]
    slope = -np.polyfit(np.log(steps), np.log(errors), 1)[0]
    assert 3.7 < slope < 4.5, (errors, slope)


@pytest.fixture(scope="module")
def double_pendulum_runs():
    run = jax.jit(
        lambda y0, rtol, order: taylor_integrate(
            double_pendulum, y0, 0.0, 100.0, rtol=rtol, atol=rtol, order=order
        ),
        static_argnums=(1, 2),
    )
    return run(Y0, 1e-15, None), run(Y0, 1e-16, 26)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_double_pendulum_to_t_100_reaches_1e_12(double_pendulum_runs):
    solution, reference = double_pendulum_runs
    assert solution.result == RESULTS.successful
    assert reference.result == RESULTS.successful
    assert solution.order == 19
    assert float(jnp.max(jnp.abs(solution.ys[-1] - reference.ys[-1]))) < 1e-12


def test_dense_output_of_the_harmonic_oscillator():
    ts = jnp.linspace(0.0, 10.0, 41)  # more than SMALL_SAVES: the inner saving loop
    oscillator = lambda t, y, args: jnp.stack([y[1], -y[0]])
    solution = taylor_integrate(oscillator, jnp.array([1.0, 0.0]), 0.0, 10.0, ts=ts)
    assert jnp.allclose(solution.ys[:, 0], jnp.cos(ts), rtol=0, atol=1e-14)
    assert jnp.allclose(solution.ys[:, 1], -jnp.sin(ts), rtol=0, atol=1e-14)
    assert int(solution.num_steps) < 41  # several save times per step


def test_backward_in_time_retraces_the_forward_run():
    oscillator = lambda t, y, args: jnp.stack([y[1], -y[0]])
    y0 = jnp.array([1.0, 0.0])
    forward = taylor_integrate(oscillator, y0, 0.0, 5.0).ys[-1]
    back = taylor_integrate(oscillator, forward, 5.0, 0.0).ys[-1]
    assert jnp.allclose(back, y0, rtol=0, atol=1e-14)


def test_pendulum_energy_has_no_linear_drift():
    periods, period = 300, 7.42  # amplitude 1.5, g/l = 1: period ≈ 7.42
    ts = jnp.linspace(0.0, periods * period, 301)
    y0 = jnp.array([1.5, 0.0])
    solution = taylor_integrate(pendulum, y0, 0.0, ts[-1], ts=ts, args=1.0)
    energy = 0.5 * solution.ys[:, 1] ** 2 - jnp.cos(solution.ys[:, 0])
    error = np.asarray(energy - energy[0])
    assert np.max(np.abs(error)) < 5e-14
    slope_over_run = np.polyfit(np.asarray(ts), error, 1)[0] * float(ts[-1])
    assert abs(slope_over_run) < 2e-14


def test_max_steps_reached_is_reported():
    solution = taylor_integrate(
        pendulum, jnp.array([1.0, 0.0]), 0.0, 100.0, args=1.0, max_steps=3
    )
    assert solution.result == RESULTS.max_steps_reached
    assert int(solution.num_steps) == 3
    assert bool(jnp.all(jnp.isnan(solution.ys)))


def _final_state(y0, g, forward_mode=False):
    solution = taylor_integrate(
        pendulum,
        y0,
        0.0,
        3.0,
        args=g,
        rtol=1e-12,
        atol=1e-12,
        forward_mode=forward_mode,
    )
    return solution.ys[-1]


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_gradients_match_finite_differences():
    y0, g = jnp.array([1.0, 0.2]), 1.3
    # one compilation for the gradient, one for the finite differences
    loss = jax.jit(lambda y0, g: _final_state(y0, g)[0])
    grad_y0, grad_g = jax.jit(jax.grad(loss, argnums=(0, 1)))(y0, g)
    eps = 1e-6
    fd_g = (loss(y0, g + eps) - loss(y0, g - eps)) / (2 * eps)
    fd_y0 = jnp.stack(
        [
            (loss(y0 + eps * e, g) - loss(y0 - eps * e, g)) / (2 * eps)
            for e in jnp.eye(2)
        ]
    )
    assert jnp.allclose(grad_g, fd_g, rtol=1e-6)
    assert jnp.allclose(grad_y0, fd_y0, rtol=1e-6)
    # Forward mode agrees with reverse mode.
    forward = lambda g: _final_state(y0, g, forward_mode=True)[0]
    _, tangent = jax.jit(lambda g: jax.jvp(forward, (g,), (1.0,)))(g)
    assert jnp.allclose(tangent, grad_g, rtol=1e-10)


def test_vmap_equals_a_loop():
    y0s = jnp.array([[0.3, 0.0], [1.0, 0.5], [2.5, -0.1]])
    gs = jnp.array([1.0, 2.0, 0.5])
    batched = jax.jit(jax.vmap(_final_state))(y0s, gs)
    looped = jnp.stack([_final_state(y0, g) for y0, g in zip(y0s, gs)])
    assert jnp.allclose(batched, looped, rtol=0, atol=1e-15)


def test_unstack_has_an_affine_rule():
    # JAX ≥ 0.11 lowers `a, b = y` to the primitive unstack; produce it here.
    from jax._src.lax.lax import unstack

    def field(t, y, args):
        a, b = unstack(y, 0)
        return jnp.stack([b, -jnp.sin(a)])

    y0 = jnp.array([0.4, 0.1])
    ours = taylor_coefficients(field, 0.0, y0, order=5, unroll=False)
    reference = lie_coefficients(lambda y: field(0.0, y, None), y0, 5)
    assert jnp.allclose(ours, reference, rtol=1e-13, atol=1e-15)


def test_lowering_stores_no_array_in_a_static_field():
    import warnings

    from lagjax.taylor.coefficients import lower_vector_field

    def field(t, y, args):  # split's sizes are NumPy integers in the jaxpr
        a, b = jnp.split(y, 2)
        return jnp.concatenate([b, -a])

    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        graph, _ = lower_vector_field(field, 0.0, jnp.ones(4), None)
    assert graph.census()["Affine"] >= 1
