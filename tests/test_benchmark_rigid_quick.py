"""`python -m benchmarks.rigid_long_horizon --quick`: it runs, and its numbers are physics.

The script runs once, as a subprocess, into a temporary folder; the tests then check
what it wrote: the Lie–Poisson splittings keep |L| to round-off while the projected
Runge–Kutta runs lose it in proportion to their tolerance, energy errors behave as
the methods' orders say, the hand-written twin integrates the same motion, and the
files (CSV, JSON, Markdown, a two-panel PNG) are there and not empty.
"""

import csv
import itertools
import json
import math
import subprocess
import sys
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest

from lagjax import diagnostics

# Fresh processes, whole scripts: CI's second step (`bash tasks.sh integration`).
pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parent.parent
NAMES = ("rigid_long_horizon.csv", "rigid_long_horizon.json")
NAMES += ("rigid_long_horizon.md", "rigid_long_horizon.png")


@pytest.fixture(scope="module")
def results(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("rigid_long_horizon")
    module = "benchmarks.rigid_long_horizon"
    run = subprocess.run(
        [sys.executable, "-m", module, "--quick", "--out", str(out)],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    assert run.returncode == 0, (
        f"the script failed:\n{(run.stdout + run.stderr)[-3000:]}"
    )
    return out


@pytest.fixture(scope="module")
def rows(results) -> list[dict]:
    with open(results / "rigid_long_horizon.csv") as handle:
        records = list(csv.DictReader(handle))
    assert records, "no points were written"
    numeric = ("value", "steps", "run_s", "compile_s", "momentum_error")
    numeric += ("space_momentum_error", "energy_error", "orthonormality", "final_error")
    return [{**r, **{key: float(r[key]) for key in numeric}} for r in records]


def _line(rows: list[dict], method: str) -> list[dict]:
    """The points of one method, from the coarsest setting to the finest."""
    line = sorted((r for r in rows if r["method"] == method), key=lambda r: -r["value"])
    assert line, f"no rows for {method}"
    return line


def test_files_are_written_and_the_figure_is_not_blank(results):
    for name in NAMES:
        assert (results / name).stat().st_size > 0, name
    png = results / "rigid_long_horizon.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    pixels = matplotlib.image.imread(png)[..., :3]
    # Axes, lines, labels: a good share of the pixels is not background white.
    assert np.mean(np.any(pixels < 0.9, axis=-1)) > 0.02
    report = json.loads((results / "rigid_long_horizon.json").read_text())
    assert report["meta"]["mode"] == "quick"
    assert {row["quantity"] for row in report["fastest"]} == {
        "momentum_error", "energy_error", "final_error",
    }  # fmt: skip
    summary = (results / "rigid_long_horizon.md").read_text()
    assert "Does the Lie–Poisson splitting beat Dopri8?" in summary


def test_lie_poisson_keeps_angular_momentum_to_round_off(rows):
    splitting = [r for r in rows if r["family"] == "Lie–Poisson"]
    assert splitting
    for row in splitting:
        # Each sub-step is an exact rotation: |Π| and R Π move only by round-off,
        # over 10⁴ steps (Kahan-compensated state update).
        assert row["momentum_error"] <= 4e-15, row
        assert row["space_momentum_error"] <= 1e-13, row
        assert row["orthonormality"] <= 1e-13, row  # q stays on the unit sphere
    # The projected Runge–Kutta runs, at every tolerance tried, are far off that.
    assert min(r["momentum_error"] for r in rows if r["family"] == "Dopri8") > 1e-13


def test_dopri8_angular_momentum_error_falls_with_the_tolerance(rows):
    line = _line(rows, "QuaternionProjection(Dopri8)")
    assert len(line) >= 3
    for loose, tight in itertools.pairwise(line):
        # rtol 1000× tighter: |L| drifts about 1000× less (at least 30× here).
        assert tight["momentum_error"] < loose["momentum_error"] / 30, (loose, tight)
        assert tight["final_error"] < loose["final_error"], (loose, tight)


def test_energy_errors_are_finite_and_follow_the_order(rows):
    for row in rows:
        assert math.isfinite(row["energy_error"]) and row["energy_error"] < 1, row
        assert row["run_s"] > 0 and row["compile_s"] >= 0 and row["steps"] > 0, row
    # Yoshida4's bounded energy error shrinks as h⁴ (observed order 3–5.5).
    line = _line(rows, "RigidBodyYoshida4")
    order = diagnostics.convergence_order(
        [r["value"] for r in line], [r["energy_error"] for r in line]
    )
    assert 3.0 < order < 5.5, order


def test_the_twin_integrates_the_same_motion(results):
    twin = json.loads((results / "rigid_long_horizon.json").read_text())["twin"]
    assert twin["steps"] == 10_000 and twin["twin_s"] > 0
    for key in ("plain", "compensated"):
        # Same method, different round-off, amplified near the separatrix; not a
        # different trajectory. (The speed ratio is reported, not asserted: timing
        # on a shared machine is no test.)
        assert twin[key]["final_difference"] < 1e-6, twin
        assert math.isfinite(twin[key]["ratio"]) and twin[key]["ratio"] > 0, twin
