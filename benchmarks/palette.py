"""One colour per method, one line style per implementation, in every figure.

Every figure-making script of `benchmarks/` draws its lines through `style(label)`,
so that Dopri8 is the same red in the work-precision diagrams, the rigid-body
long-horizon figure and the scaling figure, and a reader who learnt the colours
in one figure can read the next.

- **Colour = the numerical method** (Störmer–Verlet, Yoshida 4, Dopri8, scipy's
  DOP853, …; the SymPy route is a method of its own). The method is the longest
  known name in the label (`RigidBodyYoshida4` before `Yoshida4`), else the
  `method` argument (the scaling figure's routes, "lagjax" or "hand-written
  diffrax", all run Dopri8 or Tsit5). A label with no known method gets a colour from a stable
  hash of itself, the same in every figure.
- **Line style and marker = the implementation**: lagjax solid with circles; the
  same equations written by hand for diffrax dashed with squares, for scipy
  dash-dotted with triangles; the SymPy route dotted; `lj.sweep` dotted with
  crosses. Variants of a lagjax method (`(no compensation)`, `(axes split)`) keep
  its colour and marker and change the dash.

`restyle(axes)` applies the same mapping to lines drawn elsewhere (by
`lagjax.diagnostics.plot_work_precision`), by their labels.
"""

from __future__ import annotations

import zlib
from typing import Any

# fmt: off
METHOD_COLOURS = {
    "StormerVerlet": "#1f77b4", "Yoshida4": "#ff7f0e", "KahanLi8": "#2ca02c",
    "BlanesMoan4": "#98df8a", "SofSpa10": "#006d2c", "Yoshida6": "#ffbb78",
    "GaussLegendre(2)": "#9467bd", "GaussLegendre(3)": "#8c564b",
    "ImplicitMidpoint": "#c5b0d5", "VariationalMidpoint": "#c49c94",
    "RigidBodyVerlet": "#17becf", "RigidBodyYoshida4": "#a6761d",
    "Tsit5": "#e377c2", "Dopri8": "#d62728", "Dopri5": "#ff9896",
    "Kvaerno5": "#7f7f7f", "DOP853": "#bcbd22", "LSODA": "#393b79", "Radau": "#637939",
    "SymPy": "#000000",
}
# (what the label contains, its line style and marker), the first match wins.
IMPLEMENTATIONS = (
    ("lj.sweep", ":", "x"),
    ("SymPy, symbolic", "-.", "D"),
    ("SymPy", ":", "v"),
    ("diffrax", "--", "s"),
    ("scipy", "-.", "^"),
)
VARIANT_DASHES = {"(no compensation)": "--", "(axes split)": ":"}
# fmt: on
_SPARE = ("#6b6ecf", "#b5cf6b", "#e7ba52", "#ad494a", "#a55194", "#3182bd", "#e6550d")


def method_of(label: str) -> str | None:
    """The known method a label names (the longest match), or None."""
    if label.startswith("SymPy"):
        return "SymPy"
    for name in sorted(METHOD_COLOURS, key=len, reverse=True):
        if name in label:
            return name
    return None


def colour(label: str, method: str | None = None) -> str:
    """The colour of the method `label` names, else of `method` when given."""
    name = method_of(label) or method
    if name in METHOD_COLOURS:
        return METHOD_COLOURS[name]
    return _SPARE[zlib.crc32(label.encode()) % len(_SPARE)]


def style(label: str, method: str | None = None) -> dict[str, Any]:
    """matplotlib line properties for the line `label`: colour, dash and marker."""
    linestyle, marker = "-", "o"  # lagjax
    for part, dash, symbol in IMPLEMENTATIONS:
        if part in label:
            linestyle, marker = dash, symbol
            break
    for variant, dash in VARIANT_DASHES.items():
        if variant in label:
            linestyle = dash
    return dict(color=colour(label, method), linestyle=linestyle, marker=marker)


def restyle(axes: Any, method: str | None = None) -> None:
    """Give every labelled line of `axes` its `style`, and redraw the legend."""
    for line in axes.get_lines():
        label = line.get_label()
        if not label.startswith("_"):  # matplotlib's unlabelled lines
            line.set(**style(label, method))
    legend = axes.get_legend()
    if legend is not None:
        axes.legend(fontsize=legend.get_texts()[0].get_fontsize(), loc="best")
