"""`lj.linearize` against closed forms: Lagrangian, Hamiltonian, constrained and
rigid-body systems, stability thresholds, inputs, and honest refusals (issue 15)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.scenes.constrained import CartesianPendulum
from tests.helpers import relative_close
from tests.test_gyroscopic_modes import THREE_BODY, l4_closed_form

G = 9.81


def sorted_spectrum(values):
    values = np.asarray(values)
    return values[np.lexsort((values.real, values.imag))]


def test_double_pendulum_state_space_matrices():
    length = 0.7

    def L(q, qd):
        kinetic = length**2 * (
            qd[0] ** 2 + 0.5 * qd[1] ** 2 + qd[0] * qd[1] * jnp.cos(q[0] - q[1])
        )
        return kinetic + G * length * (2 * jnp.cos(q[0]) + jnp.cos(q[1]))

    zero = jnp.zeros(2)
    A, B = lj.linearize(lj.Lagrangian(L), (zero, zero), inputs=jnp.eye(2))
    omegas = np.sqrt(np.array([2 - np.sqrt(2), 2 + np.sqrt(2)]) * G / length)
    expected = np.concatenate([1j * omegas, -1j * omegas])
    assert np.allclose(
        sorted_spectrum(np.linalg.eigvals(A)), sorted_spectrum(expected), atol=1e-10
    )
    # B = (0; M⁻¹) with M = l²[[2, 1], [1, 1]].
    mass = length**2 * np.array([[2.0, 1.0], [1.0, 1.0]])
    assert B is not None
    assert np.allclose(B[:2], 0) and relative_close(B[2:], np.linalg.inv(mass), 1e-12)
    assert np.allclose(A[:2], np.hstack([np.zeros((2, 2)), np.eye(2)]))


def test_separable_hamiltonian_oscillator_is_exact():
    mass, stiffness = 2.0, 3.0
    ham = lj.SeparableHamiltonian(
        lambda p: p**2 / (2 * mass), lambda q: 0.5 * stiffness * q**2
    )
    result = lj.linearize(ham, (0.0, 0.0), inputs=jnp.ones(1))
    assert np.allclose(result.A, [[0, 1 / mass], [-stiffness, 0]], rtol=0, atol=1e-15)
    assert result.B is not None and np.allclose(result.B, [[0], [1]])
    assert result.verdict() == "stable"


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_l4_in_hamiltonian_form():
    mu = jnp.asarray(0.01)
    hamiltonian = THREE_BODY.to_hamiltonian()
    # At rest in the rotating frame p = ẑ × q ≠ 0: the guess is a state (q, p).
    q, p = lj.relative_equilibrium(
        hamiltonian, (jnp.array([0.4, 0.8]), jnp.array([-0.8, 0.4])), mu
    )
    position, roots = l4_closed_form(0.01)
    assert relative_close(q, position, 1e-12)
    assert relative_close(p, [-position[1], position[0]], 1e-12)
    result = lj.linearize(hamiltonian, (q, p), mu)
    assert np.allclose(
        sorted_spectrum(result.eigenvalues), sorted_spectrum(roots), atol=1e-10
    )
    assert result.verdict() == "stable"


def test_constrained_pendulum_on_its_manifold():
    scene = CartesianPendulum()
    length, gravity, mass = (
        float(x) for x in (scene.length, scene.gravity, scene.mass)
    )
    bottom = (jnp.array([0.0, -length]), jnp.zeros(2))
    result = lj.linearize(scene, bottom, inputs=jnp.eye(2))
    # Two chart coordinates (along the circle), not four: no drift modes.
    assert result.A.shape == (2, 2)
    frequency = np.sqrt(gravity / length)
    assert relative_close(
        np.sort(result.eigenvalues.imag), [-frequency, frequency], 1e-12
    )
    assert result.verdict() == "stable"
    # A horizontal force accelerates the bob by F/m; the rod takes a vertical one.
    assert result.B is not None
    assert relative_close(abs(result.B[1, 0]), 1 / mass, 1e-12)
    assert abs(float(result.B[1, 1])) < 1e-12 and np.allclose(result.B[0], 0)
    # Upside down: e^{±√(g/l) t}.
    top = lj.linearize(
        scene, (jnp.array([0.0, length]), jnp.zeros(2)), inputs=jnp.eye(2)
    )
    assert top.verdict() == "unstable"
    assert relative_close(top.growth_rate, frequency, 1e-12)


def test_constrained_state_off_the_manifold_is_refused():
    scene = CartesianPendulum()
    too_long = (jnp.array([0.0, -1.1 * float(scene.length)]), jnp.zeros(2))
    with pytest.raises(ValueError, match="constraint residual"):
        lj.linearize(scene, too_long)


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_free_rigid_body_intermediate_axis_instability(axis):
    moments = np.array([1.0, 2.0, 3.5])
    spin = 1.7
    body = lj.RigidBody(moments)
    momentum = jnp.zeros(3).at[axis].set(moments[axis] * spin)
    result = lj.linearize(body, (jnp.array([1.0, 0, 0, 0]), momentum))
    j, k = [i for i in range(3) if i != axis]
    # Euler's equations about axis i: λ² = ω²(I_i − I_j)(I_k − I_i)/(I_j I_k).
    squared = spin**2 * (moments[axis] - moments[j]) * (moments[k] - moments[axis])
    squared /= moments[j] * moments[k]
    if axis == 1:
        assert result.verdict() == "unstable"
        assert relative_close(result.growth_rate, np.sqrt(squared), 1e-12)
    else:
        # A wobble at √(−λ²); the zero eigenvalues are the conserved |Π| and the
        # turn about the spin axis, so the verdict is 'marginal', never 'unstable'.
        assert result.verdict() == "marginal"
        assert abs(float(result.growth_rate)) < 1e-12
        wobble = np.abs(np.asarray(result.eigenvalues.imag))
        assert np.min(np.abs(wobble - np.sqrt(-squared))) < 1e-12


def sleeping_top_frequencies(i1, i3, mgl, spin):
    """Space-frame precession and nutation rates of the axis: I1 s² − I3ω3 s + Mgl = 0."""
    discriminant = (i3 * spin) ** 2 - 4 * i1 * mgl
    root = np.sqrt(discriminant + 0j)
    return (i3 * spin - root) / (2 * i1), (i3 * spin + root) / (2 * i1)


def heavy_top_potential(rotation, t, mgl):
    # The centre of mass at l e3 in the body: height l R_33.
    return mgl * rotation[2, 2]


@pytest.mark.parametrize("factor", [0.99, 1.01])
def test_sleeping_top_threshold_as_a_rigid_body(factor):
    i1, i3, mgl = 1.0, 0.5, jnp.asarray(1.0)
    spin = factor * np.sqrt(4 * mgl * i1 / i3**2)  # ω3² > 4MglI1/I3²
    top = lj.RigidBody(jnp.array([i1, i1, i3]), heavy_top_potential)
    upright = (jnp.array([1.0, 0, 0, 0]), jnp.array([0.0, 0.0, i3 * spin]))
    result = lj.linearize(top, upright, mgl)
    slow, fast = sleeping_top_frequencies(i1, i3, mgl, spin)
    if factor < 1:
        assert result.verdict() == "unstable"
        assert relative_close(result.growth_rate, abs(slow.imag), 1e-10)
    else:
        assert abs(float(result.growth_rate)) < 1e-12
        # The chart turns with the body: it sees the axis at ω3 − ω±.
        seen = np.sort(np.abs(np.asarray(result.eigenvalues.imag)))[-4::2]
        assert relative_close(
            seen, np.sort([spin - fast.real, spin - slow.real]), 1e-10
        )


def tait_bryan_top(q, qd, t, args):
    r"""A symmetric top, $R = R_x(\alpha)R_y(\beta)R_z(\psi)$: regular when upright.

    The body angular velocity is $R_z(\psi)^T\mathbf u$ with $\mathbf u =
    (\dot\alpha\cos\beta, \dot\beta, \dot\psi + \dot\alpha\sin\beta)$; $R_z$ keeps
    $u_x^2 + u_y^2$, and the axis' height is $R_{33} = \cos\alpha\cos\beta$.
    """
    i1, i3, mgl = args[0], args[1], args[2]
    alpha_dot, beta_dot, psi_dot = qd[0], qd[1], qd[2]
    beta = q[1]
    transverse = (alpha_dot * jnp.cos(beta)) ** 2 + beta_dot**2
    axial = psi_dot + alpha_dot * jnp.sin(beta)
    kinetic = 0.5 * i1 * transverse + 0.5 * i3 * axial**2
    return kinetic - mgl * jnp.cos(q[0]) * jnp.cos(beta)


@pytest.mark.parametrize("factor", [0.99, 1.01])
def test_sleeping_top_threshold_in_tait_bryan_angles(factor):
    i1, i3, mgl = 1.0, 0.5, 1.0
    spin = factor * np.sqrt(4 * mgl * i1 / i3**2)
    lag = lj.Lagrangian(tait_bryan_top)
    state = (jnp.zeros(3), jnp.array([0.0, 0.0, spin]))
    args = jnp.array([i1, i3, mgl])
    # ψ turns steadily: not an equilibrium, refused unless asked for ...
    with pytest.raises(ValueError, match="rate of change"):
        lj.linearize(lag, state, args)
    # ... but ψ is cyclic, so the linearization about the steady spin is autonomous.
    result = lj.linearize(lag, state, args, check_equilibrium=False)
    slow, fast = sleeping_top_frequencies(i1, i3, mgl, spin)
    if factor < 1:
        assert result.verdict() == "unstable"
        assert relative_close(result.growth_rate, abs(slow.imag), 1e-10)
    else:
        assert abs(float(result.growth_rate)) < 1e-10
        seen = np.sort(np.abs(np.asarray(result.eigenvalues.imag)))[-4::2]
        assert relative_close(seen, [slow.real, fast.real], 1e-10)


def hoop(q, qd, t, args):
    """Bead on a hoop of radius R turning at ω about its vertical diameter."""
    radius, omega = args[0], args[1]
    kinetic = 0.5 * radius**2 * (qd**2 + (omega * jnp.sin(q)) ** 2)
    return kinetic + G * radius * jnp.cos(q)


@pytest.mark.parametrize("factor", [0.9, 1.1])
def test_bead_on_rotating_hoop_changes_stability_at_g_over_r(factor):
    radius = 0.5
    omega = factor * np.sqrt(G / radius)
    lag, args = lj.Lagrangian(hoop), jnp.array([radius, omega])
    bottom = lj.linearize(lag, (0.0, 0.0), args)
    rate = np.sqrt(abs(omega**2 - G / radius))
    if factor < 1:
        assert bottom.verdict() == "stable"
        assert relative_close(np.max(bottom.eigenvalues.imag), rate, 1e-12)
    else:
        assert bottom.verdict() == "unstable"
        assert relative_close(bottom.growth_rate, rate, 1e-12)
        # The bead settles where cos θ = g/(ω²R) and oscillates at ω sin θ.
        theta = lj.relative_equilibrium(lag, 0.5, args)
        assert relative_close(np.cos(theta), G / (omega**2 * radius), 1e-12)
        modes = lj.normal_modes(lag, theta, args)
        assert relative_close(modes.omegas, omega * np.sin(theta), 1e-10)
        assert modes.verdict() == "stable"


def test_damped_oscillator_is_asymptotically_stable():
    mass, stiffness, friction = 1.5, 6.0, 0.8
    lag = lj.Lagrangian(
        lambda q, qd: 0.5 * mass * qd**2 - 0.5 * stiffness * q**2,
        dissipation=lambda qd: 0.5 * friction * qd**2,
    )
    result = lj.linearize(lag, (0.0, 0.0))
    decay = friction / (2 * mass)
    ringing = np.sqrt(stiffness / mass - decay**2)
    assert relative_close(
        sorted_spectrum(result.eigenvalues),
        [-decay - 1j * ringing, -decay + 1j * ringing],
        1e-12,
    )
    assert result.verdict() == "stable" and float(result.growth_rate) < 0
    with pytest.raises(ValueError, match="linearize"):
        lj.normal_modes(lag, 0.0)


def test_non_equilibrium_is_refused_and_opt_out_linearizes_anyway():
    pendulum = lj.Lagrangian(lambda q, qd: 0.5 * qd**2 + G * jnp.cos(q))
    with pytest.raises(ValueError, match="not an equilibrium"):
        lj.linearize(pendulum, (0.3, 0.0))
    with pytest.raises(ValueError, match="residual generalized force"):
        lj.normal_modes(pendulum, 0.3)
    A, _ = lj.linearize(pendulum, (0.3, 0.0), check_equilibrium=False)
    assert relative_close(A, [[0, 1], [-G * np.cos(0.3), 0]], 1e-12)
    omegas, _ = lj.normal_modes(pendulum, 0.3, check_equilibrium=False)
    assert relative_close(omegas, np.sqrt(G * np.cos(0.3)), 1e-12)


def test_linearize_under_jit_and_vmap():
    @jax.jit
    def growth(mu):
        q4 = jnp.stack([0.5 - mu, jnp.sqrt(0.75)])
        return lj.linearize(THREE_BODY, (q4, jnp.zeros(2)), mu).growth_rate

    mus = jnp.array([0.02, 0.05])
    rates = np.asarray(jax.vmap(growth)(mus))
    assert abs(rates[0]) < 1e-12  # below Routh's 0.0385
    assert relative_close(rates[1], np.max(l4_closed_form(0.05)[1].real), 1e-10)


def test_bad_arguments_name_the_problem():
    pendulum = lj.Lagrangian(lambda q, qd: 0.5 * qd**2 + G * jnp.cos(q))
    with pytest.raises(ValueError, match=r"state \(q, qdot\) as a pair"):
        lj.linearize(pendulum, 0.0)
    with pytest.raises(ValueError, match=r"input matrix S .* shape \(1, m\)"):
        lj.linearize(pendulum, (0.0, 0.0), inputs=jnp.eye(2))
    with pytest.raises(TypeError, match="linearize needs a lagjax"):
        lj.linearize(lambda q, qd: q, (0.0, 0.0))
    with pytest.raises(ValueError, match=r"quaternion \(4,\), body_momentum"):
        lj.linearize(lj.RigidBody(jnp.ones(3)), (jnp.ones(3), jnp.ones(3)))
    # A constant force on a free particle: no rest point, and the message says so.
    pushed = lj.Lagrangian(lambda q, qd: 0.5 * qd**2 + 2.0 * q)
    with pytest.raises(ValueError, match=r"did not converge .* \[2\.\]"):
        lj.relative_equilibrium(pushed, 0.3)


def test_a_singular_mass_matrix_is_refused_not_called_stable():
    # L = ½(q̇₀ + q̇₁)² − ½|q|²: M = [[1, 1], [1, 1]] is singular.
    lag = lj.Lagrangian(lambda q, qd: 0.5 * (qd[0] + qd[1]) ** 2 - 0.5 * q @ q)
    with pytest.raises(Exception, match="singular"):
        lj.linearize(lag, (jnp.zeros(2), jnp.zeros(2)))
