"""The `lagjax` command: listing, running, plotting, saving, and one-line errors."""

import subprocess
import sys

import numpy as np
import pytest

import lagjax as lj
from lagjax.cli import main

# Whole runs of the command (scenes integrated, plotted, saved): CI's second step,
# `bash tasks.sh integration`. The command's refusals of bad input are checked by
# test_failures_cli.py in the default run.
pytestmark = pytest.mark.integration


def test_scenes_lists_every_scene(capsys):
    assert main(["scenes"]) == 0
    out = capsys.readouterr().out
    for name in (
        "foucault-pendulum",
        "kepler-cartesian",
        "simple-pendulum",
        "double-pendulum",
    ):
        assert name in out


def test_run_reports_plots_and_saves(capsys, tmp_path):
    plot, data = tmp_path / "run.png", tmp_path / "run.npz"
    code = main(
        [
            "run",
            "kepler-cartesian",
            "--t1",
            "6.283185307179586",
            "--plot",
            str(plot),
            "--save",
            str(data),
        ]
    )
    out = capsys.readouterr().out
    assert code == 0
    assert "solver    Yoshida4" in out and "compile" in out and "energy" in out
    assert "check" in out
    assert plot.stat().st_size > 10_000
    saved = np.load(data)
    assert saved["ts"].shape == saved["q0"].shape[:1]
    energy = saved["energy"]
    assert np.max(np.abs(energy - energy[0])) < 1e-6 * abs(energy[0])


def test_run_with_solver_param_and_batch(capsys):
    args = ["run", "simple-pendulum", "--t1", "2", "--dt", "0.01"]
    code = main(
        [*args, "--solver", "GaussLegendre2", "--param", "length=2.0", "--batch", "4"]
    )
    out = capsys.readouterr().out
    assert code == 0
    assert "GaussLegendre" in out and "batch of 4" in out


def test_a_batch_of_a_constrained_scene_starts_on_its_constraints(capsys, tmp_path):
    """The perturbed copies (q and q̇ scaled) are moved back onto the string's
    length; they were refused as starts that violate the constraints."""
    saved = tmp_path / "run.npz"
    code = main(["run", "cartesian-pendulum", "--t1", "0.5", "--batch", "3",
                 "--save", str(saved)])  # fmt: skip
    assert code == 0, capsys.readouterr()
    q = np.load(saved)["q0"]  # the first copy, every saved state
    length = lj.scenes.CartesianPendulum().length
    assert np.max(np.abs(np.linalg.norm(q, axis=-1) - length)) < 1e-12


@pytest.mark.parametrize(
    "argv, message",
    [
        (["run", "no-such-scene"], "unknown scene"),
        (["run", "simple-pendulum", "--solver", "Euler9"], "unknown solver"),
        (["run", "simple-pendulum", "--dt", "-0.1"], "--dt must be positive"),
        (["run", "simple-pendulum", "--t1", "-1"], "--backward"),
        (["run", "simple-pendulum", "--param", "length"], "NAME=VALUE"),
        (["run", "simple-pendulum", "--param", "length=abc"], "not a number"),
        (["run", "simple-pendulum", "--param", "colour=3"], "unexpected keyword"),
        (["run", "simple-pendulum", "--t1", "soon"], "invalid float"),
        (["fly"], "invalid choice"),
    ],
)
def test_bad_arguments_exit_2_with_one_line(argv, message, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err
    assert len(err.strip().splitlines()) == 1
    assert "Traceback" not in err


def test_backward_run(capsys):
    code = main(
        ["run", "harmonic-oscillator", "--t1", "-1", "--backward", "--dt", "0.01"]
    )
    assert code == 0
    assert "check" in capsys.readouterr().out


def test_console_script_entry_point():
    done = subprocess.run(
        [sys.executable, "-m", "lagjax.cli", "run", "nope"],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 2
    assert (
        done.stderr.strip()
        == "lagjax: error: unknown scene 'nope'; `lagjax scenes` lists them"
    )


def test_failed_run_exits_1_with_the_reason(capsys):
    # Fixed-point stage iteration diverges at dt = 5 s on the double pendulum (a
    # run of two steps: a --dt longer than the run is refused before it starts).
    code = main(
        [
            "run",
            "double-pendulum",
            "--solver",
            "GaussLegendre2",
            "--t1",
            "10",
            "--dt",
            "5",
        ]
    )
    err = capsys.readouterr().err
    assert code == 1
    assert err.startswith("lagjax: error: run failed:")
    assert "Traceback" not in err
    assert len(err.strip().splitlines()) == 1
