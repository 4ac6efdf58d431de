"""Systems of particles: the potential builder and the chapter-2 theorems of the course
text (conservation of P and L, uniform centre-of-mass motion, the centre-of-mass
decompositions of T and L), checked to round-off on 3 and 100 bodies."""

import itertools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.mechanics.particles import (
    angular_momentum_split,
    centre_of_mass,
    centre_of_mass_velocity,
    kinetic_energy,
    kinetic_energy_split,
    newtonian_gravity,
    pair_energy,
    particle_hamiltonian,
    particle_lagrangian,
    particle_potential,
    total_angular_momentum,
    total_momentum,
)

from .helpers import relative_close

ROUND_OFF = 1e-13


def soft_core_lennard_jones(r, sigma=0.3, alpha=0.5):
    """4[(s⁶)² − s⁶] with s⁶ = σ⁶/(r⁶ + ασ⁶): finite at r = 0 (Beutler et al. 1994)."""
    inverse6 = sigma**6 / (r**6 + alpha * sigma**6)
    return 4.0 * (inverse6**2 - inverse6)


def random_cluster(count, seed, dimension=3):
    rng = np.random.default_rng(seed)
    masses = jnp.asarray(rng.uniform(0.5, 1.5, count))
    positions = jnp.asarray(rng.normal(size=(count, dimension)))
    velocities = jnp.asarray(0.3 * rng.normal(size=(count, dimension)))
    return masses, positions, masses[:, None] * velocities


@jax.jit
def pair_sums(masses, q, strengths):
    """The builder's potential, forces and an excluded pair against sums by hand,
    in one compiled call (dispatched eagerly, each small expression compiles)."""
    field = lambda r: 0.5 * jnp.sum(r**2) + r[2]
    potential = particle_potential(
        soft_core_lennard_jones,
        pair_strengths=strengths,
        external_potential=field,
        external_couplings=masses,
    )
    pairs = list(itertools.combinations(range(5), 2))
    by_hand = sum(
        strengths[i, j] * soft_core_lennard_jones(jnp.linalg.norm(q[i] - q[j]))
        for i, j in pairs
    ) + sum(masses[i] * field(q[i]) for i in range(5))
    pair_only = jax.grad(lambda x: pair_energy(x, soft_core_lennard_jones, strengths))
    forces = -pair_only(q)
    keep = jnp.ones((5, 5), bool).at[0, 3].set(False).at[3, 0].set(False)
    return dict(
        potential=potential(q),
        by_hand=by_hand,
        net_force=jnp.sum(forces, 0),
        net_torque=total_angular_momentum(q, forces),
        excluded=pair_energy(q, soft_core_lennard_jones, strengths, interacting=keep),
        term=strengths[0, 3] * soft_core_lennard_jones(jnp.linalg.norm(q[0] - q[3])),
        full=pair_energy(q, soft_core_lennard_jones, strengths),
    )


def test_potential_and_forces_match_the_pair_sums():
    masses, q, _ = random_cluster(5, seed=1)
    strengths = np.random.default_rng(2).uniform(0.5, 2.0, (5, 5))
    found = jax.tree_util.tree_map(
        np.asarray, pair_sums(masses, q, strengths + strengths.T)
    )
    assert relative_close(found["potential"], found["by_hand"], 1e-14)
    # Strong law of action and reaction: no net force and no net torque.
    assert float(np.max(np.abs(found["net_force"]))) < ROUND_OFF
    assert float(np.max(np.abs(found["net_torque"]))) < ROUND_OFF
    # Excluding a pair removes exactly its term.
    assert relative_close(found["excluded"] + found["term"], found["full"], 1e-14)


def plain_pair_sum(q, strengths):
    """Σ_{i<j} by plain autodiff-able array code (no custom rule), for reference."""
    upper = np.triu(np.ones((q.shape[0],) * 2, bool), k=1)
    squared = jnp.sum((q[:, None] - q[None]) ** 2, -1)
    distance = jnp.sqrt(jnp.where(upper, squared, 1.0))
    return jnp.sum(jnp.where(upper, strengths * soft_core_lennard_jones(distance), 0.0))


def _ours(q, strengths):
    return pair_energy(q, soft_core_lennard_jones, strengths)


