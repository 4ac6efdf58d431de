r"""Gragg–Bulirsch–Stoer extrapolation of the leapfrog, with step-size control.

The leapfrog $S_h$ of a split system $\dot A = f(B)$, $\dot B = g(A)$ — half a
$B$-step, a full $A$-step, half a $B$-step — is symmetric, $S_h^{-1} = S_{-h}$,
so $n$ of its steps over $H$ have an error expansion in even powers of $h = H/n$
(HNW §II.8, Theorem 8.10):

$$T(h) = y(H) + e_1(H)\,h^2 + e_2(H)\,h^4 + \cdots$$

Running it with $n_j$ substeps ($j = 1..k$; by default the harmonic sequence
$n_j = j$: a symmetric one-step method needs no even $n_j$ and no smoothing step) and
eliminating the powers by Aitken–Neville,

$$T_{j,l+1} = T_{j,l} + \frac{T_{j,l} - T_{j-1,l}}{(n_j/n_{j-l})^2 - 1},$$

gives $T_{k,k}$ of order $2k$; $T_{k,k} - T_{k,k-1}$ estimates the error of
$T_{k,k-1}$ (order $2k - 2$) and steers $H$ (HNW §II.9, with a fixed order).

On the time-transformed extended Hamiltonian (`lagjax.solvers.time_transformed`)
this is the method of the algorithmic-regularisation chain codes (Mikkola &
Aarseth 2002): the logarithmic leapfrog follows each close two-body encounter
almost exactly, so its error expansion stays smooth through it, and the
extrapolation lifts it to high order at fictitious steps tens of times longer
than a splitting method's. It is not symplectic: the energy error is bounded by
the tolerance times the number of steps, not by a modified Hamiltonian.

**Round-off at close encounters.** Below tolerances of about 1e-13 the energy
error is set by round-off, and the round-off that counts is that of the close
pair's separation: computed as a difference $q_i - q_j$ of positions of size
$|q|$, it carries a relative error $\varepsilon|q|/r_{ij}$ into the force and the
log-Hamiltonian (2500 ε at the Pythagorean problem's $r \approx 4\cdot10^{-4}$;
shifting the whole configuration by 10 raises the error tenfold). With the close
pair's separation a coordinate of the system (Jacobi or chain coordinates,
Mikkola & Aarseth 1993) the error follows the tolerance, alike eagerly and under
`jax.jit`: `benchmarks/pythagorean_jacobi.py`.

**The lanes.** The $k$ leapfrog runs are independent, so they run side by side
on a leading axis of length $k$: a loop of $n_k$ sweeps, each one vectorised force
and velocity evaluation for all $k$ runs, a run with fewer substeps frozen by zero
coefficients once it is done. For the harmonic sequence that is $k$ dependent
evaluations per step instead of $k(k+1)/2$. The force and velocity are taken with
their energies in one pass on the coordinates' scalars
(`lagjax._linalg.scalar_value_and_gradient`).

??? cite "References"

    - Gragg, *On extrapolation algorithms for ordinary initial value problems*,
      SIAM J. Numer. Anal. 2, 384 (1965).
    - Bulirsch & Stoer, *Numerical treatment of ordinary differential equations
      by extrapolation methods*, Numer. Math. 8, 1 (1966).
    - Hairer, Nørsett & Wanner, *Solving Ordinary Differential Equations I*,
      2nd ed., Springer (1993), §II.8–II.9.
    - Mikkola & Tanikawa, *Algorithmic regularization of the few-body problem*,
      MNRAS 310, 745 (1999).
    - Mikkola & Aarseth, *A time-transformed leapfrog scheme*, Celest. Mech.
      Dyn. Astron. 84, 343 (2002).
    - Mikkola & Aarseth, *An implementation of N-body chain regularization*,
      Celest. Mech. Dyn. Astron. 57, 439 (1993).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from diffrax import RESULTS, AbstractTerm, LocalLinearInterpolation
from jax.flatten_util import ravel_pytree

from lagjax._core.solver_kinds import AbstractSplittingMethod
from lagjax.solvers.compensated import compensated_add, zero_compensation

# Step-size control for a fixed order (HNW §II.9, (9.4)): factor limits and safety.
SAFETY = 0.9
SHRINK_LIMIT = 0.2
GROWTH_LIMIT = 4.0


class GraggBulirschStoer(AbstractSplittingMethod):
    r"""Extrapolated leapfrog of order $2k$ with an adaptive step (module docstring).

    Made for `lj.TimeTransformed`, where `dt` is the first fictitious step:

    ```python
    solver = lj.TimeTransformed(lj.GraggBulirschStoer(rtol=1e-13, atol=1e-13))
    traj = lj.simulate(scene, y0, t1=70.0, dt=0.1, ts=ts, solver=solver)
    ```

    **Arguments:**

    - `substeps`: $n_1 < \dots < n_k$, the leapfrog runs' numbers of substeps;
      $k$ runs give order $2k$ at $n_k$ dependent vectorised force evaluations a
      step. Default Romberg's $1, 2, 4, 8$ (order 8): the tableau's weights
      $\sum_j |c_j|$ are 2.0 against 6.2 for the harmonic $1..4$ and about 30
      for $1..6$, and they multiply the round-off of every run: on the
      Pythagorean problem's encounters that decides the energy error
      (`benchmarks/close_encounters.py`: 2e-13–3e-12 at rtol 1e-13 … 1e-14,
      with the rounding of the compiled program, against 6e-12 for $1..6$).
    - `rtol`, `atol`: the local error per step, $|T_{k,k} - T_{k,k-1}| \le$
      `atol + rtol·|y|` in the root-mean-square over the components.
    """

    substeps: tuple[int, ...] = eqx.field(static=True, default=(1, 2, 4, 8))
    rtol: float = 1e-13
    atol: float = 1e-13
    term_structure: ClassVar = (AbstractTerm, AbstractTerm)
    interpolation_cls: ClassVar[Callable[..., LocalLinearInterpolation]] = (
        LocalLinearInterpolation
    )

    def __check_init__(self):
        substeps = self.substeps
        if not (
            len(substeps) >= 2
            and all(isinstance(n, int) and n >= 1 for n in substeps)
            and all(a < b for a, b in itertools.pairwise(substeps))
        ):
            raise ValueError(
                "GraggBulirschStoer needs substeps: at least two increasing "
                f"positive integers (two runs give an error estimate); got {substeps}"
            )
        for name in ("rtol", "atol"):
            value = getattr(self, name)
            if isinstance(value, (int, float)) and not value > 0:
                raise ValueError(
                    f"GraggBulirschStoer's {name} must be positive; got {value}"
                )

    @property
    def columns(self) -> int:
        """k, the number of leapfrog runs: the order is 2k."""
        return len(self.substeps)

    def order(self, terms: Any) -> int:
        return 2 * self.columns

    def init(self, terms, t0, t1, y0, args) -> Any:
        """The compensation of the state's sum of increments (Kahan)."""
        return zero_compensation(y0)

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        """$T_{k,k}$ over $[t_0, t_1]$ and its error estimate $T_{k,k} - T_{k,k-1}$.

        The runs' increments are extrapolated, not their end states: the
        tableau's weights grow with $k$, and on the increments they multiply the
        increments' round-off, not the state's. The increment meets the state
        once, in a compensated sum."""
        increments = _leapfrog_increments(terms, t0, t1, y0, args, self.substeps)
        best, second = _extrapolate(increments, self.substeps)
        error = jax.tree_util.tree_map(jnp.subtract, best, second)
        y1, compensation = compensated_add(y0, best, solver_state)
        return y1, error, dict(y0=y0, y1=y1), compensation, RESULTS.successful

    def func(self, terms, t0, y0, args):
        term_a, term_b = terms
        a, b = y0
        return term_a.vf(t0, b, args), term_b.vf(t0, a, args)

    def adapt(self, step: Any, y0: Any, y1: Any, error: Any) -> tuple[Any, Any]:
        """(accepted, next step) from the error estimate of a step of length `step`.

        The estimate is of order $2k - 1$ in the step, hence the exponent."""
        ratio = error_ratio(y0, y1, error, self.rtol, self.atol)
        accepted = ratio <= 1
        exponent = 1 / (2 * self.columns - 1)
        # A NaN ratio (a step into a singularity) shrinks the step and is refused.
        factor = SAFETY * jnp.where(ratio > 0, ratio, 1e-10) ** -exponent
        factor = jnp.where(jnp.isnan(ratio), SHRINK_LIMIT, factor)
        factor = jnp.clip(factor, SHRINK_LIMIT, GROWTH_LIMIT)
        return accepted & ~jnp.isnan(ratio), step * factor


