"""Sweeps of a per-member measure (`measure=lj.megno`): the swept MEGNO map equals
the per-member calls, tells quasi-periodic Hénon–Heiles orbits (⟨Y⟩ → 2) from a
chaotic one (⟨Y⟩ ≈ λt/2, growing), streams to disk and resumes; a failing member
is marked, and bad measures are refused by name before any work."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.phase_space import henon_heiles, henon_heiles_section_states
from tests.sweep_worker import CHUNK, MEMBERS, problem

# Three quasi-periodic orbits at E = 1/12 and the chaotic one of
# tests/test_phase_space_indicators.py at E = 1/6; four members in chunks of 3,
# so the second chunk is padded.
MEGNO = dict(dt=0.05, solver=lj.Yoshida4(), renormalize_every=0.5)
SHORT, LONG = 250.0, 1000.0


def _henon_heiles_starts():
    regular = henon_heiles_section_states(1 / 12, [0.1, -0.1, 0.2], [0.0])
    chaotic = henon_heiles_section_states(1 / 6, [-0.1], [0.0])
    return jax.tree_util.tree_map(
        lambda a, b: jnp.concatenate([a, b]), regular, chaotic
    )


def _megno_sweep(t1):
    starts = _henon_heiles_starts()
    return lj.sweep(henon_heiles(), starts, measure=lj.megno, chunk_size=3, t1=t1,
                    **MEGNO)  # fmt: skip


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_a_megno_sweep_equals_the_per_member_calls_and_finds_the_chaotic_orbit():
    starts = _henon_heiles_starts()
    swept = _megno_sweep(LONG)
    singles = [lj.megno(henon_heiles(), (q, p), LONG, **MEGNO) for q, p in zip(*starts)]
    # The sweep's program is compiled for a batch of 3, the single call's for one
    # orbit, and XLA may round them differently. On the quasi-periodic orbits that
    # stays round-off (1e-13 measured on ⟨Y⟩ ≈ 2); on the chaotic one it grows as
    # e^{λt} until the two runs follow different orbits of the same chaotic sea,
    # whose finite-time ⟨Y⟩ agree as statistics only (1.3 % apart measured under
    # pytest, bit-identical in a plain script).
    np.testing.assert_allclose(swept[:3], singles[:3], rtol=1e-11)
    np.testing.assert_allclose(swept[3], singles[3], rtol=0.1)

    early = _megno_sweep(SHORT)
    regular, chaotic = swept[:3], swept[3]
    # Quasi-periodic: ⟨Y⟩ = 2 − O(ln t / t), from below, closer at the later time.
    assert np.all((regular > 1.5) & (regular < 2.05))
    assert np.all(np.abs(regular - 2) < np.abs(early[:3] - 2))
    # Chaotic: ⟨Y⟩ ≈ λt/2, four times the horizon is about four times ⟨Y⟩.
    assert chaotic > 20 and chaotic > 3 * early[3]


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_a_megno_sweep_streams_to_disk_and_resumes(tmp_path):
    starts = _henon_heiles_starts()
    run = dict(out_dir=tmp_path, measure=lj.megno, chunk_size=3, t1=SHORT, **MEGNO)

    def crash_after_one(report):
        raise KeyboardInterrupt("killed after one chunk")

    with pytest.raises(KeyboardInterrupt):
        lj.sweep_to_disk(henon_heiles(), starts, progress=crash_after_one, **run)
    ran = []
    store = lj.sweep_to_disk(henon_heiles(), starts, progress=ran.append, **run)
    assert [r.chunk for r in ran] == [1] and store.complete
    assert sorted(store.fields) == ["finite", "value"]
    assert store.index["parameters"]["measure"] == "lagjax.phase_space.indicators.megno"
    # The same compiled program as in memory: bit for bit.
    np.testing.assert_array_equal(store.array("value"), _megno_sweep(SHORT))
    assert not store.failed().any()


def _energy(system, y0, args=None):
    """A cheap measure: H at the start (the pendulum family of tests/sweep_worker)."""
    q, p = y0
    return {"energy": system(q, p, 0.0, args), "q0": q}


def test_a_member_whose_measure_is_not_finite_is_marked(tmp_path):
    system, y0s, omegas = problem()
    broken = omegas.at[4].set(jnp.nan)
    store = lj.sweep_to_disk(
        system, y0s, broken, out_dir=tmp_path, measure=_energy, chunk_size=CHUNK
    )
    assert sorted(store.fields) == ["energy", "finite", "q0"]
    assert store.failed().tolist() == [i == 4 for i in range(MEMBERS)]
    assert sum(c["failed"] for c in store.index["chunks"]) == 1
    q, p = (np.asarray(x) for x in y0s)
    pendulum = 0.5 * p**2 + np.asarray(omegas) ** 2 * (1 - np.cos(q))
    fine = ~store.failed()
    np.testing.assert_allclose(store.array("energy")[fine], pendulum[fine], rtol=1e-14)
    in_memory = lj.sweep(system, y0s, broken, measure=_energy, chunk_size=CHUNK)
    np.testing.assert_array_equal(store.array("energy"), in_memory["energy"])
    # Another measure of the same members is another sweep.
    with pytest.raises(ValueError, match="holds another sweep's chunks"):
        lj.sweep_to_disk(system, y0s, broken, out_dir=tmp_path, chunk_size=CHUNK,
                         measure=lambda s, y0, args: _energy(s, y0, args)["q0"])  # fmt: skip


def test_bad_measures_are_refused_by_name_before_any_work(tmp_path):
    system, y0s, omegas = problem()
    out = tmp_path / "out"
    with pytest.raises(TypeError, match="measure must be a function"):
        lj.sweep(system, y0s, omegas, measure="megno", t1=1.0)
    with pytest.raises(TypeError, match="measure must be a function"):
        lj.sweep_to_disk(system, y0s, omegas, out_dir=out, measure=None)
    # lj.megno needs t1, and takes no throw: found by tracing one member.
    with pytest.raises(TypeError, match=r"members cannot run .*t1"):
        lj.sweep(system, y0s, omegas, measure=lj.megno, dt=0.01)
    with pytest.raises(TypeError, match=r"members cannot run .*throw"):
        lj.sweep_to_disk(system, y0s, omegas, out_dir=out, measure=lj.megno,
                         t1=1.0, dt=0.01, throw=False)  # fmt: skip

    def clashing(system, y0, args=None):
        return {"finite": y0[0], "q": y0[1]}

    with pytest.raises(ValueError, match=r"\['finite'\] .*rename"):
        lj.sweep_to_disk(system, y0s, omegas, out_dir=out, measure=clashing)
    assert not out.exists()
