"""Scenes: the classical-mechanics canon as ready-made systems with known answers.

Every scene class is importable from here (`from lagjax.scenes import
FoucaultPendulum`); `catalog()` maps each one's command-line name to its class and
`describe()` lists them. Every class docstring starts with a one-line description and
gives its L or H, its parameters with their units and the source of its closed forms.
See `base.AbstractScene` for the convention and `base.parameter` for how parameters
are declared and checked.
"""

from lagjax.scenes.base import AbstractScene as AbstractScene
from lagjax.scenes.base import Interval as Interval
from lagjax.scenes.base import parameter as parameter
from lagjax.scenes.central import KeplerCartesian as KeplerCartesian
from lagjax.scenes.central import KeplerPolar as KeplerPolar
from lagjax.scenes.chains import FermiPastaUlamChain as FermiPastaUlamChain
from lagjax.scenes.chains import LinearTriatomicMolecule as LinearTriatomicMolecule
from lagjax.scenes.chains import SpringChain as SpringChain
from lagjax.scenes.constrained import CartesianAtwoodMachine as CartesianAtwoodMachine
from lagjax.scenes.constrained import CartesianPendulum as CartesianPendulum
from lagjax.scenes.constrained import (
    CartesianRotatingWireBead as CartesianRotatingWireBead,
)
from lagjax.scenes.driven import DampedDrivenOscillator as DampedDrivenOscillator
from lagjax.scenes.earth import EastwardDeflection as EastwardDeflection
from lagjax.scenes.earth import FoucaultPendulum as FoucaultPendulum
from lagjax.scenes.earth import PlumbLine as PlumbLine
from lagjax.scenes.fields import AtwoodMachine as AtwoodMachine
from lagjax.scenes.fields import ChargeInUniformFields as ChargeInUniformFields
from lagjax.scenes.fields import FreeFall as FreeFall
from lagjax.scenes.oscillators import CoupledOscillators as CoupledOscillators
from lagjax.scenes.oscillators import HarmonicOscillator as HarmonicOscillator
from lagjax.scenes.pendulums import DoublePendulum as DoublePendulum
from lagjax.scenes.pendulums import SimplePendulum as SimplePendulum
from lagjax.scenes.planetary import PlanetarySystem as PlanetarySystem
from lagjax.scenes.pythagorean import PythagoreanThreeBody as PythagoreanThreeBody
from lagjax.scenes.rigid import EarthFreePrecession as EarthFreePrecession
from lagjax.scenes.rigid import HeavySymmetricTop as HeavySymmetricTop
from lagjax.scenes.rigid import TorqueFreeBody as TorqueFreeBody
from lagjax.scenes.rolling_disk import RollingDisk as RollingDisk
from lagjax.scenes.rotating import AcceleratedFrameParticle as AcceleratedFrameParticle
from lagjax.scenes.rotating import BeadOnRotatingWire as BeadOnRotatingWire
from lagjax.scenes.rotating import SpinningFrameParticle as SpinningFrameParticle

# The catalogue's order (not alphabetical): from the oscillator to the rolling disk,
# as a course goes.
__all__ = [  # noqa: RUF022
    "HarmonicOscillator",
    "CoupledOscillators",
    "DampedDrivenOscillator",
    "SimplePendulum",
    "DoublePendulum",
    "LinearTriatomicMolecule",
    "SpringChain",
    "FermiPastaUlamChain",
    "FoucaultPendulum",
    "EastwardDeflection",
    "PlumbLine",
    "SpinningFrameParticle",
    "AcceleratedFrameParticle",
    "BeadOnRotatingWire",
    "KeplerCartesian",
    "KeplerPolar",
    "PlanetarySystem",
    "PythagoreanThreeBody",
    "ChargeInUniformFields",
    "AtwoodMachine",
    "FreeFall",
    "TorqueFreeBody",
    "HeavySymmetricTop",
    "EarthFreePrecession",
    "CartesianPendulum",
    "CartesianAtwoodMachine",
    "CartesianRotatingWireBead",
    "RollingDisk",
    "AbstractScene",
    "Interval",
    "parameter",
    "catalog",
    "command_name",
    "describe",
    "summary",
]


def command_name(scene_class: type) -> str:
    """The scene's command-line name: `SimplePendulum` → `simple-pendulum`."""
    name = scene_class.__name__
    return "".join(
        f"-{char.lower()}" if char.isupper() and index else char.lower()
        for index, char in enumerate(name)
    )


def catalog() -> dict[str, type[AbstractScene]]:
    """{command-line name: scene class} for every scene exported here, in `__all__`'s
    order (stable: the command line and the tests rely on it)."""
    exported = (globals()[name] for name in __all__)
    return {
        command_name(cls): cls
        for cls in exported
        if isinstance(cls, type)
        and issubclass(cls, AbstractScene)
        and not cls.__name__.startswith("Abstract")
    }


def summary(scene_class: type) -> str:
    """The first line of the scene's docstring: plain text, no LaTeX or Markdown."""
    return (scene_class.__doc__ or "").strip().splitlines()[0]


def describe() -> str:
    """One line per scene, aligned: its command-line name and what it is."""
    names = catalog()
    width = max(map(len, names)) + 2
    return "\n".join(f"{name:<{width}}{summary(cls)}" for name, cls in names.items())
