"""Catalogue of bad and extreme uses of the `lagjax` command, run in-process.

The command never prints a traceback: bad arguments exit 2, a failed run 1, an
interrupted run 130, each with one line `lagjax: error: …` (or the interrupt line)
naming the problem. Output paths are checked before anything is compiled, and an
interrupted run still saves the states it computed.
"""

import math
import re

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.cli import command as cli
from lagjax.cli import main
from lagjax.cli import run as cli_run
from lagjax.cli.plot import _check_series
from tests.helpers import one_error_line

PENDULUM = ["run", "simple-pendulum"]
BAD_ARGUMENTS = [
    (["run", "no-such-scene"], "unknown scene 'no-such-scene'"),
    ([*PENDULUM, "--solver", "Euler9"], "unknown solver 'Euler9'; choose from"),
    ([*PENDULUM, "--dt", "-0.1"], "--dt must be positive"),
    ([*PENDULUM, "--dt", "0"], "--dt must be positive, got 0.0"),
    ([*PENDULUM, "--dt", "nan"], "--dt must be a finite number, got nan"),
    ([*PENDULUM, "--dt", "inf"], "--dt must be a finite number, got inf"),
    ([*PENDULUM, "--dt", "1e-300"], "means 5e+300 steps"),
    ([*PENDULUM, "--t1", "1e12", "--dt", "1e-3"], "means 1e+15 steps"),
    ([*PENDULUM, "--t1", "nan"], "--t1 must be a finite number, got nan"),
    ([*PENDULUM, "--t1", "inf"], "--t1 must be a finite number, got inf"),
    ([*PENDULUM, "--t1", "0"], "--t1 must be non-zero"),
    ([*PENDULUM, "--t1", "-1"], "pass --backward"),
    ([*PENDULUM, "--t1", "soon"], "invalid float value: 'soon'"),
    ([*PENDULUM, "--param", "length"], "--param expects NAME=VALUE"),
    ([*PENDULUM, "--param", "=2"], "--param expects NAME=VALUE"),
    ([*PENDULUM, "--param", "length=abc"], "--param length: 'abc' is not a number"),
    ([*PENDULUM, "--param", "colour=3"], "no parameter 'colour' (unexpected keyword)"),
    ([*PENDULUM, "--param", "mass=-1"], "--param mass=-1: SimplePendulum: mass"),
    ([*PENDULUM, "--param", "length=-1"], "length = -1.0 must be > 0"),
    ([*PENDULUM, "--param", "length=0"], "length = 0.0 must be > 0"),
    ([*PENDULUM, "--param", "mass=nan"], "--param mass=nan: parameters must be finite"),
    ([*PENDULUM, "--param", "gravity=inf"], "parameters must be finite"),
    ([*PENDULUM, "--param", "amplitude=1,2"], "needs one number, got 2 comma"),
    (["run", "torque-free-body", "--param", "moments=1"], "needs 3 comma-separated"),
    (["run", "torque-free-body", "--param", "moments=1,2"], "e.g. moments=1,2,3"),
    (["run", "torque-free-body", "--param", "moments=1,0,2"], "moments"),
    (["run", "kepler-cartesian", "--param", "eccentricity=1.5"], "eccentricity"),
    ([*PENDULUM, "--batch", "0"], "--batch must be at least 1, got 0"),
    ([*PENDULUM, "--batch", "-3"], "--batch must be at least 1"),
    ([*PENDULUM, "--batch", "two"], "invalid int value: 'two'"),
    ([*PENDULUM, "--save", "/nonexistent-folder/out.npz"], "does not exist"),
    ([*PENDULUM, "--plot", "/bad/path.png"], "the folder /bad does not exist"),
    ([*PENDULUM, "--plot", "run.xyz"], "unknown image format 'xyz'"),
    ([*PENDULUM, "--plot", ""], "is a directory; give a file name"),
    (["fly"], "invalid choice: 'fly'"),
    ([], "the following arguments are required"),
    (["run"], "the following arguments are required: scene"),
    ([*PENDULUM, "--frobnicate"], "unrecognized arguments: --frobnicate"),
]


@pytest.mark.parametrize("argv, message", BAD_ARGUMENTS)
def test_bad_arguments_exit_2_before_compiling(argv, message, capsys):
    assert main(argv) == 2
    line = one_error_line(capsys)
    assert line.startswith("lagjax: error: ")
    assert message in line


@pytest.mark.parametrize("flag", ["--save", "--plot"])
def test_an_output_path_that_is_a_directory_is_refused(flag, tmp_path, capsys):
    assert main([*PENDULUM, flag, str(tmp_path)]) == 2
    assert "is a directory; give a file name" in one_error_line(capsys)


