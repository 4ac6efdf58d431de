"""Drawing a Poincaré section: one colour per orbit, the section's own coordinates.

matplotlib is imported inside the function, so the package does not need it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import numpy as np

from lagjax.phase_space.sections import PoincareSection, poincare_section


def _coordinate(section: PoincareSection, pick: Callable[[Any, Any], Any]):
    """pick(q, p) at every stored crossing, as a (batch, max_crossings) array."""
    mapped = jax.vmap(jax.vmap(pick))
    return np.asarray(mapped(section.q, section.p))


def draw_section(
    section: PoincareSection,
    *,
    horizontal: Callable[[Any, Any], Any],
    vertical: Callable[[Any, Any], Any],
    ax: Any = None,
    point_size: float = 1.0,
) -> Any:
    """Scatter the crossings of a computed section, one colour per orbit.

    `horizontal`, `vertical`: `(q, p) -> scalar`, the plotted coordinates, e.g.
    `lambda q, p: q[1]` and `lambda q, p: p[1]` for (y, p_y). Returns the Axes.
    """
    import matplotlib.pyplot as plt

    if ax is None:
        _, ax = plt.subplots(figsize=(5, 5))
    xs, ys = _coordinate(section, horizontal), _coordinate(section, vertical)
    colours = plt.get_cmap("tab20")(np.arange(xs.shape[0]) % 20)
    for x, y, colour in zip(xs, ys, colours, strict=True):
        stored = np.isfinite(x) & np.isfinite(y)  # drop the NaN padding
        ax.scatter(x[stored], y[stored], s=point_size, color=colour, linewidths=0)
    ax.set_title(f"Poincaré section, {xs.shape[0]} orbits")
    return ax


def plot_poincare_section(
    system: Any,
    y0s: tuple[Any, Any],
    t1: float,
    surface: Callable[[Any, Any], Any],
    *,
    horizontal: Callable[[Any, Any], Any],
    vertical: Callable[[Any, Any], Any],
    ax: Any = None,
    point_size: float = 1.0,
    **section_options: Any,
) -> tuple[Any, PoincareSection]:
    """Compute the section of the orbits from `y0s` and draw it (`draw_section`).

    Build `y0s` on an energy shell with `states_on_energy_shell` (a grid in the
    section's coordinates) to draw the classic picture.

    **Arguments:**
    - `system`, `y0s`, `t1`, `surface`: as `poincare_section`; `section_options`
      (`dt`, `solver`, `direction`, `max_crossings`, `args`) are passed on.
    - `horizontal`, `vertical`, `ax`, `point_size`: as `draw_section`.

    **Returns:** `(ax, section)`.
    """
    section = poincare_section(system, y0s, t1, surface, **section_options)
    ax = draw_section(
        section, horizontal=horizontal, vertical=vertical, ax=ax, point_size=point_size
    )
    return ax, section
