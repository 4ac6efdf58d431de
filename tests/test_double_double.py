"""Double-double arithmetic (`lagjax._linalg.double_double*`) against exact
rational arithmetic, under `jit`, and the time-transformed run that uses it:
Kepler's energy at the pericentre of an eccentric orbit, where float64 round-off
random-walks (issue 30)."""

from fractions import Fraction

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
import lagjax._linalg.double_double_arithmetic as dd
from lagjax._linalg.double_double import in_double_double, rounded_tree, split_tree

EPS_DD = 2.0**-100  # a few units of double-double's 2⁻¹⁰⁶


def _exact(x: dd.DoubleDouble, i: int) -> Fraction:
    return Fraction(float(x.hi[i])) + Fraction(float(x.lo[i]))


def _operands(seed: int, size: int = 64) -> tuple[dd.DoubleDouble, dd.DoubleDouble]:
    rng = np.random.default_rng(seed)
    scale = 10.0 ** rng.integers(-6, 7, size=size)
    x_hi, y_hi = rng.normal(size=size) * scale, rng.normal(size=size)
    x = dd.fast_two_sum(
        jnp.asarray(x_hi), jnp.asarray(x_hi * rng.normal(size=size) * 1e-17)
    )
    y = dd.fast_two_sum(
        jnp.asarray(y_hi), jnp.asarray(y_hi * rng.normal(size=size) * 1e-17)
    )
    return x, y


def test_error_free_transformations_are_exact_under_jit():
    rng = np.random.default_rng(0)
    a = rng.normal(size=200) * 10.0 ** rng.integers(-8, 9, size=200)
    b = rng.normal(size=200) * 10.0 ** rng.integers(-8, 9, size=200)
    s, p = jax.jit(dd.two_sum)(a, b), jax.jit(dd.two_product)(a, b)
    for i in range(a.size):
        assert Fraction(a[i]) + Fraction(b[i]) == _exact(s, i)
        assert Fraction(a[i]) * Fraction(b[i]) == _exact(p, i)


def test_a_square_keeps_its_product_rounding_under_jit():
    """x·x fused by XLA with a sum into one multiply-add counted the product's
    rounding twice (half an ulp wrong) before `_stored`."""
    x = dd.DoubleDouble(jnp.asarray(0.58), jnp.asarray(1.3e-18))
    square = jax.jit(lambda x: dd.multiply(x, x))(x)
    exact = (Fraction(0.58) + Fraction(1.3e-18)) ** 2
    got = Fraction(float(square.hi)) + Fraction(float(square.lo))
    assert abs(got - exact) <= EPS_DD * exact


@pytest.mark.parametrize("name", ["add", "multiply", "divide"])
def test_arithmetic_against_rationals(name):
    x, y = _operands(seed=1)
    result = jax.jit(getattr(dd, name))(x, y)
    for i in range(x.hi.size):
        a, b = _exact(x, i), _exact(y, i)
        exact = {"add": a + b, "multiply": a * b, "divide": a / b}[name]
        # The sum's error is relative to its operands, not to a cancelled result.
        scale = abs(a) + abs(b) if name == "add" else abs(exact)
        assert abs(_exact(result, i) - exact) <= EPS_DD * scale


def test_mixed_and_root_against_rationals():
    x, y = _operands(seed=2)
    b = y.hi
    products = jax.jit(dd.multiply_double)(x, b)
    quotients = jax.jit(dd.divide_double)(x, b)
    roots = jax.jit(dd.square_root)(
        dd.DoubleDouble(jnp.abs(x.hi), jnp.sign(x.hi) * x.lo)
    )
    for i in range(x.hi.size):
        a, bi = _exact(x, i), Fraction(float(b[i]))
        assert abs(_exact(products, i) - a * bi) <= EPS_DD * abs(a * bi)
        assert abs(_exact(quotients, i) - a / bi) <= EPS_DD * abs(a / bi)
        root = _exact(roots, i)
        assert abs(root * root - abs(a)) <= EPS_DD * abs(a)


def test_a_gradient_by_autodiff_in_double_double():
    """∇V of a rational V (no roots: the exact gradient is rational)."""

    def potential(q):
        return -1.0 / (q @ q) + q[0] * q[1] ** 3 / 7.0

    q = jnp.asarray([0.3, 0.7])
    gradient = jax.jit(in_double_double(jax.grad(potential)))(split_tree(q))
    x, y = Fraction(0.3), Fraction(0.7)
    r2 = x * x + y * y
    exact = [2 * x / r2**2 + y**3 / 7, 2 * y / r2**2 + 3 * x * y**2 / 7]
    for i, value in enumerate(exact):
        assert abs(_exact(gradient, i) - value) <= EPS_DD * abs(value)
    assert np.allclose(rounded_tree(gradient), jax.grad(potential)(q), rtol=1e-15)


def test_a_transcendental_is_refused_by_name():
    with pytest.raises(NotImplementedError, match="'exp'"):
        in_double_double(jnp.exp)(split_tree(jnp.asarray(1.0)))


def test_bad_precision_is_refused():
    with pytest.raises(ValueError, match="double-double"):
        lj.TimeTransformed(lj.Yoshida4(), precision="quad")
    with pytest.raises(ValueError, match="GraggBulirschStoer"):
        lj.TimeTransformed(
            lj.GraggBulirschStoer(rtol=1e-12, atol=1e-12), precision="double-double"
        )


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_kepler_energy_at_pericentre_in_double_double():
    """e = 0.99, saves at 40 pericentre passages: in float64 the log Hamiltonian's
    round-off walk, magnified by 2/(1 − e) = 200 at the pericentre, reaches
    about 1e-12 here; in double-double what is left is the saves' own rounding
    to float64 (the energy's condition number there is about 400)."""
    e = 0.99
    kepler = lj.SeparableHamiltonian(
        lambda p: p @ p / 2, lambda q: -1 / jnp.sqrt(q @ q)
    )
    y0 = (np.array([1 - e, 0.0]), np.array([0.0, np.sqrt((1 + e) / (1 - e))]))
    ts = 2 * np.pi * np.arange(0, 201, 5)

    def errors(precision):
        solver = lj.TimeTransformed(lj.Yoshida4(), precision=precision)
        traj = lj.simulate(kepler, y0, t1=float(ts[-1]), ts=ts, dt=0.05, solver=solver)
        q, p = np.asarray(traj.q), np.asarray(traj.p)
        energy = 0.5 * np.sum(p**2, 1) - 1 / np.linalg.norm(q, axis=1)
        angular = q[:, 0] * p[:, 1] - q[:, 1] * p[:, 0]
        r = np.linalg.norm(q, axis=1)
        lenz_y = -p[:, 0] * angular - q[:, 1] / r
        lenz_x = p[:, 1] * angular - q[:, 0] / r
        drift = np.abs(np.arctan2(lenz_y, lenz_x))
        return np.max(np.abs(energy / -0.5 - 1)), np.max(drift)

    energy_dd, drift_dd = errors("double-double")
    energy_double, _ = errors("double")
    assert energy_dd < 1.5e-13
    assert drift_dd < 1e-14
    assert energy_dd < energy_double / 3
