"""Repeated `simulate(..., solver=lj.Taylor(backend="heyoka"))` calls
(`lagjax._integrate.taylor_heyoka_repeat`): a call of a known structure gives the
first-call path's trajectory, reads its new values (state, parameters, times),
and refuses bad values with the first-call path's own errors."""

from collections import OrderedDict

import diffrax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax._integrate import taylor_heyoka_repeat
from lagjax._integrate.taylor_run import run_taylor

pytest.importorskip("heyoka")

TOL = 1e-13


def double_pendulum(q, qd, t, args):
    """m = l = 1; `args["g"]` the gravity."""
    (a, b), (u, v) = (q[0], q[1]), (qd[0], qd[1])
    kinetic = u**2 + 0.5 * v**2 + u * v * jnp.cos(a - b)
    return kinetic + args["g"] * (2 * jnp.cos(a) + jnp.cos(b))


PENDULUM = lj.Lagrangian(double_pendulum)


def energy_of(state, g: float) -> float:
    """T + V of the double pendulum, in NumPy."""
    (a, b), (u, v) = (np.asarray(x, np.float64) for x in state)
    return u**2 + 0.5 * v**2 + u * v * np.cos(a - b) - g * (2 * np.cos(a) + np.cos(b))


def start(a: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    return np.array([a, 0.3]), np.zeros(2)


def repeated(y0, **kwargs):
    """`simulate` as a user calls it: a fresh `lj.Taylor` each time."""
    return lj.simulate(PENDULUM, y0, rtol=TOL, atol=TOL,
                       solver=lj.Taylor(backend="heyoka"), **kwargs)  # fmt: skip


def first_call_path(y0, t1, ts=None, args=None, max_steps=None, throw=True):
    """What `simulate` ran for every heyoka call before repeats were kept."""
    return run_taylor(PENDULUM, y0, 0.0, t1, None, lj.Taylor(backend="heyoka"), ts,
                      args, TOL, TOL, max_steps, throw)  # fmt: skip


@pytest.fixture
def first_calls(monkeypatch):
    """The calls that went the first-call way, from no kept repeat."""
    calls = []

    def counted(*args, **kwargs):
        calls.append(args)
        return run_taylor(*args, **kwargs)

    monkeypatch.setattr(taylor_heyoka_repeat, "run_taylor", counted)
    monkeypatch.setattr(taylor_heyoka_repeat, "_REPEATS", OrderedDict())
    return calls


def same_trajectory(a, b):
    assert a.stats["solver"] == b.stats["solver"] == "Taylor[heyoka]"
    assert a.result == b.result and a.system is b.system
    np.testing.assert_array_equal(a.ts, b.ts)
    for x, y in zip(a.ys, b.ys):
        assert type(x) is type(y)
        np.testing.assert_array_equal(x, y)
    assert a.stats.keys() == b.stats.keys()
    for key in a.stats:
        assert np.all(a.stats[key] == b.stats[key]), key


def test_a_repeat_reads_new_values_and_gives_the_first_call_path_trajectory(
    first_calls,
):
    ts = np.linspace(0.0, 2.0, 5)
    cases = [
        dict(t1=2.0, args={"g": 9.81}),  # the first call of each structure
        dict(t1=2.0, args={"g": 9.81}, ts=ts),
        dict(t1=2.0, args={"g": 4.0}),  # repeats: new values
        dict(t1=3.0, args={"g": 9.81}, y0=start(0.8)),
        dict(t1=2.0, args={"g": 4.0}, ts=ts),
        dict(t1=0.1, args={"g": 9.81}, y0=tuple(np.float32(x) for x in start())),
        dict(t1=0.3, args={"g": 9.81}, y0=tuple(np.float32(x) for x in start(0.2))),
    ]
    finals = []
    for case in cases:
        y0 = case.pop("y0", start())
        run = repeated(y0, **case)
        same_trajectory(run, first_call_path(y0, **case))
        finals.append(np.concatenate([run.q[-1], run.qdot[-1]]))
        # the physics: the conservative pendulum keeps its energy
        g = np.asarray(case["args"]["g"], y0[0].dtype)  # the run's parameter
        end = energy_of((run.q[-1], run.qdot[-1]), g)
        assert abs(end - energy_of(y0, g)) < 1e-11
    assert len(first_calls) == 3  # one per structure, the rest repeats
    assert not np.allclose(finals[0], finals[2])  # g read anew


@pytest.mark.parametrize(
    "bad",
    [
        dict(y0=(np.array([np.nan, 0.3]), np.zeros(2))),
        dict(args={"g": np.nan}),
        dict(t1=np.inf),
        dict(t1=0.0),
        dict(ts=np.array([0.5, 0.2])),
        dict(ts=np.array([0.5, 9.0])),
    ],
)
def test_bad_values_on_a_repeat_are_refused_as_on_a_first_call(bad, first_calls):
    good = dict(y0=start(), t1=1.0, args={"g": 9.81})
    with_ts = "ts" in bad
    repeated(good["y0"], t1=1.0, args=good["args"], ts=[0.5] if with_ts else None)
    assert len(first_calls) == 1 and len(taylor_heyoka_repeat._REPEATS) == 1
    call = {**good, **bad}
    y0 = call.pop("y0")
    with pytest.raises(ValueError) as first:
        first_call_path(y0, **call)
    with pytest.raises(ValueError) as repeat:
        repeated(y0, **call)
    assert str(repeat.value) == str(first.value)
    assert len(first_calls) == 2  # the repeat handed the bad call over


def test_a_failed_repeat_raises_the_first_call_path_error(first_calls):
    pendulum = dict(t1=50.0, args={"g": 9.81}, max_steps=5)
    kept = repeated(start(), throw=False, **pendulum)  # kept, though it failed
    assert kept.result == diffrax.RESULTS.max_steps_reached
    assert np.all(np.isnan(kept.q))  # not reached: NaN, as on a first call
    with pytest.raises(lj.SimulationError) as first:
        first_call_path(start(), **pendulum)
    with pytest.raises(lj.SimulationError) as repeat:
        repeated(start(), **pendulum)
    assert str(repeat.value) == str(first.value)
    assert len(first_calls) == 1  # the failed run was a repeat


def test_one_member_statistics_equal_the_general_ones():
    """One concrete member's `traj.stats` come from fewer NumPy calls (cold after
    a heyoka run): the general path's values and types, for a run that reached
    t1, ran out of steps, turned non-finite, or was refused its times."""
    from lagjax._integrate import taylor_heyoka
    from lagjax.taylor.heyoka_runs import (
        BAD_TIMES,
        NON_FINITE,
        STEP_LIMIT,
        SUCCESS,
        Rows,
    )

    state = np.array([[0.5, 0.3, 0.1, -0.2]])
    for code, ys in ((SUCCESS, state), (STEP_LIMIT, state * np.nan),
                     (NON_FINITE, state * np.inf), (BAD_TIMES, state * np.nan)):  # fmt: skip
        rows = Rows(np.array([2.0]), ys, np.asarray(17, np.int64),
                    np.asarray(code, np.int32))  # fmt: skip
        fast = taylor_heyoka.run_statistics(rows, None, 100)
        general = taylor_heyoka._statistics(rows, None, 100)
        assert list(fast) == list(general)
        for key, value in general.items():
            assert type(fast[key]) is type(value), key
            assert fast[key] == value, key


def pendulum(q, qd, t, args):
    """One coordinate: q and q̇ scalars."""
    return 0.5 * qd**2 + args["g"] * jnp.cos(q)


SIMPLE = lj.Lagrangian(pendulum)


@pytest.mark.parametrize(
    "system, make_y0",
    [
        (PENDULUM, lambda a: (np.array([a, 0.3]), np.zeros(2))),  # no flatten
        (PENDULUM, lambda a: [np.array([a, 0.3]), np.zeros(2)]),  # a list: flattened
        (PENDULUM, lambda a: (np.array([a, 0.3]), np.zeros(2, np.int64))),  # cast
        (PENDULUM, lambda a: (jnp.array([a, 0.3]), jnp.zeros(2))),  # JAX arrays
        (SIMPLE, lambda a: (a, 0.0)),  # Python floats: no flatten
    ],
)
def test_each_kind_of_y0_repeats_the_first_call_path_trajectory(
    system, make_y0, first_calls
):
    """y0 a plain tuple of NumPy arrays or floats takes the repeat's short way
    (its key without a pytree flatten, one `concatenate`); any other y0 the
    general one: the first-call path's trajectory either way, and one first
    call for the structure."""
    args, finals = {"g": 9.81}, []
    for a in (0.5, 0.8, 0.5):
        y0 = make_y0(a)
        run = lj.simulate(system, y0, t1=2.0, args=args, rtol=TOL, atol=TOL,
                          solver=lj.Taylor(backend="heyoka"))  # fmt: skip
        first = run_taylor(system, y0, 0.0, 2.0, None, lj.Taylor(backend="heyoka"),
                           None, args, TOL, TOL, None, True)  # fmt: skip
        same_trajectory(run, first)
        finals.append(np.asarray(run.q[-1]))
    assert len(first_calls) == 1  # the later calls were repeats
    assert not np.allclose(finals[0], finals[1])  # y0 read anew
    np.testing.assert_array_equal(finals[0], finals[2])


def test_a_system_s_own_pair_check_runs_on_a_repeat(first_calls):
    """The default `checked_state_pair` reads only structure and shapes, which
    the repeat's key fixes; a system's own may read values, and a repeat
    refuses what it refuses, with its error."""

    class Guarded(lj.Lagrangian):
        def checked_state_pair(self, first, second):
            if np.asarray(first)[0] > 1.0:
                raise ValueError("q0[0] above 1: refused by the system")
            return super().checked_state_pair(first, second)

    guarded = Guarded(double_pendulum)  # pyright: ignore[reportCallIssue]

    def run(a: float):
        return lj.simulate(guarded, start(a), t1=1.0, args={"g": 9.81}, rtol=TOL,
                           atol=TOL, solver=lj.Taylor(backend="heyoka"))  # fmt: skip

    run(0.5)
    run(0.9)
    assert len(first_calls) == 1
    with pytest.raises(ValueError, match="refused by the system"):
        run(1.5)
    assert len(first_calls) == 2  # the repeat handed the bad call over


def test_all_finite_equals_numpy():
    """The finiteness of a small state read from its Python floats is
    `np.isfinite(...).all()`, in value and type, for any dtype and size."""
    from lagjax._integrate.taylor_heyoka import all_finite

    for values in ([0.5, -2.0], [np.nan, 1.0], [1.0, -np.inf], [], [1e30, 1e-40]):
        for dtype in (np.float64, np.float32, np.longdouble):
            for shape in ((-1,), (1, -1)):
                ys = np.array(values, dtype).reshape(shape)
                expected = np.isfinite(ys).all()
                assert type(all_finite(ys)) is type(expected)
                assert all_finite(ys) == expected
    big = np.zeros(1000)
    assert all_finite(big) and not all_finite(np.append(big, np.nan))


def test_a_heyoka_trajectory_is_the_one_its_init_builds():
    """A heyoka run's `Trajectory` is built by `tree_unflatten`, without
    `__init__`: the same fields, values and tree structure as `Trajectory(...)`."""
    import diffrax as dfx
    import jax

    from lagjax._integrate.taylor_heyoka import SOLVER_NAME, _trajectory
    from lagjax.trajectory import Trajectory

    ts, ys = np.array([2.0]), (np.ones((1, 2)), np.zeros((1, 2)))
    stats = {"num_steps": np.asarray(7), "finite": np.True_}
    result = dfx.RESULTS.successful
    built = _trajectory(ts, ys, PENDULUM, {"g": 1.0}, stats, result)
    init = Trajectory(
        ts=ts,  # pyright: ignore[reportArgumentType]  (NumPy, as on the CPU route)
        ys=ys, system=PENDULUM, args={"g": 1.0}, run_stats=stats, result=result,
        solver_name=SOLVER_NAME,
    )  # fmt: skip
    assert type(built) is Trajectory
    assert vars(built).keys() == vars(init).keys()
    assert jax.tree_util.tree_structure(built) == jax.tree_util.tree_structure(init)
    for a, b in zip(jax.tree_util.tree_leaves(built), jax.tree_util.tree_leaves(init)):
        assert a is b
    assert built.stats == {"solver": SOLVER_NAME, **stats} and built.q is ys[0]
