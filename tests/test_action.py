"""The action ∫L dt: quadrature order, Hamilton's principle, Hamilton–Jacobi.

Closed forms used: the oscillator q = A cos(ωt + φ) has
S = −¼mωA²[sin 2(ωt₁ + φ) − sin 2(ωt₀ + φ)], and between end points
S(q₀, q₁, T) = mω[(q₀² + q₁²) cos ωT − 2q₀q₁]/(2 sin ωT) with
p₁ = mω(q₁ cos ωT − q₀)/sin ωT, p₀ = mω(q₁ − q₀ cos ωT)/sin ωT; a free particle has
S = m|q₁ − q₀|²/2T (Goldstein, Poole & Safko §10.1–10.2; the course text §6.6.1).
"""

import functools

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.action_principle.hamilton_principle import (
    action,
    action_of_path,
    principal_function,
)
from lagjax.action_principle.shooting import action_between, trajectory_between
from lagjax.scenes.central import KeplerCartesian
from lagjax.scenes.oscillators import HarmonicOscillator

from .helpers import relative_close

MASS, OMEGA, AMPLITUDE, PHASE, T1 = 1.0, 2.0, 0.8, 0.3, 1.3

oscillator = lj.Lagrangian(
    lambda q, v: 0.5 * MASS * v**2 - 0.5 * MASS * OMEGA**2 * q**2,
    quadratic_in_velocity=True,
)
oscillator_h = lj.SeparableHamiltonian(
    lambda p: p**2 / (2 * MASS), lambda q: 0.5 * MASS * OMEGA**2 * q**2
)


def exact_q(t):
    return AMPLITUDE * jnp.cos(OMEGA * t + PHASE)


def exact_qdot(t):
    return -AMPLITUDE * OMEGA * jnp.sin(OMEGA * t + PHASE)


def exact_action(t0, t1):
    return (
        -0.25
        * MASS
        * OMEGA
        * AMPLITUDE**2
        * (jnp.sin(2 * (OMEGA * t1 + PHASE)) - jnp.sin(2 * (OMEGA * t0 + PHASE)))
    )


def samples(ts, q, second, system=oscillator):
    """A Trajectory holding given samples (q and q̇, or q and p)."""
    return lj.Trajectory(
        ts=ts,
        ys=(q, second),
        system=system,
        args=None,
        run_stats={},
        result=diffrax.RESULTS.successful,
        solver_name="samples",
    )


def slopes(errors, intervals):
    return np.diff(np.log(errors)) / np.diff(np.log(1.0 / np.asarray(intervals)))


INTERVALS = (8, 16, 32, 64)


def smooth_path(t):
    return jnp.sin(2 * t) + 0.3 * t**2  # not a solution of the EL equation


@functools.cache
def smooth_path_action():
    """The reference action of `smooth_path`, computed once for both warps."""
    return action_of_path(oscillator, smooth_path, 0.0, T1, intervals=256, nodes=5)


@functools.partial(jax.jit, static_argnums=0)
def smooth_path_sampled_action(intervals, warp):
    """The action from n + 1 samples of `smooth_path`; one compilation per n serves
    both warps (a traced argument)."""
    u = jnp.linspace(0.0, 1.0, intervals + 1)
    ts = T1 * (u + warp * jnp.sin(jnp.pi * u) / jnp.pi)  # monotone for warp < 1
    qdot = jax.vmap(jax.grad(smooth_path))(ts)
    return action(oscillator, samples(ts, smooth_path(ts), qdot))


@pytest.mark.parametrize("warp", [0.0, 0.3], ids=["uniform", "non-uniform"])
def test_order_four_on_any_smooth_path(warp):
    reference = smooth_path_action()
    errors = [
        abs(float(smooth_path_sampled_action(n, warp) - reference)) for n in INTERVALS
    ]
    assert np.all(np.abs(slopes(errors, INTERVALS) - 4.0) < 0.15), errors


