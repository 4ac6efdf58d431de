r"""Chain regularization: gravitating bodies in chain coordinates, in fictitious time.

Close encounters of several bodies need two things: steps that shrink with the
closest separation, and separations accurate to their own size, not to the size
of the positions they are differences of. The first is the logarithmic
Hamiltonian (`lagjax.solvers.time_transformed`); the second are chain
coordinates (`lagjax.solvers.chain_coordinates`): the vectors between
neighbours of a chain through the closest pairs are the integration variables,
re-formed at step boundaries as the closest pairs change. Together they are the
*algorithmic regularization chain* of Mikkola & Merritt (2006, 2008), here with
the time-transformed leapfrog extrapolated by `GraggBulirschStoer` (Mikkola &
Aarseth 2002) or composed by any splitting table.

**The Hamiltonian.** For $N$ bodies with pairwise Newtonian gravity, in the
chain's order (masses $m_1..m_N$ along it) and with the centre of mass apart,

$$T(\mathbf W) = \sum_{k=1}^{N} \frac{|\mathbf W_{k-1} - \mathbf W_k|^2}{2 m_k},
\qquad
V(\mathbf X) = -\sum_{k<l} \frac{G m_k m_l}{|\mathbf r_{kl}|},$$

($\mathbf W_0 = \mathbf W_N = 0$), with $\mathbf r_{kl}$ the sum
$\mathbf X_k + \dots + \mathbf X_{l-1}$ for places at most two links apart and a
difference of positions along the chain otherwise. $H = T + V$ is separable, so
the time-transformed drift and kick flow exactly; the masses in chain order are
the flow's `args` (`ChainBodies`), gathered again when the chain changes.

**In a run** (`lagjax._integrate.chain_run`): the user's barycentric-frame
$(q, p)$ become the chain state once, the loop re-forms the chain after each
step, and the states at the save times are taken back. Nothing in a step
depends on where the bodies are, only on their separations: shifting the whole
configuration changes the result by the shift's round-off in the centre of mass
alone.

??? cite "References"

    - Mikkola & Aarseth, *An implementation of N-body chain regularization*,
      Celest. Mech. Dyn. Astron. 57, 439 (1993).
    - Mikkola & Tanikawa, *Algorithmic regularization of the few-body problem*,
      MNRAS 310, 745 (1999).
    - Mikkola & Aarseth, *A time-transformed leapfrog scheme*, Celest. Mech.
      Dyn. Astron. 84, 343 (2002).
    - Mikkola & Merritt, MNRAS 372, 219 (2006); AJ 135, 2398 (2008).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp

from lagjax.solvers.chain_coordinates import chain_separations
from lagjax.solvers.extrapolation import GraggBulirschStoer
from lagjax.solvers.splitting_engine import AbstractSplittingSolver
from lagjax.solvers.time_transformed import TimeTransformed, logarithmic_weight


class ChainBodies(eqx.Module):
    """The flow's `args`: the masses in chain order (N,) and G."""

    masses: jax.Array
    gravitational_constant: jax.Array


class ChainHamiltonian(eqx.Module):
    """$H = T(\\mathbf W) + V(\\mathbf X)$ of the module docstring, as the
    time-transformed terms call it: `kinetic_energy(W, t, bodies)` and
    `potential_energy(X, t, bodies)` with `bodies` a `ChainBodies`."""

    def kinetic_energy(self, p: Any, t: Any = 0.0, args: Any = None) -> jax.Array:
        """T of the chain momenta W = `p` (N−1, d); `args` a `ChainBodies`."""
        del t
        places = p.shape[0] + 1
        kinetic = jnp.zeros((), p.dtype)
        for k in range(places):
            momentum = (p[k - 1] if k > 0 else 0) - (p[k] if k < places - 1 else 0)
            kinetic = kinetic + jnp.sum(momentum**2) / (2 * args.masses[k])
        return kinetic

    def potential_energy(self, q: Any, t: Any = 0.0, args: Any = None) -> jax.Array:
        """V of the chain vectors X = `q` (N−1, d); `args` a `ChainBodies`."""
        del t
        masses = args.masses
        binding = jnp.zeros((), q.dtype)
        for (i, j), separation in chain_separations(q).items():
            distance = jnp.sqrt(jnp.sum(separation**2))
            binding = binding + masses[i] * masses[j] / distance
        return -args.gravitational_constant * binding


CHAIN_HAMILTONIAN = ChainHamiltonian()


class ChainRegularization(eqx.Module):
    r"""Gravitating bodies in a chain of their closest pairs, stepped in fictitious
    time (module docstring): for close encounters of three or more bodies.

    Use it through `simulate` on a system whose `args` carry `masses` (N,) and
    `gravitational_constant` (the Pythagorean scene, a `PlanetarySystem`) and
    whose H is their Newtonian gravity, `dt` the first fictitious step:

    ```python
    solver = lj.ChainRegularization(lj.GraggBulirschStoer(rtol=3e-14, atol=3e-14))
    traj = lj.simulate(scene, scene.initial_state(), t1=70.0, dt=0.1, ts=ts,
                       solver=solver)
    ```

    **Arguments:**

    - `splitting`: `GraggBulirschStoer(rtol=..., atol=...)`, the extrapolated
      leapfrog with step control, or any lagjax splitting table at the fixed
      fictitious step `dt` (as in `lj.TimeTransformed`).
    - `weight`: $w(x) > 0$ with $dt/ds = w(-V)$; default $1/x$, the logarithmic
      Hamiltonian.
    """

    splitting: AbstractSplittingSolver | GraggBulirschStoer
    weight: Callable[[Any], Any] = logarithmic_weight

    @property
    def name(self) -> str:
        return f"ChainRegularization({type(self.splitting).__name__})"

    def __check_init__(self):
        self.time_transformed()  # the same solvers are refused, by name

    def time_transformed(self) -> TimeTransformed:
        """The time-transformed method that steps the chain's Hamiltonian."""
        return TimeTransformed(self.splitting, self.weight)

    def terms(self) -> tuple[Any, Any]:
        """The splitting engine's terms on the extended chain state
        ((W, p_t), (X, t)) (`TimeTransformed.terms`)."""
        return self.time_transformed().terms(CHAIN_HAMILTONIAN)
