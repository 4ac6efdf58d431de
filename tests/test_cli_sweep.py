"""`lagjax sweep`: a scene over a grid of parameters and starts, streamed to a
directory; the members obey the closed form, the grid is recorded in the order the
members run, a rerun resumes, and bad inputs are refused in one line (exit 2)
before anything is compiled or written."""

import json
import math
import shutil

import jax
import numpy as np
import pytest

import lagjax as lj
from lagjax.cli import main

# One compiled program serves every sweep below: same scene, times and chunks.
T1, DT, CHUNK = 0.5, 0.01, 4
RUN = ["--t1", str(T1), "--dt", str(DT), "--chunk-size", str(CHUNK)]
STIFFNESS = np.linspace(1.0, 4.0, 3)
Q0 = np.array([0.2, -0.5])


def _oscillator_sweep(out, *extra):
    return main(
        ["sweep", "harmonic-oscillator", "--out", str(out), "--param",
         "stiffness=1:4:3", "--q0", "0.2,-0.5", "--p0", "0.3", "--saves", "3",
         *RUN, *extra]
    )  # fmt: skip


def _closed_form(k, q0, p0, t, m=1.0):
    """q(t), p(t) of the oscillator H = p²/2m + kq²/2 from (q0, p0)."""
    omega = math.sqrt(k / m)
    q = q0 * np.cos(omega * t) + p0 / (m * omega) * np.sin(omega * t)
    p = -m * omega * q0 * np.sin(omega * t) + p0 * np.cos(omega * t)
    return q, p


def _chunk_files(out):
    return {p: p.stat().st_mtime_ns for p in sorted(out.glob("chunk_*/*.npy"))}


# One compilation (~10 s on the loaded 2-core machine): CI's second step.
@pytest.mark.integration
def test_a_grid_sweep_obeys_the_closed_form_and_resumes(tmp_path, capsys):
    out = tmp_path / "sweep"
    assert _oscillator_sweep(out) == 0
    printed = capsys.readouterr()
    assert "members   6 = --param stiffness (3) × --q0 q (2)" in printed.out
    assert "0 members resumed, 6 run now" in printed.out
    assert "failed    0 members" in printed.out
    assert "sweep: 6/6 members" in printed.err  # progress on stderr, per chunk
    assert "members/s" in printed.err and "s left" in printed.err

    store = lj.open_sweep(out)
    grid = store.index["attributes"]["lagjax sweep"]
    assert grid["shape"] == [3, 2] and grid["layout"] == "grid"
    assert [a["target"] for a in grid["axes"]] == ["stiffness", "q"]
    np.testing.assert_allclose(grid["axes"][0]["values"], STIFFNESS)
    q, p, ts = store.array("q"), store.array("p"), store.array("ts")
    assert q.shape == (6, 3) and np.allclose(ts, [0.0, T1 / 2, T1])
    for member in range(6):  # member k sits at unravel_index(k, shape)
        i, j = np.unravel_index(member, grid["shape"])
        exact_q, exact_p = _closed_form(STIFFNESS[i], Q0[j], 0.3, ts[member])
        np.testing.assert_allclose(q[member], exact_q, atol=1e-8)
        np.testing.assert_allclose(p[member], exact_p, atol=1e-8)

    # The same command again: everything is on disk, nothing is redone.
    written = _chunk_files(out)
    assert _oscillator_sweep(out) == 0
    assert "6 members resumed, 0 run now" in capsys.readouterr().out
    assert _chunk_files(out) == written

    # A crash after the first chunk: the rerun redoes the one chunk that was lost.
    shutil.rmtree(out / "chunk_000001")
    index = json.loads((out / "index.json").read_text())
    index["chunks"] = index["chunks"][:1]
    (out / "index.json").write_text(json.dumps(index))
    assert _oscillator_sweep(out, "--quiet") == 0
    printed = capsys.readouterr()
    assert "4 members resumed, 2 run now" in printed.out and printed.err == ""
    np.testing.assert_array_equal(lj.open_sweep(out).array("q"), q)

    # --zip pairs the axes instead: member k has the k-th value of each.
    zipped = tmp_path / "zipped"
    argv = ["sweep", "harmonic-oscillator", "--out", str(zipped), "--zip",
            "--param", "stiffness=1,4", "--q0", "0.2,-0.5", "--p0", "0",
            "--saves", "3", "--quiet", *RUN]  # fmt: skip
    assert main(argv) == 0
    final = lj.open_sweep(zipped).array("q")[:, -1]
    expected = [_closed_form(k, q0, 0.0, T1)[0] for k, q0 in [(1, 0.2), (4, -0.5)]]
    np.testing.assert_allclose(final, expected, atol=1e-8)


