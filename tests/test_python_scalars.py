"""Python floats in `y0` and `args` are data, not parts of the compiled program: a
new value compiles nothing, and the answer follows the value."""

import jax.numpy as jnp
import numpy as np

import lagjax as lj
from tests.helpers import counted_compilations


def pendulum(theta, theta_dot, t, args):
    g, length = args
    return 0.5 * length**2 * theta_dot**2 + g * length * jnp.cos(theta)


def test_new_python_floats_compile_nothing_and_change_the_answer():
    lag = lj.Lagrangian(pendulum)

    def final(amplitude, g):
        run = lj.simulate(lag, (amplitude, 0.0), t1=1.0, dt=0.01, args=(g, 1.0))
        return float(run.q[-1])

    final(0.01, 9.81)  # compiles the program once
    with counted_compilations() as compiled:
        small = final(0.02, 9.81)
        stronger = final(0.02, 4 * 9.81)
    assert compiled == []
    # small oscillations: θ(t) = θ0 cos(√(g/l) t)
    np.testing.assert_allclose(small, 0.02 * np.cos(np.sqrt(9.81)), rtol=1e-4)
    np.testing.assert_allclose(stronger, 0.02 * np.cos(2 * np.sqrt(9.81)), rtol=1e-4)