def error_ratio(y0: Any, y1: Any, error: Any, rtol: Any, atol: Any) -> jax.Array:
    """RMS over the components of error / (atol + rtol·max(|y0|, |y1|))."""
    scaled = jax.tree_util.tree_map(
        lambda e, a, b: (e / (atol + rtol * jnp.maximum(jnp.abs(a), jnp.abs(b)))) ** 2,
        error,
        y0,
        y1,
    )
    leaves = [jnp.ravel(x) for x in jax.tree_util.tree_leaves(scaled)]
    return jnp.sqrt(jnp.mean(jnp.concatenate(leaves)))


def _substep_tables(substeps: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Per sweep i and run j: the A-step weight (1 while i < n_j) and the B-step
    weight after it (1, ½ at the last substep, 0 once done)."""
    sweeps = np.arange(max(substeps))[:, None]
    counts = np.asarray(substeps)[None, :]
    a_weights = (sweeps < counts).astype(float)
    b_weights = np.where(sweeps < counts - 1, 1.0, 0.0)
    b_weights = np.where(sweeps == counts - 1, 0.5, b_weights)
    return a_weights, b_weights


def _leapfrog_increments(terms, t0, t1, y0, args, substeps: tuple[int, ...]) -> Any:
    """The increments y_j − y0 of the k leapfrog runs over [t0, t1] (n_j
    substeps), stacked on a leading axis (the lanes, module docstring).

    Each half of the state is one flat vector per lane, so an update is one
    kernel, not one per leaf. Each stage point is y0 + increment, rounded once: a
    stage point moved in place gathers a rounding of the state's size at every
    substep, which the tableau then weights. On the Pythagorean problem, (1, 2, 4,
    8) at the six tolerances 1e-13 … 1e-14 of `benchmarks/close_encounters.py`
    that gave energy errors of 1.9e-13–1.4e-12 against 5.1e-13–7.5e-12 moved in
    place. (Kahan's compensation of the sums as well changed nothing measurable.)"""
    term_a, term_b = terms
    (a0, unravel_a), (b0, unravel_b) = (ravel_pytree(half) for half in y0)
    h = (t1 - t0) / jnp.asarray(substeps, dtype=jnp.result_type(t1 - t0))
    # All the sweeps' step lengths in one product per half (one kernel, not 2·n_k).
    a_factors, b_factors = (
        jnp.asarray(weights, h.dtype)[..., None] * h[:, None]
        for weights in _substep_tables(substeps)
    )
    a_rate = jax.vmap(lambda b: ravel_pytree(term_a.vf(t0, unravel_b(b), args))[0])
    b_rate = jax.vmap(lambda a: ravel_pytree(term_b.vf(t0, unravel_a(a), args))[0])
    lanes = len(substeps)
    delta_a = jnp.zeros((lanes, a0.size), a0.dtype)
    delta_b = 0.5 * h[:, None] * b_rate(jnp.broadcast_to(a0, (lanes, a0.size)))

    # A rolled loop over the sweeps (each one vectorised kick and drift): on the
    # Pythagorean problem as fast as unrolled within the noise (4.6 against 4.2 µs
    # a step) and compiled in a third of the time (4 s against 14 s).
    def sweep(index, deltas):
        delta_a, delta_b = deltas
        delta_a = delta_a + a_factors[index] * a_rate(b0 + delta_b)
        delta_b = delta_b + b_factors[index] * b_rate(a0 + delta_a)
        return delta_a, delta_b

    delta_a, delta_b = jax.lax.fori_loop(0, max(substeps), sweep, (delta_a, delta_b))
    return jax.vmap(unravel_a)(delta_a), jax.vmap(unravel_b)(delta_b)


def _along_lanes(factor: Any, x: jax.Array) -> jax.Array:
    """`factor` (one per lane) shaped to broadcast against the stacked `x`."""
    return jnp.reshape(factor, (-1,) + (1,) * (jnp.ndim(x) - 1)).astype(x.dtype)


def _extrapolate(runs: Any, substeps: tuple[int, ...]) -> tuple[Any, Any]:
    """(T_{k,k}, T_{k,k−1}): Aitken–Neville in h² on the stacked runs, one column
    of the tableau at a time (column l holds T_{j,l} for j = l..k)."""
    counts = np.asarray(substeps, dtype=float)
    columns = len(substeps)
    column, previous = runs, runs
    for level in range(1, columns):
        # T_{j,l+1} for j = level..k−1 (0-based), from the rows j and j − 1.
        ratios = (counts[level:] / counts[: columns - level]) ** 2 - 1
        previous = column
        column = jax.tree_util.tree_map(
            lambda x, r=ratios: x[1:] + (x[1:] - x[:-1]) / _along_lanes(r, x), column
        )
    best = jax.tree_util.tree_map(lambda x: x[-1], column)
    second = jax.tree_util.tree_map(lambda x: x[-1], previous)
    return best, second
