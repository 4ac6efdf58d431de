"""The heyoka backend: the jaxpr translation, runs against lagjax's own, the batch
mode, the compilation cache, and what it refuses (by name)."""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj

hy = pytest.importorskip("heyoka")

from lagjax.taylor.heyoka_backend import (  # noqa: E402
    UnsupportedPrimitiveError,
    heyoka_cache_info,
    heyoka_integrate,
    heyoka_integrate_batch,
    heyoka_tolerance,
    jaxpr_to_heyoka,
)


def double_pendulum(q, qd, t, args):
    """m = l = 1; `args["g"]` the gravity."""
    (a, b), (u, v) = (q[0], q[1]), (qd[0], qd[1])
    kinetic = u**2 + 0.5 * v**2 + u * v * jnp.cos(a - b)
    return kinetic + args["g"] * (2 * jnp.cos(a) + jnp.cos(b))


LAGRANGIAN = lj.Lagrangian(double_pendulum)
ARGS = {"g": jnp.asarray(9.81)}
Y0 = np.array([0.5, 0.3, 0.0, 0.0])


def vector_field(t, y, args):
    q, qd = y[:2], y[2:]
    return jnp.concatenate([qd, LAGRANGIAN.acceleration(q, qd, t, args)])


def test_translation_matches_the_jax_vector_field():
    system = jaxpr_to_heyoka(vector_field, 4, ARGS)
    variables = [y for y, _ in system.equations]
    rhs = hy.cfunc([f for _, f in system.equations], variables)
    states = np.random.default_rng(0).normal(size=(20, 4))
    jax_field = jax.jit(jax.vmap(vector_field, (None, 0, None)))  # one compilation
    for g in (9.81, 1.5):
        jax_values = jax_field(0.0, states, {"g": g})
        heyoka_values = rhs(np.ascontiguousarray(states.T), pars=np.full((1, 20), g)).T
        np.testing.assert_allclose(heyoka_values, jax_values, rtol=1e-13, atol=1e-13)
    assert system.num_pars == 1 and system.poisoned == ()


@pytest.mark.integration  # compiles diffrax's Dopri8 for the reference
def test_one_trajectory_agrees_with_dopri8():
    ts = np.linspace(0.0, 5.0, 6)
    run = heyoka_integrate(vector_field, Y0, 0.0, 5.0, ts=ts, args=ARGS, tol=1e-15)
    reference = lj.simulate(
        LAGRANGIAN, (jnp.asarray(Y0[:2]), jnp.asarray(Y0[2:])), t1=5.0, ts=ts,
        args=ARGS, solver=diffrax.Dopri8(), rtol=1e-13, atol=1e-13, max_steps=10**5,
    )  # fmt: skip
    assert run.status == "time_limit" and run.num_steps > 0
    np.testing.assert_allclose(run.ys[:, :2], reference.q, atol=1e-10)
    np.testing.assert_allclose(run.ys[:, 2:], reference.qdot, atol=1e-10)


def test_batch_equals_single_runs():
    y0s = np.stack([[a, 0.3, 0.0, 0.0] for a in np.linspace(0.1, 1.0, 6)])
    gs = np.linspace(9.0, 10.0, 6)
    batch = heyoka_integrate_batch(
        vector_field, y0s, 0.0, 1.0, args_batch={"g": gs}, tol=1e-15
    )
    for i in range(6):
        single = heyoka_integrate(vector_field, y0s[i], 0.0, 1.0, args={"g": gs[i]},
                                  tol=1e-15)  # fmt: skip
        # SIMD and scalar code round the elementary functions differently.
        np.testing.assert_allclose(batch.ys[i], single.ys, rtol=0, atol=1e-14)
        assert abs(batch.num_steps[i] - single.num_steps) <= 1
    assert list(batch.status) == ["time_limit"] * 6


def test_final_states_equal_the_dense_output_path():
    """A run saving only t1 goes straight there (one propagate_until per block);
    saving at ts = [t1] goes through heyoka's dense-output grid: same states, same
    steps, for every member of a padded batch and for one."""
    y0s = np.stack([[a, 0.3, 0.0, 0.0] for a in np.linspace(0.1, 1.0, 6)])
    for starts in (y0s, y0s[:1]):
        direct = heyoka_integrate_batch(vector_field, starts, 0.0, 1.0, args=ARGS,
                                        tol=1e-15)  # fmt: skip
        grid = heyoka_integrate_batch(vector_field, starts, 0.0, 1.0, ts=[1.0],
                                      args=ARGS, tol=1e-15)  # fmt: skip
        np.testing.assert_array_equal(direct.ys, grid.ys)
        np.testing.assert_array_equal(direct.num_steps, grid.num_steps)
        assert list(direct.status) == list(grid.status) == ["time_limit"] * len(starts)


def test_new_args_do_not_recompile():
    heyoka_integrate(vector_field, Y0, 0.0, 1.0, args=ARGS, tol=1e-14)
    before = heyoka_cache_info()
    runs = [heyoka_integrate(vector_field, Y0, 0.0, 1.0, args={"g": jnp.asarray(g)},
                             tol=1e-14) for g in (1.0, 4.0)]  # fmt: skip
    assert heyoka_cache_info() == before
    assert not np.allclose(runs[0].ys, runs[1].ys)


def test_unsupported_primitive_is_refused_by_name():
    def rounded(t, y, args):
        return jnp.round(y)

    with pytest.raises(UnsupportedPrimitiveError, match="`round`"):
        jaxpr_to_heyoka(rounded, 2)


