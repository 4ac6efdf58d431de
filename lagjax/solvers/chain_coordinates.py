r"""Chain coordinates: the separations of the closest pairs as integration variables.

A separation $\mathbf q_j - \mathbf q_i$ computed from positions of size $|q|$
carries a rounding error $\varepsilon|q|$, a relative error $\varepsilon|q|/r$ in
the force of a close pair: 2500 ε at the Pythagorean problem's closest approach.
Mikkola & Aarseth (1993) order the bodies in a *chain* $i_1, \dots, i_N$ through
the closest pairs and integrate the chain vectors themselves,

$$\mathbf X_k = \mathbf q_{i_{k+1}} - \mathbf q_{i_k}\quad(k = 1..N-1),\qquad
\mathbf R = \frac1M\sum_i m_i\mathbf q_i,$$

a point transformation whose conjugate momenta $\mathbf W_k$ and $\mathbf P$
follow from $\sum_i \mathbf p_i\cdot d\mathbf q_i
= \sum_k \mathbf W_k\cdot d\mathbf X_k + \mathbf P\cdot d\mathbf R$:

$$\mathbf p_{i_k} = \frac{m_{i_k}}{M}\mathbf P + \mathbf W_{k-1} - \mathbf W_k
\quad(\mathbf W_0 = \mathbf W_N = 0),\qquad
\mathbf W_k = -\sum_{j \le k}\Big(\mathbf p_{i_j} - \frac{m_{i_j}}{M}\mathbf P\Big),$$

so $\mathbf P$ is the total momentum and the map is canonical. In the barycentric
frame the Hamiltonian stays separable, $H = T(\mathbf W) + V(\mathbf X)$
(`lagjax.solvers.chain`), and the centre of mass moves on its own line,
$\mathbf R(t) = \mathbf R_0 + \mathbf P\,(t - t_0)/M$.

**Separations.** A pair at most `NEAR_IN_CHAIN` links apart is separated by the
sum of the chain vectors between them, exact for neighbours; a pair further apart
by the difference of positions along the chain (the rule of Mikkola & Aarseth
1993): a long sum gathers one rounding per term, and such a pair is far apart
whenever the chain follows the closest pairs.

**Building and re-forming the chain.** The chain starts at the closest pair and
grows at either end by the shortest link to a body not yet in it (Mikkola &
Aarseth 1993, §3). At a step boundary the chain is built again from the
separations of the current one; where it differs, the new chain vectors are the
old ones' sums between the new neighbours (`rechained`), so a pair that was
already chained keeps its separation to the last bit and a new link carries the
round-off of the old vectors it sums. Under `jit` the chain is an array of body
indices and the transformation a few gathers; a boolean says whether it changed.

??? cite "References"

    - Mikkola & Aarseth, *An implementation of N-body chain regularization*,
      Celest. Mech. Dyn. Astron. 57, 439 (1993).
    - Mikkola & Merritt, *Algorithmic regularization with velocity-dependent
      forces*, MNRAS 372, 219 (2006); *Implementing few-body algorithmic
      regularization with post-Newtonian terms*, AJ 135, 2398 (2008).
"""

from __future__ import annotations

import itertools
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

# Pairs at most this many links apart are separated by a sum of chain vectors.
NEAR_IN_CHAIN = 2


class ChainState(NamedTuple):
    """Chain vectors `X` (N−1, d), their momenta `W` (N−1, d), and `order` (N,):
    the body at each place of the chain."""

    X: jax.Array
    W: jax.Array
    order: jax.Array


def chain_separations(X: jax.Array) -> dict[tuple[int, int], jax.Array]:
    """{(i, j): position of place j − position of place i} for places i < j of the
    chain (module docstring, *separations*). Unrolled over the pairs: N is small,
    and the scalar arithmetic fuses (`lagjax._linalg.scalar_value_and_gradient`)."""
    links = X.shape[0]
    along = [jnp.zeros_like(X[0])]  # positions along the chain from its head
    for k in range(links):
        along.append(along[-1] + X[k])
    separations = {}
    for i in range(links + 1):
        for j in range(i + 1, links + 1):
            if j - i <= NEAR_IN_CHAIN:
                separation = X[i]
                for between in range(i + 1, j):
                    separation = separation + X[between]
            else:
                separation = along[j] - along[i]
            separations[(i, j)] = separation
    return separations


def _separation_array(X: jax.Array) -> jax.Array:
    """(N, N, d): entry [i, j] the vector from place i to place j (antisymmetric)."""
    places = X.shape[0] + 1
    separations = chain_separations(X)
    zero = jnp.zeros_like(X[0])
    rows = [
        [
            separations[(i, j)] if i < j else (-separations[(j, i)] if j < i else zero)
            for j in range(places)
        ]
        for i in range(places)
    ]
    return jnp.stack([jnp.stack(row) for row in rows])


