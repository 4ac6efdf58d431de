"""The scene mechanism: parameters as fields, passed as args, vmappable."""

import jax
import jax.numpy as jnp
import numpy as np

import lagjax as lj
from lagjax.scenes.base import AbstractScene
from tests.helpers import relative_close


def _oscillator_potential(q, t, scene):
    return 0.5 * scene.stiffness * q**2


def _kinetic(p, t, scene):
    return 0.5 * p**2 / scene.mass


class _Oscillator(AbstractScene):
    mass: jax.Array
    stiffness: jax.Array

    default_t1 = 1.0
    default_dt = 0.01

    def __init__(self, mass=1.0, stiffness=4.0):
        self.mass = jnp.asarray(mass)
        self.stiffness = jnp.asarray(stiffness)

    def system(self):
        return lj.SeparableHamiltonian(_kinetic, _oscillator_potential)

    def initial_state(self):
        return jnp.asarray(1.0), jnp.asarray(0.0)

    def checks(self, trajectory):
        omega = jnp.sqrt(self.stiffness / self.mass)
        return {"q(t1)": (trajectory.q[-1], jnp.cos(omega * trajectory.ts[-1]))}


def test_scene_runs_and_checks():
    scene = _Oscillator()
    traj = lj.simulate(scene, scene.initial_state(), t1=1.0, dt=0.001)
    measured, expected = scene.checks(traj)["q(t1)"]
    assert np.isclose(measured, expected, atol=1e-10)
    # Yoshida4 keeps H to O((ωh)⁴) ≈ 1.6e-11 at ωh = 0.002 (2.0e-12 measured).
    assert relative_close(traj.energy()[-1], 2.0, 1e-10)


def test_vmap_over_scenes_is_a_parameter_sweep():
    stiffnesses = jnp.array([1.0, 4.0, 9.0])
    scenes = jax.vmap(lambda k: _Oscillator(stiffness=k))(stiffnesses)

    def final(scene):
        return lj.simulate(scene, scene.initial_state(), t1=1.0, dt=0.001).q[-1]

    assert np.allclose(
        jax.vmap(final)(scenes), jnp.cos(jnp.sqrt(stiffnesses)), atol=1e-10
    )
