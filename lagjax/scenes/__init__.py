"""Scenes: the classical-mechanics canon as ready-made systems with known answers.

`catalog()` maps each scene's command-line name to its class; every class docstring
starts with a one-line description and gives its L or H and the source of its
closed forms. See `base.AbstractScene` for the convention.
"""

from __future__ import annotations

import re

from .base import AbstractScene as AbstractScene


def _command_name(scene_class: type) -> str:
    """`SimplePendulum` → `simple-pendulum`."""
    return re.sub(r"(?<!^)(?=[A-Z])", "-", scene_class.__name__).lower()


def catalog() -> dict[str, type[AbstractScene]]:
    """{command-line name: scene class} for every scene, in a stable order."""
    from . import (
        central,
        chains,
        constrained,
        earth,
        fields,
        oscillators,
        pendulums,
        rigid,
        rotating,
    )

    modules = (
        oscillators,
        pendulums,
        chains,
        earth,
        rotating,
        central,
        fields,
        rigid,
        constrained,
    )
    return {_command_name(cls): cls for module in modules for cls in module.SCENES}


def describe() -> str:
    """One line per scene: its name and what it is."""
    return "\n".join(
        f"{name:28s} {(cls.__doc__ or '').strip().splitlines()[0]}"
        for name, cls in catalog().items()
    )
