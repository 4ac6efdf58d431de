"""Fixed-point iteration for implicit stage equations, in the state's precision.

`StageIteration` repeats Z ← G(Z) until two iterates agree to within
atol + rtol·|Z| in the max norm. It is the Jacobian-free default of the
Gauss–Legendre methods: for a non-stiff problem the map G (h times the vector field
at the stages) is a contraction with constant ≈ h·Lip(f), so a handful of
evaluations reach round-off, far cheaper than a Newton step with its Jacobian and
LU factorisation.

It is an optimistix fixed-point solver, used through `optimistix.fixed_point`.
When the iteration does not contract (h·Lip(f) ≳ 1, a stiff step) it stops at
the solver's iteration limit and the step reports a failed nonlinear solve;
`lagjax.solvers.implicit.stage_failure_message` turns that into a message naming
the remedy, Newton's method (`root_finder=optimistix.Newton(...)`), which
converges at any step size. Two things set it apart from
`optimistix.FixedPointIteration`: its state has the
dtype of the iterate, so float32 stage solves also work when x64 is enabled; and
its tolerances are floored at what the iterate's dtype can resolve
(`lagjax._core.precision.reachable_tolerance`), so the float64 default of 1e-14 becomes
≈ 5e-6 in float32 instead of an unreachable test.

References: Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed.,
Springer (2006), §VIII.6.2 (fixed-point versus Newton iteration for implicit
Runge–Kutta stages).
"""

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx
from jaxtyping import Array, PyTree

from lagjax._core.precision import reachable_tolerance


class _IterationState(eqx.Module):
    scaled_change: Array  # max-norm change of the last iteration over its tolerance


class StageIteration(optx.AbstractFixedPointSolver):
    """Z ← G(Z) until ‖Z_new − Z‖ ≤ s·atol + rtol·|Z_new| (max norm, elementwise).

    **Arguments:**

    - `rtol`, `atol`: stopping tolerances; raised to 45 ε of the iterate's dtype
      when below it.
    - `norm`: the norm of the scaled change (default the max norm).

    `s` is `options["scale"]` when the caller passes one (1 otherwise): the
    Gauss–Legendre step passes the size of the state, min(1, max|y0|), so that
    `atol` is relative to a small state. With an absolute floor of 45 ε the stage increments of a
    pendulum of amplitude 1e-9 (about 1e-11) stopped at three digits, and the run
    was off by 1.6e-7 relative.
    """

    rtol: float
    atol: float
    norm: Callable[[PyTree], Array] = optx.max_norm

    def init(self, fn, y, args, options, f_struct, aux_struct, tags):
        del fn, args, options, f_struct, aux_struct, tags
        return _IterationState(jnp.array(jnp.inf, dtype=_dtype_of(y)))

    def step(self, fn, y, args, options, state, tags):
        del state, tags
        new_y, aux = fn(y, args)
        dtype = _dtype_of(y)
        rtol = reachable_tolerance(self.rtol, dtype)
        # never 0: a state at rest at 0 iterates 0 → 0, and 0/0 would never stop
        atol = jnp.maximum(
            reachable_tolerance(self.atol, dtype) * options.get("scale", 1.0),
            jnp.finfo(dtype).tiny,
        )
        scaled = jax.tree_util.tree_map(
            lambda new, old: (new - old) / (atol + rtol * jnp.abs(new)), new_y, y
        )
        return new_y, _IterationState(self.norm(scaled).astype(dtype)), aux

    def terminate(self, fn, y, args, options, state, tags):
        del fn, y, args, options, tags
        return state.scaled_change < 1, optx.RESULTS.successful

    def postprocess(self, fn, y, aux, args, options, state, tags, result):
        del fn, args, options, state, tags, result
        return y, aux, {}


def _dtype_of(tree: Any) -> Any:
    return jnp.result_type(*jax.tree_util.tree_leaves(tree))