def closest_pair_chain(distance: jax.Array) -> jax.Array:
    """The chain through N bodies from their (N, N) distances: the closest pair,
    then at either end the shortest link to a body not yet chained (module
    docstring). Returns the bodies in chain order, (N,) integers; the closest
    pair's lower index comes first, so a chain built again from its own
    separations is the same array when no link is shorter than before."""
    places = distance.shape[0]
    distance = jnp.where(jnp.eye(places, dtype=bool), jnp.inf, distance)
    first, second = jnp.divmod(jnp.argmin(distance).astype(jnp.int32), places)
    # A deque in an array of 2N − 1 slots: the head grows down, the tail up.
    chain = jnp.zeros((2 * places - 1,), jnp.int32)
    head, tail = places - 1, places
    chain = chain.at[head].set(first).at[tail].set(second)
    chained = (jnp.arange(places) == first) | (jnp.arange(places) == second)
    ends = (first, second)
    for _ in range(places - 2):
        to_head = jnp.where(chained, jnp.inf, distance[ends[0]])
        to_tail = jnp.where(chained, jnp.inf, distance[ends[1]])
        at_head = jnp.min(to_head) < jnp.min(to_tail)
        body = jnp.where(at_head, jnp.argmin(to_head), jnp.argmin(to_tail))
        body = body.astype(jnp.int32)
        head = jnp.where(at_head, head - 1, head)
        tail = jnp.where(at_head, tail, tail + 1)
        chain = chain.at[jnp.where(at_head, head, tail)].set(body)
        chained = chained | (jnp.arange(places) == body)
        ends = (jnp.where(at_head, body, ends[0]), jnp.where(at_head, ends[1], body))
    return jax.lax.dynamic_slice(chain, (head,), (places,))


def _relative_momenta(W: jax.Array) -> jax.Array:
    """p_k − m_k P/M at each place: W_{k−1} − W_k with W_0 = W_N = 0."""
    zero = jnp.zeros_like(W[:1])
    return jnp.concatenate([zero, W]) - jnp.concatenate([W, zero])


def _momenta_of_links(relative: jax.Array) -> jax.Array:
    """W_k = −Σ_{j≤k} (p_j − m_j P/M) over the places in chain order."""
    return -jnp.cumsum(relative, axis=0)[:-1]


def to_chain(masses: jax.Array, q: jax.Array, p: jax.Array):
    """Barycentric (q, p) of shape (N, d) → (`ChainState`, R, P): the chain through
    the closest pairs, the centre of mass R and the total momentum P."""
    masses = jnp.asarray(masses)
    total = jnp.sum(masses)
    centre = jnp.sum(masses[:, None] * q, axis=0) / total
    momentum = jnp.sum(p, axis=0)
    distance = jnp.sqrt(jnp.sum((q[:, None] - q[None, :]) ** 2, axis=-1))
    order = closest_pair_chain(distance)
    placed_q, placed_p = q[order], p[order]
    relative = placed_p - (masses[order] / total)[:, None] * momentum
    X = placed_q[1:] - placed_q[:-1]
    return ChainState(X, _momenta_of_links(relative), order), centre, momentum


def from_chain(masses: jax.Array, chain: ChainState, centre: Any, momentum: Any):
    """(q, p) of shape (N, d) in body order from a `ChainState`, the centre of mass
    and the total momentum (the inverse of `to_chain`)."""
    X, W, order = chain
    masses = jnp.asarray(masses)
    placed_masses = masses[order]
    total = jnp.sum(masses)
    along = jnp.concatenate([jnp.zeros_like(X[:1]), jnp.cumsum(X, axis=0)])
    own_centre = jnp.sum(placed_masses[:, None] * along, axis=0) / total
    placed_q = centre + (along - own_centre)
    placed_p = (placed_masses / total)[:, None] * momentum + _relative_momenta(W)
    q = jnp.zeros_like(placed_q).at[order].set(placed_q)
    p = jnp.zeros_like(placed_p).at[order].set(placed_p)
    return q, p


def rechained(chain: ChainState) -> tuple[ChainState, jax.Array]:
    """(the chain built again from its own separations, whether it changed).

    The new chain vectors are the old ones' separations between the new neighbours
    (`chain_separations`: sums of old vectors, or differences along the chain for
    places more than `NEAR_IN_CHAIN` apart); the new momenta sum the old places'
    relative momenta. Where the chain did not change the old state is returned
    bit for bit."""
    X, W, order = chain
    separation = _separation_array(X)
    distance = jnp.sqrt(jnp.sum(separation**2, axis=-1))
    places = closest_pair_chain(distance)  # old places in the new order
    new_X = separation[places[:-1], places[1:]]
    new_W = _momenta_of_links(_relative_momenta(W)[places])
    changed = jnp.any(places != jnp.arange(places.shape[0]))
    new = ChainState(new_X, new_W, order[places])
    kept = jax.tree_util.tree_map(lambda a, b: jnp.where(changed, a, b), new, chain)
    return ChainState(*kept), changed


def chain_links(order: Any) -> list[tuple[int, int]]:
    """The chain's links as sorted body pairs (for tests and reports)."""
    order = np.asarray(order)
    return sorted(
        (int(min(a, b)), int(max(a, b))) for a, b in itertools.pairwise(order)
    )
