"""`AbstractScene`: a worked example — a system, its parameters, a start, its answers.

A scene is an equinox Module whose physical parameters are array fields declared
with `parameter()`. Its physics is a plain function `L(q, qdot, t, scene)` (or
`H(q, p, t, scene)`, or `T(p, t, scene)` and `V(q, t, scene)`) that reads the
parameters from the scene passed as `args`; `system()` wraps that function in the
right lagjax class — a `SeparableHamiltonian` when the physics is separable, a
`Lagrangian` with no time dependence when autonomous, and so on, so nothing the scene
does not need is computed. Because the parameters travel as `args`, `jax.vmap` over
a batch of scenes is a parameter sweep:

    scenes = jax.vmap(lambda g: SimplePendulum(gravity=g))(gs)
    finals = jax.vmap(lambda s: lj.simulate(s, s.initial_state(), t1=1.0, dt=1e-3).q)(scenes)

**Validation.** Each `parameter()` states what the physics allows — `positive=True`
for masses, lengths, moments, stiffnesses; an `Interval` for eccentricities and
angles — and every parameter must be finite. `AbstractScene.__check_init__` checks
*concrete* values when a scene is built and raises a `ValueError` naming the
parameter, its value and the allowed range. Values that are JAX tracers (a scene
built inside `jax.jit`, `jax.vmap` or `jax.grad`) are not checked: their values do
not exist at trace time, and a run-time check (`eqx.error_if`) inside every traced
construction would add a host callback to the compiled sweep. Validate a batch
before vmapping over it (e.g. build one scene from its extremes).

**Units.** SI unless a scene says otherwise; **angles are in radians** (latitudes,
amplitudes, tilts): pass `math.radians(45)`, not `45`. Angle parameters with a
bounded range reject a value in degrees with a hint.

**Coordinates.** A scene names its coordinates and their units
(`coordinate_names`, `coordinate_units`, `time_unit`; `coordinates()` gives one
name and one unit per entry of q flattened), so that plots and tables read like
physics: "θ [rad]", "x [m]" rather than "q[0]". Undeclared names are `q[i]` with no
unit.

A scene holds physics and known answers only: no derivation, no integration.
`checks(trajectory)` compares what a run measured with the scene's closed forms, for
the command line and notebooks; `diagnostic(trajectory)`, where a scene has one, is
the one curve that shows its physics along a run (the Foucault pendulum's swing
plane turning at −ω_E sin φ, say), measured against its closed form.
"""

from __future__ import annotations

import abc
import dataclasses
import math
from collections.abc import Callable
from typing import Any, ClassVar, Literal, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.core import Tracer
from jax.flatten_util import ravel_pytree

from lagjax._core.solver_kinds import DefaultMethod
from lagjax._core.system import AbstractSystem
from lagjax._core.system_protocols import LagrangianLike
from lagjax.mechanics.hamiltonian import AbstractHamiltonian
from lagjax.mechanics.lagrangian import Lagrangian

_RULE = "lagjax.scene_parameter"  # the field-metadata key of a parameter's rule

StateKind = Literal["velocity", "momentum"]


@dataclasses.dataclass(frozen=True)
class Interval:
    """The allowed values of a parameter, e.g. `Interval(0, 1, include_high=False)`
    for an eccentricity of a bound orbit, 0 ≤ e < 1."""

    low: float = -math.inf
    high: float = math.inf
    include_low: bool = True
    include_high: bool = True

    def contains(self, value: np.ndarray) -> bool:
        above = value >= self.low if self.include_low else value > self.low
        below = value <= self.high if self.include_high else value < self.high
        return bool(np.all(above & below))

    def __str__(self) -> str:
        if self.high == math.inf:
            return f"{'≥' if self.include_low else '>'} {self.low:g}"
        if self.low == -math.inf:
            return f"{'≤' if self.include_high else '<'} {self.high:g}"
        left, right = (
            "[" if self.include_low else "(",
            "]" if self.include_high else ")",
        )
        return f"in {left}{self.low:.6g}, {self.high:.6g}{right}"


POSITIVE = Interval(0.0, include_low=False)
NONNEGATIVE = Interval(0.0)
LATITUDE = Interval(-math.pi / 2, math.pi / 2)
# A pendulum released at rest at |θ₀| < π; at the top it would stay (and its period
# diverges), and a value in degrees is caught.
BELOW_THE_TOP = Interval(-math.pi, math.pi, include_low=False, include_high=False)