def test_state_dependent_loop_is_refused_by_name():
    def newton(t, y, args):
        return jax.lax.while_loop(lambda x: x[0] > 1.0, lambda x: x / 2, y)

    with pytest.raises(UnsupportedPrimitiveError, match="`while`"):
        jaxpr_to_heyoka(newton, 2)


def test_traced_inputs_are_refused_by_name():
    def final(y0):
        return heyoka_integrate(vector_field, y0, 0.0, 1.0, args=ARGS).ys

    with pytest.raises(TypeError, match=r"traced `y0`.*lj\.Taylor"):
        jax.jit(final)(jnp.asarray(Y0))
    with pytest.raises(TypeError, match="traced `args`"):
        jax.grad(lambda g: heyoka_integrate(vector_field, Y0, 0.0, 1.0,
                                            args={"g": g}).ys.sum())(9.81)  # fmt: skip


def test_bad_tolerances_and_step_limit():
    for bad in (0.0, -1e-9, float("nan")):
        with pytest.raises(ValueError, match="rtol"):
            heyoka_tolerance(bad, 1e-9)
    with pytest.raises(RuntimeError, match="max_steps = 5"):
        heyoka_integrate(vector_field, Y0, 0.0, 100.0, args=ARGS, max_steps=5)
    partial = heyoka_integrate(vector_field, Y0, 0.0, 100.0, ts=[50.0, 100.0],
                               args=ARGS, max_steps=5, throw=False)  # fmt: skip
    assert partial.status == "step_limit" and np.isnan(partial.ys).all()


def test_unstack_is_translated_on_every_axis():
    """JAX ≥ 0.11 lowers `a, b = q` to the primitive `unstack`; here it is bound
    directly (JAX 0.10 lowers unpacking to slices), on the state, on a 2-d view of
    it, on the parameters and on numbers."""
    from jax._src.lax.lax import unstack  # the primitive itself, on any JAX

    def coupled(t, y, args):
        q1, q2, v1, v2 = unstack(y, 0)
        (a, u), (b, w) = unstack(y.reshape(2, 2), 1)  # columns (q1, v1), (q2, v2)
        k1, k2 = unstack(args["k"], 0)
        c1, c2 = unstack(jnp.array([1.0, 0.5]), 0)
        return jnp.stack([u, w, -k1 * jnp.sin(q1) + c1 * (q2 - a) * v2,
                          -k2 * jnp.sin(b) - c2 * (q2 - q1) + v1])  # fmt: skip

    system = jaxpr_to_heyoka(coupled, 4, {"k": jnp.zeros(2)})
    assert system.num_pars == 2
    rhs = hy.cfunc([f for _, f in system.equations], [y for y, _ in system.equations])
    states = np.random.default_rng(1).normal(size=(10, 4))
    k = np.array([2.0, 3.0])
    q1, q2, v1, v2 = states.T  # the same field written with NumPy's indexing
    expected = np.stack([v1, v2, -k[0] * np.sin(q1) + (q2 - q1) * v2,
                         -k[1] * np.sin(q2) - 0.5 * (q2 - q1) + v1], axis=1)  # fmt: skip
    pars = np.repeat(k[:, None], 10, axis=1)
    heyoka_values = rhs(np.ascontiguousarray(states.T), pars=pars).T
    np.testing.assert_allclose(heyoka_values, expected, rtol=1e-14, atol=1e-14)


def test_selects_with_numeric_predicates_pick_their_case():
    """`where` and `select_n` whose predicate is a number pick a case per element
    (translated by NumPy, no JAX call), on expressions and on numbers alike."""

    def selects(t, y, args):
        which = jnp.array([0, 2, 1])
        picked = jax.lax.select_n(which, y, 2 * y, y**2)
        numbers = jax.lax.select_n(which > 0, jnp.arange(3.0), jnp.ones(3))
        scalar = jax.lax.select_n(jnp.asarray(1), y, jnp.sin(y))
        return (
            jnp.where(jnp.array([True, False, True]), y, -y) + picked + numbers + scalar
        )

    system = jaxpr_to_heyoka(selects, 3)
    rhs = hy.cfunc([f for _, f in system.equations], [y for y, _ in system.equations])
    y = np.random.default_rng(2).normal(size=(3, 7))
    expected = (
        np.where([[True], [False], [True]], y, -y)
        + np.stack([y[0], y[1] ** 2, 2 * y[2]])
        + np.array([[0.0], [1.0], [1.0]])
        + np.sin(y)
    )
    np.testing.assert_allclose(rhs(y), expected, rtol=1e-15, atol=1e-15)


def test_powers_of_a_zero_base_stay_finite():
    """q³ and q⁴ of an oscillator launched from its equilibrium q = 0: heyoka's
    real-exponent pow divides by the base there (err_nf_state); the translation's
    products of squares keep the run, and its energy, exact."""
    anharmonic = lj.Lagrangian(
        lambda q, v: 0.5 * v**2 - 0.5 * q**2 - q**3 / 3 - 0.25 * q**4
    )
    run = lj.simulate(anharmonic, (0.0, 1.0), t1=2.0, ts=np.linspace(0.0, 2.0, 5),
                      rtol=1e-15, atol=1e-15, solver=lj.Taylor(backend="heyoka"))  # fmt: skip
    q, v = np.asarray(run.q), np.asarray(run.qdot)
    energy = 0.5 * v**2 + 0.5 * q**2 + q**3 / 3 + 0.25 * q**4
    assert np.all(np.isfinite(q)) and np.ptp(q) > 0.5
    np.testing.assert_allclose(energy, 0.5, rtol=0, atol=1e-13)
