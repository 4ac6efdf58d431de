"""`AbstractScene`: a worked example — a system, its parameters, a start, its answers.

A scene is an equinox Module whose physical parameters are array fields. Its
physics is a plain function `L(q, qdot, t, scene)` (or `H(q, p, t, scene)`, or
`T(p, t, scene)` and `V(q, t, scene)`) that reads the parameters from the scene
passed as `args`; `system()` wraps that function in the right lagjax class — a
`SeparableHamiltonian` when the physics is separable, a `Lagrangian` with no time
dependence when autonomous, and so on, so nothing the scene does not need is
computed. Because the parameters travel as `args`, `jax.vmap` over a batch of
scenes is a parameter sweep:

    scenes = jax.vmap(lambda g: SimplePendulum(g=g))(gs)
    finals = jax.vmap(lambda s: lj.simulate(s, s.initial_state(), t1=1.0, dt=1e-3).q)(scenes)

A scene holds physics and known answers only: no derivation, no integration.
`checks(trajectory)` compares what a run measured with the scene's closed forms, for
the command line and notebooks.
"""

from __future__ import annotations

import abc
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp

from lagjax.mechanics.hamiltonian import AbstractHamiltonian
from lagjax.mechanics.lagrangian import Lagrangian
from lagjax.system import AbstractSystem


def parameter(default: float | Any) -> Any:
    """A physical parameter field: a float array (vmappable, differentiable).

    Stored with an explicit float dtype: weakly typed scalars would make scenes
    built from Python numbers and from arrays compile separately.
    """
    return eqx.field(default=default, converter=lambda x: jnp.asarray(x, dtype=float))


class AbstractScene(AbstractSystem):
    """Base of all scenes. Subclasses are final equinox Modules.

    Class attributes: `default_t1` (s) and `default_dt` (s, for fixed-step solvers;
    the scene's own scale). Store parameters as `jnp.asarray(x, dtype=float)`: weakly
    typed scalars would make differently built scenes compile separately.
    """

    default_t1: ClassVar[float]
    default_dt: ClassVar[float]

    @abc.abstractmethod
    def system(self) -> Lagrangian | AbstractHamiltonian:
        """The lagjax system; integrate it with `args=self` (simulate does)."""

    @abc.abstractmethod
    def initial_state(self) -> tuple[Any, Any]:
        """A representative start: (q0, q̇0) for a Lagrangian, (q0, p0) otherwise."""

    # -- AbstractSystem: a scene is its system with itself as `args` -------------
    # `simulate` and the action resolve a scene first; the other methods delegate
    # for code that holds a scene directly.

    def resolve(self, args: Any) -> tuple[AbstractSystem, Any]:
        """`(self.system(), self)`, or the caller's `args` when given (a batch of
        scenes, or a scene of other parameters)."""
        return self.system(), self if args is None else args

    def default_solver(self, dt: Any) -> Any:
        return self.system().default_solver(dt)

    def adapt_solver(self, solver: Any) -> Any:
        return self.system().adapt_solver(solver)

    def integration(self, solver: Any, y0: Any, t0: Any, args: Any) -> Any:
        args = self if args is None else args
        return self.system().integration(solver, y0, t0, args)

    @property
    def second_is_momentum(self) -> bool:
        return self.system().second_is_momentum

    def state_velocity(self, q: Any, second: Any, t: Any, args: Any) -> Any:
        return self.system().state_velocity(q, second, t, args)

    def state_momentum(self, q: Any, second: Any, t: Any, args: Any) -> Any:
        return self.system().state_momentum(q, second, t, args)

    def state_energy(self, q: Any, second: Any, t: Any, args: Any) -> Any:
        return self.system().state_energy(q, second, t, args)

    def path_lagrangian(self) -> Lagrangian:
        return self.system().path_lagrangian()

    def checks(self, trajectory: Any) -> dict[str, tuple[jax.Array, jax.Array]]:
        """{name: (measured, expected)} from a trajectory of this scene.

        The default has none; scenes with closed forms override it.
        """
        del trajectory
        return {}
