"""A disk rolling without slipping: nonholonomic constraints with multipliers.

Oracles independent of the code: the steady circular motion from Newton–Euler
about the centre (`RollingDisk.steady_spin_rate`), energy conservation (friction at
a rolling contact does no work) and the contact point at rest.
"""

import jax
import jax.numpy as jnp

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


def test_friction_force_of_steady_rolling():
    """λ is the horizontal contact force: in steady rolling, the centripetal one.

    Newton for the centre on its circle: F = m R σ Ω ĥ, σ = ψ̇ + Ω sin θ the spin
    about the axis, ĥ = ŷ at heading 0 (and no force along the rolling direction).
    """
    disk = RollingDisk(spin_rate=0.0)
    disk = RollingDisk(spin_rate=disk.steady_spin_rate())
    q0, qdot0 = disk.initial_state()
    lag = disk.system()
    axial = disk.spin_rate + disk.heading_rate * jnp.sin(disk.tilt)
    centripetal = disk.mass * disk.radius * axial * disk.heading_rate
    force = lag.multipliers(q0, qdot0, 0.0, disk)
    assert relative_close(force, jnp.stack([0.0, centripetal]), 1e-12)


@jax.jit
@jax.vmap
def roll(disk):
    """A run of `disk` (t = 0..3 s) and what it measured, in one compile."""
    run = lj.simulate(disk, disk.initial_state(), t1=3.0, dt=2e-3)
    return dict(
        start=disk.initial_state(),
        end=(run.q[-1], run.qdot[-1]),
        checks=disk.checks(run),
    )


def test_steady_and_nutating_rolling():
    steady = RollingDisk(spin_rate=0.0).steady_spin_rate()
    spins = jnp.stack([steady, jnp.asarray(-15.0)])  # steady circle; nutating
    out = roll(jax.vmap(lambda spin: RollingDisk(spin_rate=spin))(spins))
    energy, energy0 = out["checks"]["energy"]
    assert relative_close(energy, energy0, 1e-12)
    # ċ = ω × (c − P): the contact point is at rest.
    centre_velocity, rolling_velocity = out["checks"]["rolling"]
    assert relative_close(centre_velocity, rolling_velocity, 1e-15)
    (q0, qdot0), (q, qdot) = out["start"], out["end"]
    # Steady: tilt, tilt rate, heading rate and spin stay at their start values.
    assert abs(float(q[0, 2] - q0[0, 2])) < 1e-11
    assert relative_close(qdot[0, 2:], qdot0[0, 2:], 1e-11)
    # Nutating: the tilt really moves (so the checks above are not vacuous).
    assert abs(float(q[1, 2] - q0[1, 2])) > 1e-2
