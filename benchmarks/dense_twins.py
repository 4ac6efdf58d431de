r"""Hand-written scan twins of fixed-step runs that save off the grid, every step, or
densely — what `benchmarks/dense_output.py` holds `lj.simulate` against.

Each twin is what a user would write by hand for one system: Yoshida's fourth-order
triple jump (kick first, the last force reused: three force evaluations a step,
plain sums) and the cubic
Hermite polynomial through the states and $h\dot y$ at the two ends of a step,

$$y(s) = (2s^3 - 3s^2 + 1)\,y_0 + (s^3 - 2s^2 + s)\,h\dot y_0
       + (-2s^3 + 3s^2)\,y_1 + (s^3 - s^2)\,h\dot y_1,$$

the extension `lagjax.solvers.hermite` gives Yoshida4. Reference: Yoshida, Phys. Lett. A
150 (1990) 262; Hairer, Nørsett & Wanner, *Solving ODEs I*, §II.6.
"""

from __future__ import annotations

import diffrax
import jax

jax.config.update("jax_enable_x64", True)  # before the arrays below are made

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import lagjax as lj  # noqa: E402

_CUBE_ROOT_2 = 2.0 ** (1.0 / 3.0)
_W1 = 1.0 / (2.0 - _CUBE_ROOT_2)
_W0 = -_CUBE_ROOT_2 * _W1
_KICKS = (_W1 / 2, (_W0 + _W1) / 2, (_W0 + _W1) / 2, _W1 / 2)
_DRIFTS = (_W1, _W0, _W1)


def _kepler_force(q):
    r2 = jnp.sum(q * q)
    return -q / (r2 * jnp.sqrt(r2))


def _pendulum_force(q):
    return -jnp.sin(q)


# name: (lagjax system, hand-written force −∂V/∂q, start, span)
TWIN_SYSTEMS = {
    "Kepler e=0.6": (
        lj.SeparableHamiltonian(
            lambda p: 0.5 * jnp.sum(p**2), lambda q: -1.0 / jnp.linalg.norm(q)
        ),
        _kepler_force,
        (jnp.array([0.4, 0.0]), jnp.array([0.0, 2.0])),
        10 * 2 * np.pi,
    ),
    "pendulum": (
        lj.SeparableHamiltonian(lambda p: 0.5 * p**2, lambda q: -jnp.cos(q)),
        _pendulum_force,
        (jnp.asarray(2.0), jnp.asarray(0.0)),
        50.0,
    ),
}


def _yoshida4(force, h):
    """One step (q, p, F) → (q, p, F): kick first, F = force(q) carried over
    (first-same-as-last, as lagjax's splittings): three forces a step."""

    def step(q, p, f):
        for kick, drift in zip(_KICKS, _DRIFTS):
            p = p + kick * h * f
            q = q + drift * h * p
            f = force(q)
        return q, p + _KICKS[-1] * h * f, f

    return step


def _cubic(force, h, start, end, s):
    """The cubic Hermite state at fraction s of a step from `start` to `end`."""
    (q0, p0), (q1, p1) = start, end
    a0, a1 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
    b0, b1 = -2 * s**3 + 3 * s**2, s**3 - s**2
    q = a0 * q0 + a1 * h * p0 + b0 * q1 + b1 * h * p1
    p = a0 * p0 + a1 * h * force(q0) + b0 * p1 + b1 * h * force(q1)
    return q, p


def _brackets(times, h, steps):
    """The step each time lies in (a grid time ends its step)."""
    return np.clip(np.ceil(np.asarray(times) / h) - 1, 0, steps - 1).astype(np.int32)


def _twin_off_grid(force, h, steps, times):
    step = _yoshida4(force, h)
    targets = jnp.asarray(_brackets(times, h, steps) + 1)

    def save(carry, x):
        target, t = x

        def advance(c):
            q, p, f, _, _, k = c
            return (*step(q, p, f), q, p, k + 1)

        carry = jax.lax.while_loop(lambda c: c[5] < target, advance, carry)
        q, p, _, q_before, p_before, k = carry
        s = (t - (k - 1) * h) / h
        return carry, _cubic(force, h, (q_before, p_before), (q, p), s)

    def run(y0):
        q0, p0 = y0
        initial = (q0, p0, force(q0), q0, p0, jnp.asarray(0, jnp.int32))
        return jax.lax.scan(save, initial, (targets, times))[1]

    return run


def _stacked_states(force, h, steps, y0):
    step = _yoshida4(force, h)

    def one(carry, _):
        carry = step(*carry)
        return carry, carry[:2]

    q0, p0 = y0
    _, (qs, ps) = jax.lax.scan(one, (q0, p0, force(q0)), None, length=steps)
    return qs, ps


def _twin_steps(force, h, steps):
    return lambda y0: _stacked_states(force, h, steps, y0)


def _twin_dense(force, h, steps, times):
    def run(y0):
        qs, ps = _stacked_states(force, h, steps, y0)
        qs = jnp.concatenate([jnp.asarray(y0[0])[None], qs])
        ps = jnp.concatenate([jnp.asarray(y0[1])[None], ps])

        def evaluate(t):
            k = jnp.clip(jnp.ceil(t / h).astype(jnp.int32) - 1, 0, steps - 1)
            s = (t - k * h) / h
            return _cubic(force, h, (qs[k], ps[k]), (qs[k + 1], ps[k + 1]), s)

        return jax.vmap(evaluate)(times)

    return run


def scan_rows(system_name: str, steps: int) -> dict:
    """name: (lagjax run, hand-written twin, start) for one system."""
    system, force, start, span = TWIN_SYSTEMS[system_name]
    h = span / steps
    off_grid = jnp.linspace(0.37 * h, span - 0.63 * h, 1001)
    options = dict(t1=span, dt=h, solver=lj.Yoshida4())

    def simulate(y0, **kwargs):
        return lj.simulate(system, y0, **options, **kwargs)

    return {
        "ts off the grid": (
            lambda y0: simulate(y0, ts=off_grid).ys,
            _twin_off_grid(force, h, steps, off_grid),
            start,
        ),
        "SaveAt(steps=True)": (
            lambda y0: simulate(y0, saveat=diffrax.SaveAt(steps=True)).ys,
            _twin_steps(force, h, steps),
            start,
        ),
        "dense=True + 1001 evaluate": (
            lambda y0: simulate(y0, dense=True).evaluate(off_grid),
            _twin_dense(force, h, steps, off_grid),
            start,
        ),
    }