@dataclasses.dataclass(frozen=True)
class _Rule:
    """What `AbstractScene.__check_init__` checks of one parameter."""

    within: Interval | None
    angle: bool

    def problem(self, value: np.ndarray) -> str | None:
        """Why a concrete value is not allowed, or None."""
        if not np.all(np.isfinite(value)):
            return "must be finite"
        if self.within is None or self.within.contains(value):
            return None
        hint = ""
        if self.angle:
            hint = " (angles are in radians: math.radians(degrees))"
        return f"must be {self.within}{hint}"


def _float_array(value: Any) -> jax.Array:
    # An explicit float dtype: weakly typed scalars would make scenes built from
    # Python numbers and from arrays compile separately.
    return jnp.asarray(value, dtype=float)


def parameter(
    default: Any,
    *,
    positive: bool = False,
    nonnegative: bool = False,
    within: Interval | None = None,
    angle: bool = False,
    convert: Callable[[jax.Array], jax.Array] | None = None,
) -> Any:
    """A physical parameter field: a float array (vmappable, differentiable), checked.

    **Arguments:**

    - `default`: the value when the caller gives none (a number or a nested tuple).
    - `positive`, `nonnegative`, `within`: the allowed values (> 0, ≥ 0, an
      `Interval`); checked, with finiteness, on concrete values when the scene is
      built (see the module docstring for traced values).
    - `angle`: the parameter is an angle in radians (documents it; a range error
      then says so).
    - `convert`: a further conversion of the float array (e.g. a vector of
      diagonal entries to a matrix).
    """
    if positive + nonnegative + (within is not None) > 1:
        raise TypeError("parameter: give at most one of positive, nonnegative, within")
    if positive:
        within = POSITIVE
    elif nonnegative:
        within = NONNEGATIVE

    def converter(value: Any) -> jax.Array:
        array = _float_array(value)
        return array if convert is None else convert(array)

    return eqx.field(
        default=default,
        converter=converter,
        metadata={_RULE: _Rule(within, angle)},
    )


def count(default: int, *, minimum: int = 1) -> Any:
    """A static integer field (a number of masses, of pairs): it fixes array shapes,
    so it is part of the compiled program rather than a traced parameter."""

    def converter(value: Any) -> int:
        number = int(value)
        if number != value or number < minimum:
            raise ValueError(f"expected a whole number ≥ {minimum}, got {value!r}")
        return number

    return eqx.field(default=default, converter=converter, static=True)


def _is_traced(value: Any) -> bool:
    return isinstance(value, Tracer)


def concrete(*values: Any) -> list[np.ndarray] | None:
    """The values as numpy arrays for a construction-time check, or None when any is
    a tracer (a scene built under `jit`/`vmap`/`grad` is not checked)."""
    if any(_is_traced(value) for value in values):
        return None
    return [np.asarray(value) for value in values]


_SUBSCRIPTS = str.maketrans("0123456789", "₀₁₂₃₄₅₆₇₈₉")


def numbered(symbol: str, size: int) -> tuple[str, ...]:
    """`symbol` with subscripts 1 … size: `numbered("x", 3)` → ("x₁", "x₂", "x₃")."""
    return tuple(f"{symbol}{str(i).translate(_SUBSCRIPTS)}" for i in range(1, size + 1))


class Diagnostic(NamedTuple):
    """One quantity measured along a run, against its closed form where known.

    `label` names the quantity and its unit ("swing-plane angle [rad]"); `measured`
    and `expected` (or None) are sampled at the saved times `ts`;
    `expected_label` names the closed form ("−ω_E sin φ · t").
    """

    label: str
    ts: jax.Array
    measured: jax.Array
    expected: jax.Array | None = None
    expected_label: str = "closed form"


