"""benchmarks/palette.py: one colour per method, one style per implementation."""

from benchmarks import palette


def test_a_method_has_one_colour_whoever_implements_it():
    dopri8 = {
        palette.colour(label)
        for label in (
            "lagjax Dopri8",
            "diffrax Dopri8 (hand-written)",
            "QuaternionProjection(Dopri8)",
        )
    }
    assert dopri8 == {palette.METHOD_COLOURS["Dopri8"]}
    assert palette.colour("lagjax", method="Dopri8") == palette.colour("lagjax Dopri8")
    # The longest name wins: the rigid-body Yoshida is a method of its own.
    assert palette.method_of("RigidBodyYoshida4 (axes split)") == "RigidBodyYoshida4"
    assert palette.method_of("SymPy, numeric solve of M") == "SymPy"


def test_methods_have_distinct_colours_and_unknown_labels_a_stable_one():
    colours = list(palette.METHOD_COLOURS.values())
    assert len(set(colours)) == len(colours)
    assert palette.colour("a new method") == palette.colour("a new method")


def test_the_implementation_sets_the_line_style():
    assert palette.style("lagjax Tsit5")["linestyle"] == "-"
    assert palette.style("diffrax Tsit5 (hand-written)")["linestyle"] == "--"
    assert palette.style("scipy DOP853 (hand-written numpy)")["marker"] == "^"
    variant = palette.style("RigidBodyVerlet (no compensation)")
    assert variant["linestyle"] == "--" and variant["marker"] == "o"
