"""A disk rolling without slipping: nonholonomic constraints with multipliers.

Oracles independent of the code: the steady circular motion from Newton–Euler
about the centre (`RollingDisk.steady_spin_rate`), energy conservation (friction at
a rolling contact does no work) and the contact point at rest.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.scenes.constrained import RollingDisk, _contact_point_velocity
from tests.helpers import relative_close


def test_rolling_constraint_rows():
    disk = RollingDisk()
    q = jnp.array([0.3, -0.2, 0.4, 1.1, 0.7])
    qdot = jnp.array([0.5, -0.3, 0.2, 0.9, -2.0])
    constraints = disk.system().constraints
    assert constraints is not None

    @jax.jit
    def measure(q, qdot):
        start = disk.initial_state()
        return (
            _contact_point_velocity(q, qdot, disk),
            constraints.jacobian(q, 0.0, disk),
            _contact_point_velocity(*start, disk),
        )

    contact, jacobian, contact_at_start = measure(q, qdot)
    # The vertical velocity of the contact point vanishes for any motion that keeps
    # the disk on the plane: only two of the three rows are constraints.
    assert abs(float(contact[2])) < 1e-15 < abs(float(contact[0]))
    assert jacobian.shape == (2, 5)
    assert float(jnp.max(jnp.abs(contact_at_start))) < 1e-15


@jax.jit
def steady_disk():
    """The default disk with the spin of steady rolling at its tilt and heading rate."""
    return RollingDisk(spin_rate=RollingDisk().steady_spin_rate())


@jax.jit
def start_multipliers(disk):
    return disk.system().multipliers(*disk.initial_state(), 0.0, disk)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_friction_force_of_steady_rolling():
    """λ is the horizontal contact force: in steady rolling, the centripetal one.

    Newton for the centre on its circle: F = m R σ Ω ĥ, σ = ψ̇ + Ω sin θ the spin
    about the axis, ĥ = ŷ at heading 0 (and no force along the rolling direction).
    """
    disk = steady_disk()
    force = start_multipliers(disk)
    disk = jax.tree_util.tree_map(np.asarray, disk)
    axial = disk.spin_rate + disk.heading_rate * np.sin(disk.tilt)
    centripetal = disk.mass * disk.radius * axial * disk.heading_rate
    assert relative_close(force, np.stack([0.0, centripetal]), 1e-12)


@jax.jit
def roll(disk):
    """A run of `disk` (t = 0..3 s) and what it measured, in one compile shared by
    every disk (vmapping it over the disks doubles its trace and compile time)."""
    run = lj.simulate(disk, disk.initial_state(), t1=3.0, dt=2e-3)
    return dict(
        start=disk.initial_state(),
        end=(run.q[-1], run.qdot[-1]),
        checks=disk.checks(run),
    )


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_steady_and_nutating_rolling():
    as_numpy = lambda out: jax.tree_util.tree_map(np.asarray, out)
    steady = as_numpy(roll(steady_disk()))  # a steady circle
    nutating = as_numpy(roll(RollingDisk(spin_rate=-15.0)))
    for out in (steady, nutating):
        energy, energy0 = out["checks"]["energy"]
        assert relative_close(energy, energy0, 1e-12)
        # ċ = ω × (c − P): the contact point is at rest.
        centre_velocity, rolling_velocity = out["checks"]["rolling"]
        assert relative_close(centre_velocity, rolling_velocity, 1e-15)
    # Steady: tilt, tilt rate, heading rate and spin stay at their start values.
    (q0, qdot0), (q, qdot) = steady["start"], steady["end"]
    assert abs(float(q[2] - q0[2])) < 1e-11
    assert relative_close(qdot[2:], qdot0[2:], 1e-11)
    # Nutating: the tilt really moves (so the checks above are not vacuous).
    (q0, _), (q, _) = nutating["start"], nutating["end"]
    assert abs(float(q[2] - q0[2])) > 1e-2
