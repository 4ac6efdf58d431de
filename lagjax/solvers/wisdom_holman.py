r"""Wisdom–Holman splitting: Kepler orbits drifted exactly, the planets' pull as kicks.

In a planetary system one mass dominates: each planet moves nearly on a Kepler
orbit about it, disturbed by forces a fraction $\varepsilon \sim m_{\rm planet}/
m_\star$ of the star's. Split the Hamiltonian there (Wisdom & Holman 1991;
Kinoshita, Yoshida & Nakai 1991),

$$H = H_{\rm Kepler} + H_{\rm interaction},$$

flow $H_{\rm Kepler}$ exactly (`lagjax.solvers.kepler_drift`: Gauss's f and g
functions) and $H_{\rm interaction}$, a function of the positions alone, as a
kick. The leapfrog of the two, drift–kick–drift,

$$\Phi_h = D_{h/2} \circ K_h \circ D_{h/2},$$

is symplectic, time-reversible, and errs by $O(\varepsilon h^2)$ instead of
$O(h^2)$: a step of days follows planets over millions of years.

**Jacobi coordinates** (bodies $0 \ldots N-1$, the star first;
$\eta_i = \sum_{j \le i} m_j$): $\tilde{\mathbf x}_i$ is body $i$'s position
relative to the centre of mass of bodies $0..i-1$, and $\tilde{\mathbf x}_0$ the
centre of mass of all; the momenta follow as $\tilde p = A^{-\mathsf T} p$ for the
position map $\tilde x = A x$, so the change is canonical, and
$\tilde{\mathbf p}_i = \tilde m_i \dot{\tilde{\mathbf x}}_i$ with
$\tilde m_i = m_i\eta_{i-1}/\eta_i$. The split (Wisdom, Holman & Touma 1996;
Rein & Tamayo 2015) is

$$H_{\rm Kepler} = \frac{|\tilde{\mathbf p}_0|^2}{2\eta_{N-1}} + \sum_{i\ge1}
\Big(\frac{|\tilde{\mathbf p}_i|^2}{2\tilde m_i} - \frac{G m_0 m_i}{|\tilde{\mathbf x}_i|}\Big),
\qquad
H_{\rm interaction} = \sum_{i\ge2} \frac{G m_0 m_i}{|\tilde{\mathbf x}_i|}
- \sum_{\substack{i<j\\(i,j)\ne(0,1)}} \frac{G m_i m_j}{r_{ij}}:$$

planet $i$'s Kepler problem has $\mu_i = G m_0\eta_i/\eta_{i-1}$, the centre of mass
drifts freely, and for the innermost planet the Jacobi and direct terms cancel
identically (they are left out, not subtracted).

**Symplectic correctors** (Wisdom, Holman & Touma 1996). The map's error
Hamiltonian is, to first order in $\varepsilon$, removed by a near-identity
canonical change of variables $C$: integrate $C^{-1}$ of the start, apply $C$ to
each output, and the error falls from $O(\varepsilon h^2)$ to
$O(\varepsilon h^k + \varepsilon^2 h^2)$ for a corrector of order $k$ = 3, 5 or
7, at no cost per step. $C$ is a product of
$Z(a, b) = D_a K_{-b} D_{-2a} K_b D_a$ with the paper's coefficients
($a_1 = \sqrt{7/40}$, $a_j = j a_1$), which are for the drift–kick–drift map.

`WisdomHolman.step` is the synchronised diffrax step (two Kepler drifts, one kick);
`lagjax._integrate.wisdom_holman_run` merges the half drifts of consecutive steps,
$u \mapsto D_h K_h u$ on $u = D_{h/2}\,y$, one drift and one kick per step.

??? cite "References"

    - Wisdom & Holman, *Symplectic maps for the N-body problem*, Astron. J. 102,
      1528 (1991).
    - Kinoshita, Yoshida & Nakai, *Symplectic integrators and their application
      to dynamical astronomy*, Celest. Mech. Dyn. Astron. 50, 59 (1991).
    - Wisdom, Holman & Touma, *Symplectic correctors*, Fields Inst. Commun. 10,
      217 (1996).
    - Rein & Tamayo, *WHFast: a fast and unbiased implementation of a symplectic
      Wisdom–Holman integrator*, MNRAS 452, 376 (2015).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, ClassVar, Protocol, runtime_checkable

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from lagjax.solvers.kepler_drift import kepler_drift

_A1 = math.sqrt(7 / 40)
# (a_j, b_j) of the factors Z(a_j h, b_j h) of the corrector C, applied in this
# order (WHT96; as printed to 50 digits in Rein & Tamayo's WHFast). C⁻¹ is the
# same sequence with every b negated (Z(a, b)⁻¹ = Z(−a, b), and each table is
# antisymmetric).
_B31 = 0.024900596027799867499350357910273437184309981229127
_B51 = -0.0083001986759332891664501193034244790614366604097090
_B52 = 0.041500993379666445832250596517122395307183302048545
_B71 = 0.0024926811426922105779030593952776964450539008582219
_B72 = -0.018270923246702131478062356884535264841652263842597
_B73 = 0.053964399093127498721765893493510877532452806339655
CORRECTORS: dict[int, tuple[tuple[float, float], ...]] = {
    3: ((_A1, _B31), (-_A1, -_B31)),
    5: ((-2 * _A1, -_B51), (-_A1, -_B52), (_A1, _B52), (2 * _A1, _B51)),
    7: (
        (-3 * _A1, -_B71),
        (-2 * _A1, -_B72),
        (-_A1, -_B73),
        (_A1, _B73),
        (2 * _A1, _B72),
        (3 * _A1, _B71),
    ),
}


class RESULTS(diffrax.RESULTS):  # pyright: ignore[reportGeneralTypeIssues]
    """diffrax's result codes, and the Kepler drift's own."""

    kepler_not_converged = (
        "the Kepler drift did not converge for some body (its universal Kepler "
        "equation, bounded iterations): a non-finite state, a body at the star, "
        "or a step far beyond the orbital period"
    )


@runtime_checkable
class GravitatingBodies(Protocol):
    """What Wisdom–Holman needs to know of a system: `masses` (N,), the first
    the dominant one, and the `gravitational_constant` G."""

    masses: jax.Array
    gravitational_constant: jax.Array


# --- Jacobi coordinates -----------------------------------------------------------


def jacobi_matrices(masses: jax.Array) -> tuple[jax.Array, jax.Array]:
    """(A, A⁻¹) with Jacobi positions x̃ = A x (module docstring), from the masses."""
    size = masses.shape[-1]
    interior = jnp.cumsum(masses)  # η_i
    before = jnp.concatenate([jnp.ones((1,), masses.dtype), interior[:-1]])  # η_{i−1}
    row, col = np.indices((size, size))
    # Row i ≥ 1: x_i minus the centre of mass of bodies j < i; row 0: all of it.
    to_jacobi = jnp.where(
        row == 0,
        masses[None, :] / interior[-1],
        jnp.where(row == col, 1.0, 0.0)
        - jnp.where(col < row, masses[None, :] / before[:, None], 0.0),
    )
    # x_i = x̃_0 + (η_{i−1}/η_i) x̃_i − Σ_{k>i} (m_k/η_k) x̃_k.
    to_inertial = jnp.where(
        col == 0,
        1.0,
        jnp.where(
            col > row,
            -masses[None, :] / interior[None, :],
            jnp.where(col == row, before[None, :] / interior[None, :], 0.0),
        ),
    )
    return to_jacobi.astype(masses.dtype), to_inertial.astype(masses.dtype)


def to_jacobi(masses: jax.Array, q: jax.Array, p: jax.Array) -> tuple[Any, Any]:
    """Inertial (q, p), each (N, d), to Jacobi (x̃, p̃): x̃ = A q, p̃ = A⁻ᵀ p."""
    to_jacobi_matrix, to_inertial_matrix = jacobi_matrices(masses)
    return to_jacobi_matrix @ q, to_inertial_matrix.T @ p


def to_inertial(masses: jax.Array, q: jax.Array, p: jax.Array) -> tuple[Any, Any]:
    """Jacobi (x̃, p̃) back to inertial (q, p): q = A⁻¹ x̃, p = Aᵀ p̃."""
    to_jacobi_matrix, to_inertial_matrix = jacobi_matrices(masses)
    return to_inertial_matrix @ q, to_jacobi_matrix.T @ p


def kepler_constants(masses: jax.Array, g: jax.Array) -> tuple[jax.Array, jax.Array]:
    """(m̃, μ): Jacobi masses (m̃_0 = total mass) and each planet's μ_i =
    G m_0 η_i/η_{i−1} (μ_0, unused, is G m_0)."""
    interior = jnp.cumsum(masses)
    before = jnp.concatenate([interior[:1], interior[:-1]])
    jacobi_masses = jnp.where(
        jnp.arange(masses.shape[-1]) == 0, interior[-1], masses * before / interior
    )
    return jacobi_masses, g * masses[0] * interior / before


def _pair_potential(x: jax.Array, masses: jax.Array, pairs: np.ndarray) -> jax.Array:
    """Σ over the marked pairs (i < j) of m_i m_j / r_ij.

    All N² differences by broadcasting and a constant mask: their derivative is a
    broadcast too, where indexing pairs would differentiate into scatters (slow on
    CPU).
    """
    differences = x[:, None, :] - x[None, :, :]
    squared = jnp.sum(differences**2, axis=-1)
    squared = jnp.where(pairs, squared, 1)  # no 1/0 on the diagonal
    products = masses[:, None] * masses[None, :]
    return jnp.sum(jnp.where(pairs, products / jnp.sqrt(squared), 0))


def _inertial_positions(masses: jax.Array, jacobi_q: jax.Array) -> jax.Array:
    """x = A⁻¹ x̃ as a broadcast sum (fuses with what follows, unlike a dot)."""
    to_inertial_matrix = jacobi_matrices(masses)[1]
    return jnp.sum(to_inertial_matrix[:, :, None] * jacobi_q[None, :, :], axis=1)


def interaction_energy(
    jacobi_q: jax.Array, masses: jax.Array, g: jax.Array
) -> jax.Array:
    """H_interaction at the Jacobi positions (module docstring)."""
    size = masses.shape[-1]
    pairs = np.triu(np.ones((size, size), bool), 1)
    pairs[0, 1] = False  # the innermost planet's pull is all Kepler's
    direct = _pair_potential(_inertial_positions(masses, jacobi_q), masses, pairs)
    jacobi_radii = jnp.sqrt(jnp.sum(jacobi_q[2:] ** 2, axis=-1))
    indirect = masses[0] * jnp.sum(masses[2:] / jacobi_radii)
    return g * (indirect - direct)


# --- The terms and the solver -----------------------------------------------------


class KeplerInteractionTerm(diffrax.AbstractTerm):
    r"""N gravitating bodies in Jacobi coordinates, y = (x̃, p̃), each (N, d).

    `vf` is Hamilton's vector field of the whole $H$ (for diffrax's `func`);
    the Wisdom–Holman step uses the two parts separately.
    """

    masses: jax.Array
    gravitational_constant: jax.Array

    def vf(self, t: Any, y: Any, args: Any) -> Any:
        q, p = y
        jacobi_masses, _ = kepler_constants(self.masses, self.gravitational_constant)

        size = self.masses.shape[-1]
        pairs = np.triu(np.ones((size, size), bool), 1)

        def potential(jacobi_q):
            x = _inertial_positions(self.masses, jacobi_q)
            return -self.gravitational_constant * _pair_potential(x, self.masses, pairs)

        return p / jacobi_masses[:, None], -jax.grad(potential)(q)

    def contr(self, t0: Any, t1: Any, **kwargs: Any) -> Any:
        return t1 - t0

    def prod(self, vf: Any, control: Any) -> Any:
        return jax.tree_util.tree_map(lambda v: control * v, vf)

    def drift(self, y: Any, tau: Any) -> tuple[Any, jax.Array]:
        """The flow of H_Kepler for time τ: (y, every body's drift converged)."""
        q, p = y
        jacobi_masses, mu = kepler_constants(self.masses, self.gravitational_constant)
        velocity = p / jacobi_masses[:, None]
        planets, planet_velocity, converged = kepler_drift(
            q[1:], velocity[1:], mu[1:], tau
        )
        centre = q[:1] + tau * velocity[:1]
        new_q = jnp.concatenate([centre, planets])
        new_p = jnp.concatenate([p[:1], planet_velocity * jacobi_masses[1:, None]])
        return (new_q, new_p), jnp.all(converged)

    def drift_kick_sequence(
        self, y: Any, h: Any, drifts: tuple[float, ...], kicks: tuple[float, ...]
    ) -> tuple[Any, jax.Array]:
        """y ↦ K_{k_n h} D_{d_n h} ⋯ K_{k_1 h} D_{d_1 h} y as one `lax.scan` (one
        drift and one kick compiled, however long the sequence); also: every
        drift converged."""
        if not drifts:
            return y, jnp.ones((), bool)

        def pair(carry, coefficients):
            y, converged = carry
            drift, kick = coefficients
            y, ok = self.drift(y, drift * h)
            return (self.kick(y, kick * h), converged & ok), None

        table = jnp.asarray(np.stack([drifts, kicks], axis=-1), dtype=h.dtype)
        (y, converged), _ = jax.lax.scan(pair, (y, jnp.ones((), bool)), table)
        return y, converged

    def kick(self, y: Any, tau: Any) -> Any:
        """The flow of H_interaction for time τ: p̃ −= τ ∂H_interaction/∂x̃."""
        q, p = y
        force = jax.grad(interaction_energy)(
            q, self.masses, self.gravitational_constant
        )
        return q, p - tau * force


class WisdomHolman(diffrax.AbstractSolver):
    r"""Wisdom–Holman splitting for planetary systems (module docstring), in Jacobi
    coordinates, with an optional symplectic corrector.

    Use it through `simulate` with a system of gravitating bodies whose first mass
    dominates (`lagjax.scenes.PlanetarySystem`); `y0` and the saved states are
    the inertial positions and momenta:

    ```python
    solar = lj.scenes.PlanetarySystem()  # HLW's outer solar system
    traj = lj.simulate(solar, solar.initial_state(), t1=1e6, dt=10.0,
                       solver=lj.WisdomHolman(corrector=5))
    ```

    **Arguments:**

    - `corrector`: None (the plain map, error $O(\varepsilon h^2)$), or 3, 5, 7:
      the order $k$ of Wisdom, Holman & Touma's corrector, error
      $O(\varepsilon h^k + \varepsilon^2 h^2)$.

    As a diffrax solver its term is a `KeplerInteractionTerm` and its state the
    Jacobi $(\tilde x, \tilde p)$ (`to_jacobi`); `step` is the synchronised
    drift–kick–drift map without the corrector (`corrected` applies it).
    """

    corrector: int | None = eqx.field(default=None, static=True)

    term_structure: ClassVar = KeplerInteractionTerm
    interpolation_cls: ClassVar[Callable[..., diffrax.LocalLinearInterpolation]] = (
        diffrax.LocalLinearInterpolation
    )

    def __check_init__(self):
        if self.corrector is not None and self.corrector not in CORRECTORS:
            raise ValueError(
                f"WisdomHolman(corrector={self.corrector!r}): the symplectic "
                f"correctors are of order {', '.join(map(str, CORRECTORS))}; pass "
                "one of them, or None for the plain map"
            )

    @property
    def name(self) -> str:
        suffix = "" if self.corrector is None else f"corrector={self.corrector}"
        return f"WisdomHolman({suffix})"

    def order(self, terms: Any) -> int:
        return 2

    def init(self, terms, t0, t1, y0, args) -> None:
        return None

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        h = t1 - t0
        y, first = terms.drift(y0, h / 2)
        y, second = terms.drift(terms.kick(y, h), h / 2)
        result = RESULTS.where(
            first & second,
            RESULTS.successful,  # pyright: ignore[reportArgumentType]
            RESULTS.kepler_not_converged,
        )
        return y, None, dict(y0=y0, y1=y), None, result

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)

    def enter(self, terms: KeplerInteractionTerm, y: Any, h: Any):
        """From real Jacobi coordinates y to the merged loop's u = D_{h/2} C⁻¹(y)
        (`lagjax._integrate.wisdom_holman_run`); also: every drift converged."""
        drifts, kicks = _corrector_pairs(self.corrector, to_mapping=True)
        return terms.drift_kick_sequence(y, h, (*drifts, 0.5), (*kicks, 0.0))

    def leave(self, terms: KeplerInteractionTerm, u: Any, h: Any):
        """Back from u to real Jacobi coordinates, C(D_{−h/2} u); also: every
        drift converged."""
        drifts, kicks = _corrector_pairs(self.corrector, to_mapping=False)
        return terms.drift_kick_sequence(u, h, (-0.5, *drifts), (0.0, *kicks))


def _corrector_pairs(
    order: int | None, to_mapping: bool
) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """C⁻¹ (real to mapping coordinates: the table as printed) or C (b negated)
    as (drift, kick) pairs in units of h: each Z(a, b) = D_a K_{−b} D_{−2a} K_b D_a
    is (a, −b), (−2a, b), (a, 0)."""
    if order is None:
        return (), ()
    sign = 1.0 if to_mapping else -1.0
    drifts, kicks = [], []
    for a, b in CORRECTORS[order]:
        drifts += [a, -2 * a, a]
        kicks += [-sign * b, sign * b, 0.0]
    return tuple(drifts), tuple(kicks)