@pytest.mark.parametrize("nodes, order", [(2, 4.0), (3, 6.0)])
def test_order_on_a_true_path(nodes, order):
    """On a true path the interpolation error enters at second order only."""

    @functools.partial(jax.jit, static_argnums=0)
    def error(intervals):  # the samples and their action in one compilation
        ts = jnp.linspace(0.0, T1, intervals + 1)
        traj = samples(ts, exact_q(ts), exact_qdot(ts))
        return jnp.abs(action(oscillator, traj, nodes=nodes) - exact_action(0, T1))

    errors = [float(error(n)) for n in INTERVALS]
    assert np.all(np.abs(slopes(errors, INTERVALS) - order) < 0.15), errors
    assert errors[-1] < 10 ** (-order - 3.5)


def test_hamiltonian_trajectory_phase_space_and_lagrangian_forms():
    ts = jnp.linspace(0.0, T1, 65)
    momenta = MASS * exact_qdot(ts)
    expected = exact_action(0, T1)
    for hamiltonian in (oscillator_h, oscillator.to_hamiltonian()):
        traj = samples(ts, exact_q(ts), momenta, system=hamiltonian)
        assert traj.is_hamiltonian
        assert relative_close(action(hamiltonian, traj), expected, 1e-10)
        assert relative_close(action(oscillator, traj), expected, 1e-10)


def closed_form_samples(qdot0, ts):
    """Oscillator samples from q(0) = exact_q(0), q̇(0) = qdot0 (differentiable)."""
    q0 = exact_q(0.0)
    q = q0 * jnp.cos(OMEGA * ts) + qdot0 / OMEGA * jnp.sin(OMEGA * ts)
    qdot = -q0 * OMEGA * jnp.sin(OMEGA * ts) + qdot0 * jnp.cos(OMEGA * ts)
    return samples(ts, q, qdot)


def test_jit_and_gradient_follow_hamilton():
    """dS/dq̇₀ at fixed q₀ is p₁·∂q₁/∂q̇₀ = p₁ sin(ωT)/ω (δS = p₁δq₁ − p₀δq₀)."""
    ts = jnp.linspace(0.0, T1, 129)
    action_from = lambda v: action(oscillator, closed_form_samples(v, ts))
    value, slope = jax.jit(jax.value_and_grad(action_from))(exact_qdot(0.0))
    assert relative_close(value, exact_action(0, T1), 1e-12)
    expected_slope = MASS * exact_qdot(T1) * jnp.sin(OMEGA * T1) / OMEGA
    assert relative_close(slope, expected_slope, 1e-10)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_batched_and_padded_trajectories():
    ts = jnp.linspace(0.0, T1, 129)
    speeds = jnp.array([-0.5, 0.0, 1.2, exact_qdot(0.0)])

    @jax.jit
    def batched_and_looped(speeds):  # one compilation for both ways
        batch = jax.vmap(lambda v: closed_form_samples(v, ts))(speeds)
        one_by_one = [action(oscillator, closed_form_samples(v, ts)) for v in speeds]
        return (
            action(oscillator, batch),
            jnp.stack(one_by_one),
            principal_function(oscillator, batch),
        )

    batched, one_by_one, principal = batched_and_looped(speeds)
    assert batched.shape == (4,) and principal.shape == (4, 129)
    assert relative_close(batched, one_by_one, 1e-14)
    assert relative_close(batched[-1], exact_action(0, T1), 1e-12)
    # Backwards in time the action changes sign.
    reverse = lambda tr: jax.tree_util.tree_map(lambda x: x[::-1], tr)
    backwards = samples(ts[::-1], *reverse((exact_q(ts), exact_qdot(ts))))
    assert relative_close(action(oscillator, backwards), -exact_action(0, T1), 1e-12)
    # Padding (t = inf, states inf) never reaches the values or the gradients.
    pad = jnp.full(3, jnp.inf)
    padded_ts = jnp.concatenate([ts, pad])
    momenta = jnp.concatenate([MASS * exact_qdot(ts), pad])
    of_positions = lambda q: action(
        oscillator_h, samples(padded_ts, q, momenta, system=oscillator_h)
    )
    value, gradient = jax.jit(jax.value_and_grad(of_positions))(
        jnp.concatenate([exact_q(ts), pad])
    )
    assert relative_close(value, exact_action(0, T1), 1e-12)
    assert bool(jnp.all(jnp.isfinite(gradient))) and bool(jnp.all(gradient[-3:] == 0))
    # SaveAt(steps=True) pads the unused slots with t = inf: they are skipped.
    padded = lj.simulate(
        oscillator,
        (exact_q(0.0), exact_qdot(0.0)),
        t1=T1,
        dt=T1 / 128,
        solver=diffrax.Dopri8(),
        saveat=diffrax.SaveAt(t0=True, steps=True),
        max_steps=200,
    )
    assert not bool(jnp.all(jnp.isfinite(padded.ts)))
    assert relative_close(action(oscillator, padded), exact_action(0, T1), 1e-12)


