"""`lagjax.scenes` as a public face: every scene exported, one parameter idiom,
`state_kind` declared and honest, `describe()` aligned plain text, and physical
parameters validated where they are set.

No integration here: construction, types and messages only (fast).
"""

import dataclasses
import importlib
import inspect
import math
import pkgutil

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
import lagjax.scenes as scenes
from lagjax.mechanics.hamiltonian import AbstractHamiltonian
from lagjax.mechanics.lagrangian import Lagrangian
from lagjax.scenes import AbstractScene, parameter

HELPERS = {"AbstractScene", "Interval", "parameter"}
FUNCTIONS = {"catalog", "command_name", "describe", "summary"}


def _defined_scene_classes() -> set[type]:
    """Every concrete scene class defined in any module of the package."""
    found = set()
    for info in pkgutil.iter_modules(scenes.__path__):
        module = importlib.import_module(f"lagjax.scenes.{info.name}")
        for _, value in inspect.getmembers(module, inspect.isclass):
            if (
                issubclass(value, AbstractScene)
                and value.__module__ == module.__name__
                and not inspect.isabstract(value)
            ):
                found.add(value)
    return found


SCENE_CLASSES = sorted(_defined_scene_classes(), key=lambda cls: cls.__name__)


def test_every_scene_class_is_exported_and_in_the_catalogue():
    from lagjax.scenes import FoucaultPendulum  # the example

    assert FoucaultPendulum is lj.scenes.earth.FoucaultPendulum
    assert len(SCENE_CLASSES) >= 26
    for cls in SCENE_CLASSES:
        assert getattr(scenes, cls.__name__) is cls, cls
        assert cls.__name__ in scenes.__all__, cls
    assert set(scenes.catalog().values()) == set(SCENE_CLASSES)


def test_catalogue_is_built_from_the_exports_in_a_stable_order():
    catalog = scenes.catalog()
    exported = [getattr(scenes, name) for name in scenes.__all__]
    assert list(catalog.values()) == [c for c in exported if c in set(SCENE_CLASSES)]
    assert list(catalog)[:3] == [
        "harmonic-oscillator",
        "coupled-oscillators",
        "damped-driven-oscillator",
    ]
    assert catalog["foucault-pendulum"] is scenes.FoucaultPendulum
    assert catalog["fermi-pasta-ulam-chain"] is scenes.FermiPastaUlamChain
    for name in catalog:
        assert name == name.lower() and " " not in name and not name.startswith("-")


def test_dir_shows_scenes_submodules_and_documented_functions_only():
    submodules = {info.name for info in pkgutil.iter_modules(scenes.__path__)}
    public = {name for name in dir(scenes) if not name.startswith("_")}
    scene_names = {cls.__name__ for cls in SCENE_CLASSES}
    assert public == scene_names | submodules | HELPERS | FUNCTIONS, public ^ (
        scene_names | submodules | HELPERS | FUNCTIONS
    )
    assert "re" not in public and "annotations" not in public


def test_describe_is_aligned_plain_text():
    lines = scenes.describe().splitlines()
    assert len(lines) == len(scenes.catalog())
    starts = set()
    for line, (name, cls) in zip(lines, scenes.catalog().items()):
        assert line.startswith(name + "  ")
        summary = line[len(name) :].lstrip()
        assert summary == scenes.summary(cls) and summary
        starts.add(len(line) - len(summary))
        for raw in ("$", "\\", "`", "**"):
            assert raw not in summary, (name, summary)
    assert len(starts) == 1  # every description starts in the same column


def test_state_kind_is_declared_on_the_base_and_matches_the_system():
    assert "state_kind" in AbstractScene.__annotations__
    for cls in SCENE_CLASSES:
        system = cls().system()
        kind = cls.state_kind
        if kind == "velocity":
            assert isinstance(system, Lagrangian), cls
        else:
            assert kind == "momentum" and isinstance(system, AbstractHamiltonian), cls


def _array_fields(scene: AbstractScene) -> list[dataclasses.Field]:
    return [
        field
        for field in dataclasses.fields(scene)
        if not field.metadata.get("static", False)
    ]


@pytest.mark.parametrize("cls", SCENE_CLASSES, ids=lambda cls: cls.__name__)
def test_one_parameter_idiom_strongly_typed_float_arrays(cls):
    scene = cls()
    fields = _array_fields(scene)
    assert fields, cls
    for field in fields:
        # Declared with parameter(): it carries a validation rule.
        assert any(key.startswith("lagjax.") for key in field.metadata), field.name
        value = getattr(scene, field.name)
        assert isinstance(value, jax.Array), field.name
        assert value.dtype == jnp.float64, field.name
        assert not value.weak_type, field.name  # one compiled program, however built


