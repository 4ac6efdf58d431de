r"""The action $S = \int L\,dt$: Hamilton's principle and Hamilton's principal function.

**Action of a path.** For a path $q(t)$ given as a function of time,

$$ S[q] = \int_{t_0}^{t_1} L\big(q(t), \dot q(t), t\big)\,dt , $$

with $\dot q$ from `jax.jvp` of the path and the integral by $m$-point
Gauss–Legendre quadrature on equal panels (exact for polynomials of degree
$2m - 1$, so of order $2m$ in the panel width): `action_of_path`. Hamilton's
principle (the course text §3.6, eq. 3.100–3.105) says that the true path makes
$S$ stationary among paths with the same end points: for $\eta(t_0) = \eta(t_1) =
0$, $S[q + \varepsilon\eta] - S[q] = O(\varepsilon^2)$.

**Action of a saved trajectory.** Between two saved times $t_k, t_{k+1}$ (spacing
$h$) the path is the cubic Hermite interpolant of $(q_k, \dot q_k, q_{k+1}, \dot
q_{k+1})$, whose error $e(t) = q^{(4)}(\xi)\,(t - t_k)^2 (t - t_{k+1})^2/4!$ is
$O(h^4)$ and vanishes at the samples; each interval is then integrated as a path
(`action`). Because $e$ vanishes at every sample, the first variation gives

$$ S[q + e] - S[q] = \int \Big(\frac{\partial L}{\partial q}
   - \frac{d}{dt}\frac{\partial L}{\partial \dot q}\Big)\cdot e\,dt
   + O\big(\|\dot e\|^2\big), $$

so the rule is of **order 4** in the sample spacing for any smooth path (uniform or
not). Along a *true* path of a conservative system the bracket vanishes and only
the second-order term $O(h^6)$ and the quadrature's $O(h^{2m})$ remain: **order 6**
with the default $m = 3$ nodes (measured in `tests/test_action.py`).

A Hamiltonian system is integrated in phase space, $S = \int (p\cdot\dot q - H)\,dt$
(the course text §6.3), with $q$ and $p$ both Hermite-interpolated from the slopes
$(\dot q, \dot p)$ of Hamilton's equations: no Legendre transform is needed, and the
same variational argument gives the same orders.

**Hamilton's principal function.** Along a true path $dS/dt = p\cdot\dot q - H =
L$ (the course text §6.6, eq. 6.71–6.72), so $S(q(t), t) - S(q(t_0), t_0) =
\int_{t_0}^t L\,dt'$ — the cumulative action, `principal_function`. As a function
of the end points, $S(q_1, t_1; q_0, t_0)$, it is `lagjax.action_principle.shooting.action_between`.

References: the course text §3.6 (Hamilton's principle), §6.3, §6.6 (Hamilton–Jacobi
equation, eq. 6.6.1 for the oscillator); Goldstein, Poole & Safko, *Classical
Mechanics*, 3rd ed., §2.1–2.3, §8.5, §10.1; Hairer, Lubich & Wanner, *Geometric
Numerical Integration*, 2nd ed., §VI.6 (Hamilton's principle and the generating
function of the flow).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from lagjax._core.system import AbstractSystem
from lagjax._core.system_protocols import LagrangianLike
from lagjax.mechanics.hamiltonian import AbstractHamiltonian
from lagjax.mechanics.legendre import tree_dot
from lagjax.trajectory import Trajectory

System = AbstractSystem

# Three nodes integrate the Hermite interpolant's action to O(h⁶), which is what the
# interpolation itself achieves on a true path; more nodes would not raise the order.
DEFAULT_NODES = 3


def resolve_system(system: System, args: Any) -> tuple[AbstractSystem, Any]:
    """The mechanical system and its args; a scene gives its system and itself as
    args (as `simulate` does). Refuses systems without an action functional."""
    if not isinstance(system, AbstractSystem):
        raise TypeError(
            "the action needs a Lagrangian, a Hamiltonian or a scene; got "
            f"{type(system).__name__}"
        )
    system, args = system.resolve(args)
    system.path_lagrangian()  # raises for systems with no action (a RigidBody)
    return system, args


def _gauss_legendre(
    integrand: Callable[[jax.Array], jax.Array], t0: Any, t1: Any, nodes: int
) -> jax.Array:
    """∫ integrand dt over [t0, t1] with the `nodes`-point Gauss–Legendre rule."""
    if nodes < 1:
        raise ValueError(f"nodes must be a positive integer, got {nodes}")
    abscissae, weights = np.polynomial.legendre.leggauss(nodes)
    half_width = (t1 - t0) / 2
    times = (t0 + t1) / 2 + half_width * jnp.asarray(abscissae)
    return half_width * jnp.dot(jnp.asarray(weights), jax.vmap(integrand)(times))


def _path_action(
    lagrangian: LagrangianLike, path: Callable, t0: Any, t1: Any, args: Any, nodes: int
) -> jax.Array:
    """∫ L(q, q̇, t) dt over one panel, q̇ = dq/dt by forward-mode autodiff."""

    def integrand(t):
        q, qdot = jax.jvp(path, (t,), (jnp.ones_like(t),))
        return lagrangian(q, qdot, t, args)

    return _gauss_legendre(integrand, t0, t1, nodes)


def _phase_space_path_action(
    hamiltonian: AbstractHamiltonian,
    phase_path: Callable,
    t0: Any,
    t1: Any,
    args: Any,
    nodes: int,
) -> jax.Array:
    """∫ (p·q̇ − H(q, p, t)) dt over one panel for a path t ↦ (q, p)."""

    def integrand(t):
        (q, p), (qdot, _) = jax.jvp(phase_path, (t,), (jnp.ones_like(t),))
        return tree_dot(p, qdot) - hamiltonian(q, p, t, args)

    return _gauss_legendre(integrand, t0, t1, nodes)


@eqx.filter_jit
def action_of_path(
    system: System,
    path: Callable[[jax.Array], Any],
    t0: Any,
    t1: Any,
    args: Any = None,
    *,
    nodes: int = DEFAULT_NODES,
    intervals: int = 1,
) -> jax.Array:
    r"""The action $\int_{t_0}^{t_1} L(q(t), \dot q(t), t)\,dt$ of a path $t \mapsto q(t)$.

    **Arguments:**
    - `system`: a `Lagrangian`, or a Hamiltonian (its Legendre-transformed
      Lagrangian is used), or a scene (which is then also the default `args`).
    - `path`: a function of the scalar time returning q (any pytree); $\dot q$ is
      its derivative by `jax.jvp`, so the path must be differentiable in t.
    - `nodes`: Gauss–Legendre nodes per panel (exact for degree $2\,$nodes$-1$).
    - `intervals`: number of equal panels.

    Jit-able and differentiable (with respect to anything the path closes over,
    `t0`, `t1` and `args`). Use it to test Hamilton's principle:
    `jax.jvp(lambda eps: action_of_path(lag, lambda t: q(t) + eps * eta(t), ...), ...)`.

    **References:** the course text §3.6, eq. 3.100–3.103.
    """
    system, args = resolve_system(system, args)
    lagrangian = system.path_lagrangian()
    fractions = jnp.arange(intervals + 1) / intervals
    edges = t0 + (t1 - t0) * fractions
    panels = jax.vmap(lambda a, b: _path_action(lagrangian, path, a, b, args, nodes))(
        edges[:-1], edges[1:]
    )
    return jnp.sum(panels)


def _hermite(t_start, t_end, value_start, slope_start, value_end, slope_end):
    """The cubic Hermite interpolant on [t_start, t_end], a function of t (pytrees)."""
    width = t_end - t_start

    def path(t):
        s = (t - t_start) / width
        h00 = (1 + 2 * s) * (1 - s) ** 2
        h10 = s * (1 - s) ** 2
        h01 = s**2 * (3 - 2 * s)
        h11 = s**2 * (s - 1)
        return jax.tree_util.tree_map(
            lambda a, va, b, vb: (
                h00 * a + h10 * width * va + h01 * b + h11 * width * vb
            ),
            value_start,
            slope_start,
            value_end,
            slope_end,
        )

    return path


def _fill_padding(trajectory: Trajectory) -> Trajectory:
    """Padding of `SaveAt(steps=True)` (t = inf, states inf) replaced by copies of
    the last saved time and state.

    The padded intervals are dropped from the sum anyway, but evaluating L or the
    vector field at inf would put NaN into the gradients through `jnp.where` (and
    zeros instead could meet a potential singular at q = 0).
    """
    saved = jnp.isfinite(trajectory.ts)
    count = saved.shape[-1]
    last = jnp.sum(saved, axis=-1, keepdims=True) - 1
    index = jnp.where(saved, jnp.arange(count), last)

    def fill(x):
        where = index.reshape(index.shape + (1,) * (jnp.ndim(x) - index.ndim))
        return jnp.take_along_axis(x, where, axis=index.ndim - 1)

    return eqx.tree_at(
        lambda tr: (tr.ts, tr.ys),
        trajectory,
        (fill(trajectory.ts), jax.tree_util.tree_map(fill, trajectory.ys)),
    )


def _interval_actions_single(system, nodes, ts, values, slopes, args):
    """Action over each interval of one (unbatched) saved trajectory."""
    if system.second_is_momentum:
        q, p = values
        slopes = jax.vmap(system.vector_field, in_axes=(0, 0, 0, None))(q, p, ts, args)
    # Padded intervals have zero width: a dummy unit width keeps them finite.
    usable = ts[1:] != ts[:-1]
    t_start, t_end = ts[:-1], jnp.where(usable, ts[1:], ts[:-1] + 1)

    def ends(tree):
        start = jax.tree_util.tree_map(lambda x: x[:-1], tree)
        return start, jax.tree_util.tree_map(lambda x: x[1:], tree)

    (v0, v1), (s0, s1) = ends(values), ends(slopes)

    def one_interval(a, b, value_a, slope_a, value_b, slope_b):
        path = _hermite(a, b, value_a, slope_a, value_b, slope_b)
        if system.second_is_momentum:
            return _phase_space_path_action(system, path, a, b, args, nodes)
        return _path_action(system, path, a, b, args, nodes)

    pieces = jax.vmap(one_interval)(t_start, t_end, v0, s0, v1, s1)
    return jnp.where(usable, pieces, 0.0)


def _interval_actions(system: System, trajectory: Trajectory, nodes: int) -> jax.Array:
    """Action over each interval between saved times; leading batch axes kept."""
    _refuse_non_trajectory(trajectory)
    system, args = resolve_system(system, trajectory.args)
    if jnp.shape(trajectory.ts)[-1] < 2:
        raise ValueError(
            "the trajectory saves only one state (simulate's default is the final "
            "state alone); save the path, e.g. simulate(..., ts=jnp.linspace(t0, t1, "
            "n)) on the step grid of a fixed-step solver"
        )
    trajectory = _fill_padding(trajectory)
    if not system.second_is_momentum:
        values, slopes = trajectory.q, trajectory.qdot
    else:
        # Slopes come from `system`'s own Hamilton equations, inside the map.
        values, slopes = (trajectory.q, trajectory.p), None

    def single(ts, values, slopes, args):
        return _interval_actions_single(system, nodes, ts, values, slopes, args)

    mapped = single
    for _ in range(jnp.ndim(trajectory.ts) - 1):
        mapped = jax.vmap(mapped)
    return mapped(trajectory.ts, values, slopes, args)


def _refuse_non_trajectory(trajectory: Any) -> None:
    """The action reads the saved times, states and args of a run: a bare tuple of
    arrays carries neither the times nor the convention (q̇ or p) of its states."""
    if isinstance(trajectory, Trajectory):
        return
    raise TypeError(
        "the action takes the Trajectory that lj.simulate returns, with its states "
        "saved along the path (e.g. simulate(..., ts=jnp.linspace(t0, t1, 101))); "
        f"got {type(trajectory).__name__}. For a path given as a function q(t), "
        "use lj.action_of_path(system, path, t0, t1)"
    )


@eqx.filter_jit
def action(
    system: System, trajectory: Trajectory, *, nodes: int = DEFAULT_NODES
) -> jax.Array:
    r"""The action $\int L\,dt$ along a saved trajectory, from its first to last time.

    **Arguments:**
    - `system`: the `Lagrangian` whose L is integrated (evaluated at the
      trajectory's q and q̇, so a run integrated as a Hamiltonian works too), or a
      Hamiltonian, integrated in phase space as $\int (p\cdot\dot q - H)\,dt$
      (no Legendre transform), or a scene. `trajectory.args` are passed to it.
    - `trajectory`: from `simulate` (or `sweep`, whose batch axes are kept). Saved
      times may be non-uniform; padding with t = inf (`SaveAt(steps=True)`) is
      ignored.
    - `nodes`: Gauss–Legendre nodes per interval.

    Order 4 in the sample spacing for any smooth path, 6 along a true path of a
    conservative system (module docstring). The saved states must themselves be
    that accurate: save on the step grid of a fixed-step solver, or use tight
    tolerances with an adaptive one. Jit-able and differentiable.

    **References:** the course text §3.6 (eq. 3.100) and §6.6 (eq. 6.72).
    """
    return jnp.sum(_interval_actions(system, trajectory, nodes), axis=-1)


@eqx.filter_jit
def principal_function(
    system: System, trajectory: Trajectory, *, nodes: int = DEFAULT_NODES
) -> jax.Array:
    r"""Hamilton's principal function along a trajectory, $S(t_k) - S(t_0) = \int_{t_0}^{t_k} L\,dt$.

    The cumulative action at every saved time (zero at the first), by the rule of
    `action`. Along a true path this is the change of $S(q, \alpha, t)$, e.g.
    $W(q(t), E) - W(q_0, E) - E\,(t - t_0)$ for a conservative system (the course
    text eq. 6.73).

    **References:** the course text §6.6, eq. 6.71–6.73.
    """
    pieces = _interval_actions(system, trajectory, nodes)
    zero = jnp.zeros((*pieces.shape[:-1], 1), pieces.dtype)
    return jnp.concatenate([zero, jnp.cumsum(pieces, axis=-1)], axis=-1)