@jax.jit
def derivatives(q, strengths):
    """Every derivative the custom rule must get right, by it (`ours`) and by plain
    autodiff, in one compiled call."""
    symmetric = lambda g, axes: 0.5 * (g + jnp.swapaxes(g, *axes))
    batch = jnp.stack([q, 1.1 * q])
    return dict(
        grad=(jax.grad(_ours)(q, strengths), jax.grad(plain_pair_sum)(q, strengths)),
        hessian=(
            jax.hessian(_ours)(q, strengths),
            jax.hessian(plain_pair_sum)(q, strengths),
        ),
        # Only the symmetric part of k counts: compare derivatives along symmetric k.
        strengths=(
            jax.grad(_ours, 1)(q, strengths),
            symmetric(jax.grad(plain_pair_sum, 1)(q, strengths), (0, 1)),
        ),
        force_sensitivity=(
            jax.jacfwd(jax.grad(_ours), 1)(q, strengths),
            symmetric(jax.jacfwd(jax.grad(plain_pair_sum), 1)(q, strengths), (2, 3)),
        ),
        batched=(
            jax.vmap(jax.grad(_ours), in_axes=(0, None))(batch, strengths)[1],
            jax.grad(plain_pair_sum)(1.1 * q, strengths),
        ),
    )


def test_custom_derivative_rule_matches_plain_autodiff():
    _, q, _ = random_cluster(4, seed=7)
    strengths = np.random.default_rng(8).uniform(0.5, 2.0, (4, 4))
    found = derivatives(q, strengths + strengths.T)
    tolerances = dict(
        grad=1e-12, hessian=1e-12, strengths=1e-13, force_sensitivity=1e-12,
        batched=1e-12,
    )  # fmt: skip
    for name, (ours, plain) in found.items():
        assert relative_close(ours, plain, tolerances[name]), name


@jax.jit
def both_forms(masses, q, p):
    """Hamilton's and Euler–Lagrange's equations and the two energies, compiled."""
    ham = newtonian_gravity(masses, softening=0.1)
    lag = particle_lagrangian(
        masses,
        lambda r: -1.0 / jnp.sqrt(r**2 + 0.01),
        pair_strengths=masses[:, None] * masses[None, :],
    )
    velocities = p / masses[:, None]
    qdot, pdot = ham.vector_field(q, p)
    return dict(
        velocities=velocities,
        qdot=qdot,
        acceleration=lag.acceleration(q, velocities),
        force_over_mass=pdot / masses[:, None],
        lagrangian_energy=lag.energy(q, velocities),
        hamiltonian=ham(q, p),
    )


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_lagrangian_and_hamiltonian_forms_agree():
    found = jax.tree_util.tree_map(np.asarray, both_forms(*random_cluster(3, seed=3)))
    assert relative_close(found["qdot"], found["velocities"], 1e-15)
    assert relative_close(found["acceleration"], found["force_over_mass"], 1e-13)
    assert relative_close(found["lagrangian_energy"], found["hamiltonian"], 1e-14)


def test_diagnostics_in_the_plane_and_bad_input():
    masses, q, p = map(np.asarray, random_cluster(4, seed=4, dimension=2))
    expected = np.sum(q[:, 0] * p[:, 1] - q[:, 1] * p[:, 0])
    total, split = jax.jit(
        lambda q, p, m: (total_angular_momentum(q, p), angular_momentum_split(q, p, m))
    )(q, p, masses)
    assert relative_close(total, expected, 1e-15)
    assert relative_close(split.of_centre + split.about_centre, expected, 1e-14)
    with pytest.raises(ValueError, match="pair_potential"):
        particle_potential()


def figure_eight(boost, offset):
    """Chenciner & Montgomery's three-body choreography (G = m = 1, period 6.3259),
    moved by `offset` and boosted by `boost` so that P, L and R are all non-zero."""
    x1 = jnp.array([0.97000436, -0.24308753, 0.0])
    v3 = jnp.array([-0.93240737, -0.86473146, 0.0])
    positions = jnp.stack([x1, -x1, jnp.zeros(3)]) + offset
    velocities = jnp.stack([-v3 / 2, -v3 / 2, v3]) + boost
    return positions, velocities


@eqx.filter_jit
def chapter_two_quantities(run, masses):
    """Every quantity the theorems compare, in one compiled call (eager dispatch of
    these small array expressions would cost more than the run)."""
    kinetic = kinetic_energy_split(run.p, masses)
    angular = angular_momentum_split(run.q, run.p, masses)
    return dict(
        P=total_momentum(run.p),
        L=total_angular_momentum(run.q, run.p),
        scale_p=jnp.max(jnp.abs(run.p)),
        scale_l=jnp.max(jnp.abs(jnp.cross(run.q, run.p))),
        R=centre_of_mass(run.q, masses),
        V0=centre_of_mass_velocity(run.p[0], masses),
        kinetic_split=kinetic.of_centre + kinetic.about_centre,
        kinetic=kinetic_energy(run.p, masses),
        angular_split=angular.of_centre + angular.about_centre,
        energy=run.energy(),
    )