class AbstractScene(AbstractSystem):
    """Base of all scenes. Subclasses are final equinox Modules.

    Class attributes:

    - `default_t1` (s) and `default_dt` (s, for fixed-step solvers; the scene's own
      scale);
    - `state_kind`: what `initial_state()` returns besides q — `"velocity"` for
      (q, q̇) when `system()` is a `Lagrangian`, `"momentum"` for (q, p) when it is
      a Hamiltonian. Tests and the command line use it to read a run's state.
    - `coordinate_names`, `coordinate_units`: one plain-text (Unicode) name and
      unit per entry of q flattened, e.g. `("θ",)` and `("rad",)`; a scene whose
      number of coordinates is a parameter overrides `coordinates()` instead.
      Left empty, they read `q[i]` and no unit. `time_unit`: "s" unless the scene
      is dimensionless.

    Parameters are fields declared with `parameter()`, validated when concrete.
    """

    default_t1: ClassVar[float]
    default_dt: ClassVar[float]
    state_kind: ClassVar[StateKind]
    coordinate_names: ClassVar[tuple[str, ...]] = ()
    coordinate_units: ClassVar[tuple[str, ...]] = ()
    time_unit: ClassVar[str] = "s"

    def __check_init__(self) -> None:
        for field in dataclasses.fields(self):
            rule = field.metadata.get(_RULE)
            value = getattr(self, field.name, None)
            if rule is None or value is None or _is_traced(value):
                continue
            problem = rule.problem(np.asarray(value))
            if problem is not None:
                raise ValueError(
                    f"{type(self).__name__}: {field.name} = {np.asarray(value)} "
                    f"{problem}"
                )

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

    def default_method(self, dt: Any) -> DefaultMethod:
        return self.system().default_method(dt)

    def keeps_constraints(self) -> bool:
        return self.system().keeps_constraints()

    def state_rate(self, q: Any, second: Any, t: Any, args: Any) -> tuple[Any, Any]:
        return self.system().state_rate(q, second, t, self if args is None else args)

    def checked_state_pair(self, first: Any, second: Any) -> tuple[Any, Any]:
        """The system's checks, and the shapes of `self.initial_state()`."""
        first, second = self.system().checked_state_pair(first, second)
        got = jax.tree_util.tree_map(jnp.shape, (first, second))
        want = _initial_state_shapes(self)
        if got != want:
            raise ValueError(
                f"{type(self).__name__}'s state has shapes {want} (as "
                f"scene.initial_state() gives), got {got}; start from "
                "scene.initial_state() and change its values"
            )
        return first, second

    def accepted_terms(self) -> tuple[type, ...]:
        return self.system().accepted_terms()

    def default_span(self) -> tuple[float, float | None]:
        return type(self).default_t1, type(self).default_dt

    def phase_space_obstacle(self) -> str | None:
        return self.system().phase_space_obstacle()

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

    def path_lagrangian(self) -> LagrangianLike:
        return self.system().path_lagrangian()

    def conserves_energy_if_autonomous(self) -> bool:
        return self.system().conserves_energy_if_autonomous()

    def checks(self, trajectory: Any) -> dict[str, tuple[jax.Array, jax.Array]]:
        """{name: (measured, expected)} from a trajectory of this scene.

        The default has none; scenes with closed forms override it.
        """
        del trajectory
        return {}

    def coordinates(self) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """(names, units): one each per entry of q flattened, in that order.

        From `coordinate_names` and `coordinate_units`; `q[i]` and "" where a
        scene declares none. A declaration of the wrong length raises.
        """
        size = int(ravel_pytree(self.initial_state()[0])[0].size)
        names = self.coordinate_names or tuple(f"q[{i}]" for i in range(size))
        units = self.coordinate_units or ("",) * size
        if len(names) != size or len(units) != size:
            raise ValueError(
                f"{type(self).__name__} has {size} coordinates but declares "
                f"{len(names)} names and {len(units)} units"
            )
        return names, units

    def diagnostic(self, trajectory: Any) -> Diagnostic | None:
        """The curve that shows this scene's physics along a saved run, or None.

        The default has none (the command then shows the energy error alone).
        """
        del trajectory
        return None


# The shapes of a scene's initial state, by the scene's structure and its leaves'
# shapes and dtypes: tracing `initial_state` for them took 5 ms of every call
# (`simulate` checks y0 against them), as much as a short run.
_INITIAL_SHAPES: dict[Any, Any] = {}
_INITIAL_SHAPES_KEPT = 256


def _initial_state_shapes(scene: Any) -> Any:
    def traced() -> Any:
        expected = jax.eval_shape(scene.initial_state)
        return jax.tree_util.tree_map(lambda x: x.shape, tuple(expected))

    leaves, structure = jax.tree_util.tree_flatten(scene)
    key = (
        structure,
        tuple((np.shape(x), str(getattr(x, "dtype", type(x)))) for x in leaves),
    )
    try:
        hash(key)
    except TypeError:  # a static field that cannot be hashed: no cache
        return traced()
    if key not in _INITIAL_SHAPES:
        if len(_INITIAL_SHAPES) >= _INITIAL_SHAPES_KEPT:
            _INITIAL_SHAPES.clear()
        _INITIAL_SHAPES[key] = traced()
    return _INITIAL_SHAPES[key]