BAD = [
    (["no-such-scene"], "unknown scene 'no-such-scene'"),
    (["simple-pendulum", "--param", "size=3"], "has no parameter 'size'"),
    (["simple-pendulum", "--param", "length=-1:2:4"], "length=-1: SimplePendulum"),
    (["simple-pendulum", "--param", "length"], "expects NAME=VALUES"),
    (["simple-pendulum", "--param", "length=1:2"], "START:STOP:COUNT"),
    (["simple-pendulum", "--param", "length=1:2:1"], "COUNT of at least 2"),
    (["simple-pendulum", "--param", "length=1:2:2.5"], "whole COUNT"),
    (["simple-pendulum", "--param", "length=-1:2:3:log"], "above 0"),
    (["simple-pendulum", "--param", "length=1,nan"], "finite"),
    (["simple-pendulum", "--qdot0", "1"], "starts from (q, p)"),
    (["spring-chain", "--param", "size=3,4"], "cannot vary across a sweep"),
    (["double-pendulum", "--q0", "1:2:3"], "name one: --q0 θ₁=1:2:3"),
    (["double-pendulum", "--q0", "θ₃=1"], "no such coordinate"),
    (["double-pendulum", "--param", "lengths=1:2:3"], "sweep one entry"),
    (["double-pendulum", "--param", "lengths[2]=1"], "i from 0 to 1"),
    (["double-pendulum", "--param", "gravity[0]=1"], "without [i]"),
    (["double-pendulum", "--q0", "0=1", "--q0", "θ₁=2"], "given twice"),
    (["double-pendulum", "--zip", "--q0", "0=1:2:3", "--param", "gravity=1:2:4"],
     "of one length"),
    (["damped-driven-oscillator", "--param", "damping=0.1:100:3"], "underdamped"),
    (["double-pendulum", "--chunk-size", "0"], "--chunk-size must be at least 1"),
    (["double-pendulum", "--t1", "-1"], "--t1 must be a positive"),
    (["double-pendulum", "--dt", "nan"], "--dt must be a positive"),
    (["double-pendulum", "--saves", "1"], "--saves must be at least 2"),
    (["double-pendulum", "--solver", "Euler9"], "unknown solver"),
    (["double-pendulum", "--processes", "2"], "go together"),
    (["double-pendulum", "--measure", "fli"], "unknown measure 'fli'"),
    (["double-pendulum", "--measure", "megno", "--saves", "3"],
     "--saves keeps states"),
]  # fmt: skip


@pytest.mark.parametrize(("argv", "message"), BAD)
def test_bad_inputs_exit_2_with_one_line_and_write_nothing(
    argv, message, tmp_path, capsys
):
    out = tmp_path / "out"
    assert main(["sweep", *argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("lagjax: error: "), err
    assert message in err[0]
    assert not out.exists()


def test_bad_output_directories_are_refused_before_any_work(tmp_path, capsys):
    a_file = tmp_path / "a_file"
    a_file.write_text("data")
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    for out, message in (
        (a_file, "is a file, not a directory"),
        (a_file / "below", "is not writable"),
        (foreign, "holds files but no sweep index"),
    ):
        argv = ["sweep", "harmonic-oscillator", "--out", str(out), "--q0", "1,2"]
        assert main([*argv, *RUN]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("lagjax: error: --out") and message in err, err
    assert sorted(p.name for p in foreign.iterdir()) == ["notes.txt"]


def test_distributed_runtime_that_does_not_start_is_refused(monkeypatch, capsys):
    def no_cluster(*args, **kwargs):
        raise ValueError("coordinator_address should be defined.")

    monkeypatch.setattr(jax.distributed, "initialize", no_cluster)
    assert main(["sweep", "harmonic-oscillator", "--out", "x", "--distributed"]) == 2
    err = capsys.readouterr().err
    assert "distributed runtime did not start" in err and "--coordinator" in err


# A second compilation (Kepler): CI's second step.
@pytest.mark.integration
def test_failing_members_are_marked_and_counted(tmp_path, capsys):
    out = tmp_path / "kepler"
    # x = 0 at y = 0 puts the body on the centre of force: r = 0, no finite state.
    argv = ["sweep", "kepler-cartesian", "--out", str(out), "--q0", "x=0,0.5,1",
            "--t1", "0.1", "--dt", "0.001", "--quiet"]  # fmt: skip
    assert main(argv) == 0
    printed = capsys.readouterr().out
    assert "failed    1 members (first: member 0" in printed
    store = lj.open_sweep(out)
    assert store.failed().tolist() == [True, False, False]
    assert np.all(np.isfinite(store.array("q")[1:]))


# A MEGNO compilation: CI's second step.
@pytest.mark.integration
def test_a_megno_map_of_pendulum_librations(tmp_path, capsys):
    out = tmp_path / "megno"
    argv = ["sweep", "simple-pendulum", "--out", str(out), "--measure", "megno",
            "--q0", "0.5,1,2", "--t1", "200", "--dt", "0.05", "--quiet"]  # fmt: skip
    assert main(argv) == 0
    assert "measure lagjax.phase_space.indicators.megno in field value" in (
        capsys.readouterr().out
    )
    store = lj.open_sweep(out)
    assert sorted(store.fields) == ["finite", "value"] and not store.failed().any()
    megno = store.array("value")
    # Librations are quasi-periodic: ⟨Y⟩ → 2 from below as 2 − O(ln t / t). The
    # smallest is nearly isochronous (little shear), so the furthest from 2.
    assert np.all((megno > 1.2) & (megno < 2.05))
    assert np.argmax(np.abs(megno - 2)) == 0