def driven_lagrangian(q, v, t, args):
    force, drive = args
    return 0.5 * v**2 - 0.5 * OMEGA**2 * q**2 + force * q * jnp.cos(drive * t)


def kepler_lagrangian(q, v):
    return 0.5 * jnp.sum(v**2) + 1.0 / jnp.sqrt(jnp.sum(q**2))


def hamilton_cases():
    """(Lagrangian, true path, bump η with η(t₀) = η(t₁) = 0, args, t₀, t₁)."""
    kepler = KeplerCartesian(eccentricity=0.5)
    t0, t1 = 0.3, 2.5
    bump = lambda t: (
        jnp.sin(jnp.pi * (t - t0) / (t1 - t0)) * jnp.array([0.3 + 0.2 * t, -0.4 * t])
    )
    args = (0.7, 1.3)
    forced = lambda t: args[0] / (OMEGA**2 - args[1] ** 2) * jnp.cos(args[1] * t)
    forced_bump = lambda t: t * (T1 - t) * jnp.exp(t)
    return {
        "kepler": (
            lj.Lagrangian(kepler_lagrangian),
            lambda t: kepler.orbit_state(t)[0],
            bump,
            None,
            t0,
            t1,
        ),
        "driven": (
            lj.Lagrangian(driven_lagrangian),
            forced,
            forced_bump,
            args,
            0.0,
            T1,
        ),
    }


@pytest.mark.parametrize("case", ["kepler", "driven"])
def test_hamiltons_principle(case):
    lag, path, eta, args, t0, t1 = hamilton_cases()[case]

    def action_near(base):
        """ε ↦ S[base + εη], compiled once."""

        def varied(eps):
            shifted = lambda t: jax.tree_util.tree_map(
                lambda a, b: a + eps * b, base(t), eta(t)
            )
            return action_of_path(lag, shifted, t0, t1, args, nodes=8, intervals=32)

        return jax.jit(varied)

    true_action = action_near(path)
    epsilons = 1e-2 * 0.5 ** np.arange(4)
    changes = [abs(float(true_action(eps) - true_action(0.0))) for eps in epsilons]
    slope = np.diff(np.log(changes)) / np.diff(np.log(epsilons))
    assert np.all(np.abs(slope - 2.0) < 0.05), changes
    first_variation = jax.jvp(true_action, (0.0,), (1.0,))[1]
    # A path that is not a solution: the true one plus a fixed bump.
    wrong = lambda t: jax.tree_util.tree_map(lambda a, b: a + 0.2 * b, path(t), eta(t))
    first_variation_wrong = jax.jvp(action_near(wrong), (0.0,), (1.0,))[1]
    assert abs(float(first_variation)) < 1e-12 * abs(float(first_variation_wrong))