@pytest.mark.parametrize(
    "scene, solver, message",
    [
        ("harmonic-oscillator", "RigidBodyVerlet", "Lie–Poisson solver"),
        ("harmonic-oscillator", "RigidBodyYoshida4", "is not one"),
        ("simple-pendulum", "Rattle", "has no constraints"),
        ("harmonic-oscillator", "VariationalMidpoint", "discretizes a Lagrangian"),
        ("double-pendulum", "StormerVerlet", "splitting method"),
    ],
)
def test_a_solver_that_cannot_integrate_the_scene(scene, solver, message, capsys):
    assert main(["run", scene, "--solver", solver, "--t1", "0.1"]) == 2
    assert message in one_error_line(capsys)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_failed_stage_solve_names_newton(capsys):
    argv = ["run", "double-pendulum", "--solver", "GaussLegendre2", "--dt", "5"]
    assert main([*argv, "--t1", "10"]) == 1
    line = one_error_line(capsys)
    assert line.startswith("lagjax: error: run failed: ")
    assert "root_finder=optimistix.Newton" in line


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_save_writes_exactly_the_named_file(tmp_path, capsys):
    target = tmp_path / "run-without-suffix"
    assert main(["run", "harmonic-oscillator", "--t1", "1", "--save", str(target)]) == 0
    assert f"data      {target}" in capsys.readouterr().out
    assert not (tmp_path / "run-without-suffix.npz").exists()
    saved = np.load(target)
    assert saved["ts"][-1] == 1.0


def interrupt_after(monkeypatch, chunks: int):
    """Make the run raise KeyboardInterrupt (Ctrl-C) when chunk `chunks` + 1 starts."""
    real, calls = cli_run._advance, []

    def advance(compiled, state, times):
        if len(calls) == chunks:
            raise KeyboardInterrupt
        calls.append(times)
        return real(compiled, state, times)

    monkeypatch.setattr(cli_run, "_advance", advance)
    monkeypatch.setattr(cli_run, "CHUNK_STEPS", 100)  # 1000 steps: 10 chunks


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_ctrl_c_saves_what_was_computed(monkeypatch, tmp_path, capsys):
    interrupt_after(monkeypatch, chunks=3)
    target = tmp_path / "partial.npz"
    argv = ["run", "harmonic-oscillator", "--t1", "10", "--dt", "0.01"]
    assert main([*argv, "--save", str(target)]) == 130
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert err.startswith("lagjax: interrupted at t = 3 of 10")
    saved = np.load(target)
    assert saved["ts"][0] == 0.0 and math.isclose(saved["ts"][-1], 3.0)
    assert np.all(np.diff(saved["ts"]) > 0)  # chunk joints kept once
    energy = saved["energy"]  # the chunks continue one run: energy conserved
    assert np.max(np.abs(energy - energy[0])) < 1e-6 * abs(energy[0])


def test_ctrl_c_before_any_chunk(monkeypatch, capsys):
    interrupt_after(monkeypatch, chunks=0)
    monkeypatch.setattr(cli_run, "_compile", lambda *_: None)  # not needed here
    assert main(["run", "harmonic-oscillator", "--t1", "1"]) == 130
    assert "interrupted before any state was computed" in one_error_line(capsys)


def test_ctrl_c_while_compiling(monkeypatch, capsys):
    def compile_forever(*_):
        raise KeyboardInterrupt

    monkeypatch.setattr(cli_run, "_compile", compile_forever)
    assert main(["run", "harmonic-oscillator"]) == 130
    assert "nothing saved" in one_error_line(capsys)


def test_any_unexpected_error_is_one_line(monkeypatch, capsys):
    def broken(*_):
        raise RuntimeError("a bug\nwith a second line")

    monkeypatch.setattr(cli, "run_scene", broken)
    assert main(["run", "harmonic-oscillator"]) == 1
    assert one_error_line(capsys) == "lagjax: error: run failed: RuntimeError: a bug"


def test_bench_from_an_installed_wheel_says_it_needs_a_clone(monkeypatch, capsys):
    monkeypatch.setattr(cli, "__file__", "/site-packages/lagjax/cli/command.py")
    assert main(["bench", "--quick"]) == 2
    line = one_error_line(capsys)
    assert "clone the repository" in line and "python -m benchmarks" in line


def test_help_exits_0(capsys):
    assert main(["--help"]) == 0
    assert "Classical mechanics in JAX" in capsys.readouterr().out


def test_scene_listing_is_aligned_plain_text(capsys):
    assert main(["scenes"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == len(lj.scenes.catalog())
    columns = {re.match(r"\S+\s+", line).end() for line in lines}  # type: ignore[union-attr]
    assert len(columns) == 1, columns
    assert not any("$" in line or "\\" in line for line in lines)


class Saved(eqx.Module):
    """The two fields of a trajectory that the plot's check panel slices."""

    ts: jax.Array
    ys: tuple


class EndTimeScene:
    """A stand-in scene: its check reads the last saved time two ways."""

    def checks(self, window):
        return {
            "end time": (window.ts[-1], window.ys[0][-1] / 2),
            "a vector": (window.ts, window.ts),
        }


def test_plot_diagnostic_measures_each_check_on_equal_parts():
    ts = jnp.linspace(0.0, 12.0, 121)
    series = _check_series(EndTimeScene(), Saved(ts, (2 * ts, ts)))
    assert set(series) == {"end time"}  # vector checks have no curve to draw
    times, measured, expected = series["end time"]
    assert np.allclose(times, [1.9, 3.9, 5.9, 7.9, 9.9, 11.9])
    assert np.allclose(measured, times) and np.allclose(expected, times)
