"""Euler–Lagrange accelerations against the course text's closed forms."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from tests.helpers import relative_close, tree_allclose

RNG = np.random.default_rng(0)


def test_atwood_machine():
    # Course text §3 (Atwood's machine): ÿ = (M1 − M2) g / (M1 + M2).
    def L(y, ydot, t, args):
        m1, m2, g = args
        return 0.5 * (m1 + m2) * ydot**2 + (m1 - m2) * g * y

    lag = lj.Lagrangian(L)
    args = (3.0, 1.25, 9.81)
    acc = lag.acceleration(0.7, -0.2, 0.0, args)
    assert relative_close(acc, (3.0 - 1.25) * 9.81 / (3.0 + 1.25), 1e-12)
    assert jnp.shape(acc) == ()


def test_bead_on_rotating_wire_is_rheonomic():
    # x = r cos ωt, y = r sin ωt: L written through the time-dependent transformation.
    omega, m = 1.7, 0.4

    def cartesian(r, t):
        return jnp.array([r * jnp.cos(omega * t), r * jnp.sin(omega * t)])

    def L(r, rdot, t):
        velocity = jax.jvp(cartesian, (r, t), (rdot, jnp.ones_like(t)))[1]
        return 0.5 * m * velocity @ velocity

    lag = lj.Lagrangian(L)
    for r, rdot, t in [(0.3, 0.1, 0.0), (1.2, -2.0, 3.3)]:
        assert relative_close(lag.acceleration(r, rdot, t), omega**2 * r, 1e-12)


def test_free_particle_cylindrical_with_forces():
    # Course text eq. (3.61)–(3.63) with generalized forces (F_r, r F_θ, F_z).
    m = 1.3

    def L(q, qd):
        r, _, _ = q
        return 0.5 * m * (qd[0] ** 2 + r**2 * qd[1] ** 2 + qd[2] ** 2)

    def force(q, qd, t, args):
        f_r, f_theta, f_z = args
        return jnp.array([f_r, q[0] * f_theta, f_z])

    lag = lj.Lagrangian(L, force=force)
    for _ in range(3):
        q = RNG.uniform(0.5, 2.0, 3)
        qd = RNG.normal(size=3)
        f = tuple(RNG.normal(size=3))
        r, (rd, thd, _) = q[0], qd
        expected = np.array(
            [
                r * thd**2 + f[0] / m,
                (r * f[1] - 2 * m * r * rd * thd) / (m * r**2),
                f[2] / m,
            ]
        )
        assert relative_close(lag.acceleration(q, qd, 0.0, f), expected, 1e-11)


def test_free_particle_spherical_with_forces():
    # Course text eq. (3.74)–(3.76); 3.76's centrifugal term is m r² φ̇² sinθ cosθ.
    m = 0.8

    def L(q, qd):
        r, theta, _ = q
        return (
            0.5
            * m
            * (qd[0] ** 2 + r**2 * qd[1] ** 2 + r**2 * jnp.sin(theta) ** 2 * qd[2] ** 2)
        )

    def force(q, qd, t, args):
        f_r, f_theta, f_phi = args
        return jnp.array([f_r, q[0] * f_theta, q[0] * jnp.sin(q[1]) * f_phi])

    lag = lj.Lagrangian(L, force=force)
    q = np.array([1.4, 0.9, 0.3])
    qd = np.array([0.2, -0.7, 1.1])
    f_r, f_th, f_ph = 0.3, -0.5, 0.25
    r, th = q[0], q[1]
    rd, thd, phd = qd
    s, c = np.sin(th), np.cos(th)
    expected = np.array(
        [
            r * s**2 * phd**2 + r * thd**2 + f_r / m,
            (r * f_th + m * r**2 * phd**2 * s * c - 2 * m * r * rd * thd) / (m * r**2),
            (
                r * s * f_ph
                - m * (2 * r * rd * s**2 * phd + 2 * r**2 * s * c * thd * phd)
            )
            / (m * r**2 * s**2),
        ]
    )
    assert np.allclose(
        lag.acceleration(q, qd, 0.0, (f_r, f_th, f_ph)), expected, rtol=1e-11
    )


def _potentials(x, t):
    """A non-trivial, time-dependent scalar and vector potential."""
    phi = x[0] * x[1] + 0.3 * x[2] ** 2 * t + jnp.sin(x[0])
    a = jnp.array([-x[1] * x[2] * t, x[0] ** 2 + t**2 * x[2], jnp.sin(x[0]) * t**2])
    return phi, a


def _charged_lagrangian(x, v, t, args):
    m, e = args
    phi, a = _potentials(x, t)
    return 0.5 * m * v @ v - e * (phi - a @ v)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_charged_particle_lorentz_force():
    m, e = 1.7, -0.6
    lag = lj.Lagrangian(_charged_lagrangian, quadratic_in_velocity=True)
    for _ in range(3):
        x = RNG.normal(size=3)
        v = RNG.normal(size=3)
        t = RNG.uniform(0.1, 2.0)
        grad_phi = jax.grad(lambda y, s: _potentials(y, s)[0])(x, t)
        da_dt = jax.jacfwd(lambda y, s: _potentials(y, s)[1], argnums=1)(x, t)
        # jac_a[i, j] = ∂A_i/∂x_j
        jac_a = jax.jacfwd(lambda y, s: _potentials(y, s)[1])(x, t)
        E = -grad_phi - da_dt
        B = jnp.array(
            [
                jac_a[2, 1] - jac_a[1, 2],
                jac_a[0, 2] - jac_a[2, 0],
                jac_a[1, 0] - jac_a[0, 1],
            ]
        )
        lorentz = e * (E + jnp.cross(v, B)) / m
        assert relative_close(lag.acceleration(x, v, t, (m, e)), lorentz, 1e-10)


def test_charged_particle_hamiltonian():
    # H = (p − eA)²/2m + eφ from the Legendre transform.
    m, e = 1.7, -0.6
    lag = lj.Lagrangian(_charged_lagrangian, quadratic_in_velocity=True)
    ham = lag.to_hamiltonian()
    for _ in range(3):
        x, p = RNG.normal(size=3), RNG.normal(size=3)
        t = RNG.uniform(0.1, 2.0)
        phi, a = _potentials(x, t)
        expected = (p - e * a) @ (p - e * a) / (2 * m) + e * phi
        assert relative_close(ham(x, p, t, (m, e)), expected, 1e-12)


def test_rayleigh_dissipation_and_driving_force():
    # m ẍ = −k x − b ẋ + F cos(Ωt)
    m, k, b, F, Omega = 2.0, 3.0, 0.4, 0.7, 1.3

    lag = lj.Lagrangian(
        lambda x, xd: 0.5 * m * xd**2 - 0.5 * k * x**2,
        dissipation=lambda xd: 0.5 * b * xd**2,
        force=lambda x, xd, t: F * jnp.cos(Omega * t),
    )
    x, xd, t = 0.3, -1.1, 0.8
    expected = (-k * x - b * xd + F * np.cos(Omega * t)) / m
    assert relative_close(lag.acceleration(x, xd, t), expected, 1e-12)


def test_pytree_coordinates():
    # Two uncoupled pieces in a dict: a 2-D oscillator and a scalar pendulum angle.
    def L(q, qd):
        return (
            0.5 * jnp.sum(qd["xy"] ** 2)
            - 0.5 * 4.0 * jnp.sum(q["xy"] ** 2)
            + 0.5 * qd["angle"] ** 2
            + 9.0 * jnp.cos(q["angle"])
        )

    lag = lj.Lagrangian(L)
    q = {"xy": jnp.array([0.2, -0.3]), "angle": jnp.asarray(0.5)}
    qd = {"xy": jnp.array([1.0, 0.0]), "angle": jnp.asarray(0.1)}
    acc = lag.acceleration(q, qd)
    expected = {"xy": -4.0 * q["xy"], "angle": -9.0 * jnp.sin(q["angle"])}
    assert tree_allclose(acc, expected, rtol=1e-12)
    assert tree_allclose(lag.momentum(q, qd), qd)


def _chain_lagrangian(q, qd, t, args):
    masses, k = args
    stretch = jnp.diff(jnp.concatenate([jnp.zeros(1), q, jnp.zeros(1)]))
    return 0.5 * jnp.sum(masses * qd**2) - 0.5 * k * jnp.sum(stretch**2)


@pytest.mark.parametrize("n", [3, 12])
def test_spring_chain_small_and_dense_paths(n):
    # n = 3 takes the scalar formulation, n = 12 the dense one: both must equal
    # the linear closed form M⁻¹(−K q) with K the fixed-end chain stiffness.
    masses = jnp.linspace(1.0, 2.0, n)
    k = 5.0
    stiffness = k * (2 * jnp.eye(n) - jnp.eye(n, k=1) - jnp.eye(n, k=-1))
    q = jnp.asarray(RNG.normal(size=n))
    qd = jnp.asarray(RNG.normal(size=n))
    lag = lj.Lagrangian(_chain_lagrangian)
    acc = lag.acceleration(q, qd, 0.0, (masses, k))
    assert np.allclose(acc, -(stiffness @ q) / masses, rtol=1e-11, atol=1e-12)


def test_jit_and_vmap_over_states_and_args():
    def L(q, qd, t, args):
        g, length = args
        return 0.5 * length**2 * qd**2 + g * length * jnp.cos(q)

    lag = lj.Lagrangian(L)
    qs = jnp.linspace(-1.0, 1.0, 5)
    lengths = jnp.linspace(0.5, 2.0, 5)
    batched = jax.jit(
        jax.vmap(lambda q, length: lag.acceleration(q, 0.0, 0.0, (9.8, length)))
    )
    expected = -9.8 * jnp.sin(qs) / lengths
    assert relative_close(batched(qs, lengths), expected, 1e-12)


def test_energy_is_jacobi_integral():
    # For L = T − V with T quadratic, h = T + V.
    def L(q, qd):
        return (
            0.5 * (2.0 + jnp.cos(q[0])) * qd[0] ** 2
            + 0.5 * qd[1] ** 2
            - q[0] ** 2 * q[1]
        )

    lag = lj.Lagrangian(L)
    q, qd = jnp.array([0.4, -0.3]), jnp.array([1.2, 0.5])
    T = 0.5 * (2.0 + jnp.cos(q[0])) * qd[0] ** 2 + 0.5 * qd[1] ** 2
    assert relative_close(lag.energy(q, qd), T + q[0] ** 2 * q[1], 1e-13)
    assert np.allclose(
        lag.mass_matrix(q, qd), jnp.diag(jnp.array([2.0 + jnp.cos(0.4), 1.0]))
    )