def test_principal_function_is_w_minus_alpha_t():
    """S(t) − S(0) = W(q(t), E) − W(q₀, E) − E t along the oscillator (eq. 6.73)."""
    scene = HarmonicOscillator()

    @jax.jit
    def measured_and_expected():  # one compilation, not dozens of op-by-op ones
        omega = scene.frequency()
        energy = scene.system()(*scene.initial_state(), 0.0, scene)
        ts = jnp.linspace(0.0, 3.0, 301)
        q, p = scene.exact_solution(ts)
        run = samples(ts, q, p, system=scene.system())
        run = lj.Trajectory(**{**vars(run), "args": scene})
        # W = ∫p dq = J(θ + ½ sin 2θ), J = E/ω, θ the angle unwrapped (q ∝ sin θ).
        theta = jnp.unwrap(scene.angle(q, p))
        characteristic = energy / omega * (theta + 0.5 * jnp.sin(2 * theta))
        expected = characteristic - characteristic[0] - energy * ts
        return ts, principal_function(scene, run), action(scene, run), expected

    ts, measured, total, expected = measured_and_expected()
    assert measured.shape == ts.shape and float(measured[0]) == 0.0
    assert relative_close(measured, expected, 1e-11)
    assert relative_close(total, expected[-1], 1e-11)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_action_between_oscillator_closed_form_and_momenta():
    """S(q₀, q₁, T) and its gradients (reverse mode through the shooting)."""
    q0, q1 = 0.3, -0.2
    sine, cosine = np.sin(OMEGA * T1), np.cos(OMEGA * T1)
    expected = MASS * OMEGA * ((q0**2 + q1**2) * cosine - 2 * q0 * q1) / (2 * sine)
    p1 = MASS * OMEGA * (q1 * cosine - q0) / sine
    p0 = MASS * OMEGA * (q1 - q0 * cosine) / sine
    principal = lambda a, b: action_between(oscillator_h, a, b, 0.0, T1, samples=65)
    value, (d_q0, d_q1) = jax.value_and_grad(principal, argnums=(0, 1))(q0, q1)
    assert relative_close(value, expected, 1e-10)
    assert relative_close(d_q1, p1, 1e-9)
    assert relative_close(d_q0, -p0, 1e-9)


def rescaled_pendulum(q, q_prime, tau, duration):
    """L̃ = T·L(q, q'/T) in τ = t/T ∈ [0, 1]: same momentum, duration T as args."""
    velocity = q_prime / duration
    return duration * (0.5 * velocity**2 + 9.81 * jnp.cos(q))


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_hamilton_jacobi_equation_for_a_pendulum():
    """∂S/∂q₁ = p₁ of the shot path, ∂S/∂q₀ = −p₀ and ∂S/∂t₁ + H₁ = 0 (eq. 6.67–6.68).

    The end time enters as the args of a time-rescaled L, so forward-mode autodiff
    gives all three derivatives of one shooting solve.
    """
    pendulum = lj.Lagrangian(rescaled_pendulum, quadratic_in_velocity=True)
    shoot = dict(samples=129, solver=diffrax.Dopri8(), adjoint=diffrax.ForwardMode())

    def principal(q0, q1, duration):
        path = trajectory_between(pendulum, q0, q1, 0.0, 1.0, args=duration, **shoot)
        return action(pendulum, path), (path.q[-1], path.p[0], path.p[-1])

    q0, q1, duration = 0.2, 1.1, 0.6
    # Jitted: one compilation instead of dozens of op-by-op dispatches.
    gradient, (reached, p0, p1) = jax.jit(
        jax.jacfwd(principal, argnums=(0, 1, 2), has_aux=True)
    )(q0, q1, duration)
    assert relative_close(reached, q1, 1e-12)
    assert relative_close(gradient[1], p1, 1e-10)
    assert relative_close(gradient[0], -p0, 1e-10)
    energy = 0.5 * p1**2 - 9.81 * jnp.cos(q1)
    assert relative_close(gradient[2], -energy, 1e-9)


def test_rejects_what_it_cannot_integrate():
    with pytest.raises(TypeError, match="Lagrangian, a Hamiltonian or a scene"):
        action(lambda q, v: v, samples(jnp.zeros(2), jnp.zeros(2), jnp.zeros(2)))
    final_only = lj.simulate(
        oscillator, (1.0, 0.0), t1=1.0, dt=0.1, solver=diffrax.Euler()
    )
    with pytest.raises(ValueError, match="only one state"):
        action(oscillator, final_only)
    with pytest.raises(ValueError, match="nodes"):
        action_of_path(oscillator, exact_q, 0.0, 1.0, nodes=0)
    with pytest.raises(ValueError, match="Python numbers"):
        trajectory_between(oscillator, 0.0, 1.0, jnp.asarray(0.0), 1.0)