def test_python_ints_become_strong_floats():
    pendulum = scenes.SimplePendulum(mass=2, length=1)
    assert pendulum.mass.dtype == jnp.float64 and not pendulum.mass.weak_type
    # Built from numbers or from arrays: the same pytree structure and dtypes.
    from_array = scenes.SimplePendulum(mass=jnp.asarray(2.0), length=np.float64(1))
    same = jax.tree_util.tree_map(
        lambda a, b: a.dtype == b.dtype and a.weak_type == b.weak_type,
        pendulum,
        from_array,
    )
    assert all(jax.tree_util.tree_leaves(same))


@pytest.mark.parametrize(
    ("build", "field", "phrase"),
    [
        (lambda: scenes.SimplePendulum(mass=-1.0), "mass", "> 0"),
        (lambda: scenes.DoublePendulum(lengths=(1.0, 0.0)), "lengths", "> 0"),
        (lambda: scenes.TorqueFreeBody(moments=(1.0, -2.0, 3.0)), "moments", "> 0"),
        (lambda: scenes.HarmonicOscillator(stiffness=math.nan), "stiffness", "finite"),
        (lambda: scenes.KeplerCartesian(eccentricity=1.0), "eccentricity", "[0, 1)"),
        (lambda: scenes.KeplerPolar(semi_major_axis=-1.0), "semi_major_axis", "> 0"),
        (lambda: scenes.FoucaultPendulum(latitude=45.0), "latitude", "radians"),
        (lambda: scenes.SimplePendulum(amplitude=150.0), "amplitude", "radians"),
        (
            lambda: scenes.FreeFall(initial_velocity=math.inf),
            "initial_velocity",
            "finite",
        ),
        (lambda: scenes.SpringChain(mass=0.0), "mass", "> 0"),
    ],
)
def test_bad_parameters_are_refused_naming_the_field_and_the_rule(build, field, phrase):
    with pytest.raises(ValueError, match=field) as error:
        build()
    assert phrase in str(error.value)


def test_scene_specific_invariants_are_checked():
    with pytest.raises(ValueError, match="positive definite"):
        scenes.CoupledOscillators(masses=(1.0, 1.0), stiffness=((1.0, 2.0), (2.0, 1.0)))
    with pytest.raises(ValueError, match="symmetric"):
        scenes.CoupledOscillators(masses=(1.0, 1.0), stiffness=((2.0, 1.0), (0.0, 2.0)))
    with pytest.raises(ValueError, match="underdamped"):
        scenes.DampedDrivenOscillator(mass=1.0, stiffness=4.0, damping=4.0)
    with pytest.raises(ValueError, match="magnetic_field"):
        scenes.ChargeInUniformFields(magnetic_field=(0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="whole number"):
        scenes.SpringChain(size=0)
    with pytest.raises(ValueError, match="whole number"):
        scenes.FermiPastaUlamChain(pairs=2.5)


def test_boundary_values_that_are_physics_are_accepted():
    assert float(scenes.KeplerCartesian(eccentricity=0.0).eccentricity) == 0.0
    assert float(scenes.FoucaultPendulum(latitude=-math.pi / 2).latitude) < 0
    assert float(scenes.DampedDrivenOscillator(damping=0.0).damping) == 0.0
    assert float(scenes.HeavySymmetricTop(theta0=0.0).theta0) == 0.0  # upright


def test_traced_parameters_are_not_checked_and_still_sweep():
    """Under vmap the values are tracers: construction works; checks are skipped."""
    gravities = jnp.array([9.81, 1.62, 24.8])
    batch = jax.vmap(lambda g: scenes.SimplePendulum(gravity=g))(gravities)
    assert batch.gravity.shape == (3,) and batch.gravity.dtype == jnp.float64
    frequencies = jax.vmap(lambda s: s.small_amplitude_frequency())(batch)
    assert np.allclose(frequencies, np.sqrt(gravities))  # ω₀ = √(g/l), l = 1
    # A bad value inside a trace is not caught at construction (documented).
    traced = jax.jit(lambda m: scenes.HarmonicOscillator(mass=m).frequency())
    assert np.isnan(traced(-1.0))


def test_parameter_rejects_conflicting_rules():
    with pytest.raises(TypeError, match="at most one"):
        parameter(1.0, positive=True, nonnegative=True)


def test_scenes_are_final_equinox_modules():
    for cls in SCENE_CLASSES:
        assert issubclass(cls, eqx.Module)
        assert not inspect.isabstract(cls)