def assert_chapter_two_theorems(run, masses, *, external_force_free=True):
    """P and L conserved, R uniform (if free); T and L split about the CM, at all t.

    Returns the energies along the run."""
    found = jax.tree_util.tree_map(np.asarray, chapter_two_quantities(run, masses))
    P, L = found["P"], found["L"]
    assert np.max(np.abs(L - L[0])) < ROUND_OFF * found["scale_l"]
    if external_force_free:
        assert np.max(np.abs(P - P[0])) < ROUND_OFF * found["scale_p"]
        elapsed = np.asarray(run.ts - run.ts[0])[:, None]
        uniform = found["R"][0] + elapsed * found["V0"]
        assert relative_close(found["R"], uniform, ROUND_OFF)
    assert relative_close(found["kinetic_split"], found["kinetic"], 1e-14)
    assert relative_close(found["angular_split"], L, 1e-14)
    return found["energy"]


def test_three_body_figure_eight():
    masses = jnp.ones(3)
    boost, offset = np.array([0.1, -0.05, 0.2]), np.array([0.3, 0.2, -0.4])
    q0, v0 = jax.jit(figure_eight)(boost, offset)
    period = 6.32591398
    ts = jnp.linspace(0.0, period, 11)
    run = lj.simulate(
        newtonian_gravity(masses),
        (q0, v0),
        t1=period,
        dt=period / 2000,
        solver=lj.Yoshida6(),
        ts=ts,
    )
    energy = assert_chapter_two_theorems(run, masses)
    assert float(np.max(np.abs(energy - energy[0]))) < 1e-13 * abs(float(energy[0]))
    # After one period the choreography is back where it started, carried by the boost.
    assert relative_close(run.q[-1], np.asarray(q0) + period * boost, 1e-7)


def test_hundred_bodies_under_softened_gravity():
    masses, q0, p0 = random_cluster(100, seed=5)
    ts = jnp.linspace(0.0, 0.5, 6)
    run = lj.simulate(
        newtonian_gravity(masses, gravitational_constant=0.01, softening=0.1),
        (q0, p0),
        t1=0.5,
        dt=0.005,
        solver=lj.Yoshida4(),
        ts=ts,
    )
    energy = assert_chapter_two_theorems(run, masses)
    assert float(np.max(np.abs(energy - energy[0]))) < 1e-8 * abs(float(energy[0]))


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_hundred_bodies_in_a_trap_move_their_centre_like_one_body():
    """In U = ½k m|r|² the internal forces cancel from the centre of mass, which moves
    as one body of mass M in the same trap (eq. 2.7) — with a splitting method, step
    for step to round-off; L about the trap's centre is conserved, P is not."""
    masses, q0, p0 = random_cluster(100, seed=6)
    trap = lambda r: 0.5 * 4.0 * jnp.sum(r**2)
    ham = particle_hamiltonian(
        masses,
        soft_core_lennard_jones,
        pair_strengths=0.1,
        external_potential=trap,
        external_couplings=masses,
    )
    ts = jnp.linspace(0.0, 1.0, 11)
    options = dict(t1=1.0, dt=0.01, solver=lj.Yoshida4(), ts=ts)
    run = lj.simulate(ham, (q0, p0), **options)
    total = np.sum(masses)[None]
    one_body = particle_hamiltonian(
        total, external_potential=trap, external_couplings=total
    )
    # The centre's motion, compiled whole: eager, each small reduction compiles.
    centre_motion = jax.jit(lambda q, p: (centre_of_mass(q, masses), total_momentum(p)))
    centre = tuple(x[None] for x in centre_motion(q0, p0))
    twin = lj.simulate(one_body, centre, **options)
    centre_q, momentum = map(np.asarray, centre_motion(run.q, run.p))
    assert relative_close(centre_q, twin.q[:, 0], ROUND_OFF)
    assert relative_close(momentum, twin.p[:, 0], ROUND_OFF)
    assert float(np.max(np.abs(momentum - np.asarray(centre[1])))) > 0.1
    assert_chapter_two_theorems(run, masses, external_force_free=False)
