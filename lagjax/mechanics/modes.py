r"""Small oscillations about equilibrium, gyroscopic systems included.

Near an equilibrium $q_0$ the Lagrangian is, to second order in $\eta = q - q_0$,

$$ L \approx \tfrac12\dot\eta^T M\dot\eta + \dot\eta^T C\eta - \tfrac12\eta^T K\eta,
   \qquad M = \frac{\partial^2L}{\partial\dot q^2},\;
   C = \frac{\partial^2L}{\partial\dot q\,\partial q},\;
   K = -\frac{\partial^2L}{\partial q^2}, $$

all at $(q_0, \dot q = 0)$ (the course text calls M and K "T" and "V"). The symmetric
part of C is a total time derivative; its antisymmetric part $G = C - C^T$ is the
**gyroscopic** matrix — Coriolis forces in a rotating frame, the magnetic part of a
velocity-dependent potential $e\mathbf A\cdot\dot{\mathbf r}$, the spin of a top —
and the linearized equations of motion are

$$ M\ddot\eta + G\dot\eta + K\eta = 0. $$

**Without G** (the course text §5): the generalized symmetric eigenproblem
$K a_k = \omega_k^2 M a_k$, $A^T M A = 1$, solved by the Cholesky factor
$M = LL^T$: $L^{-1}KL^{-T}u = \omega^2u$, $a = L^{-T}u$.

**With G**: in the coordinates $x = L^T\eta$, $\ddot x + \hat G\dot x + \hat Kx = 0$
with $\hat G = L^{-1}GL^{-T}$ antisymmetric, and the first-order matrix
$\begin{pmatrix}0 & 1\\ -\hat K & -\hat G\end{pmatrix}$ has eigenvalues in
quadruples $\pm\lambda, \pm\bar\lambda$ (a Hamiltonian spectrum). Each mode takes one
eigenvalue of each pair $\lambda = \gamma + i\omega$: $\omega > 0$ for an
oscillation (possibly growing, $\gamma \ne 0$, after a Krein collision such as
Routh's at L4), or a real $\lambda = \gamma$ for a purely exponential mode. Its
shape $a$ is complex — the motion is $\mathrm{Re}(a\,e^{\lambda t})$, an ellipse in
general — normalised to $a^H M a = 1$ with its largest component real and positive.
Gyroscopic forces can stabilise a maximum of the potential (the sleeping top, L4)
and split degenerate frequencies (the Foucault pendulum by $\omega_E\sin\varphi$, a
charge in a field by $\omega_c$).

References: the course text §5 (eq. 5.12–5.25) and §1.4; Goldstein, *Classical
Mechanics* §6.2; Meirovitch, *Methods of Analytical Dynamics* (1970), §6.4–6.6;
Thomson & Tait, *Treatise on Natural Philosophy* §345 (gyroscopic stability).
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import optimistix as optx
from jax.flatten_util import ravel_pytree

from lagjax.mechanics import stability
from lagjax.mechanics.constrained_modes import reduce_to_constraint_surface
from lagjax.mechanics.lagrangian import Lagrangian
from lagjax.mechanics.lagrangian_argument import as_lagrangian

# ‖Ĝ‖ below this fraction of √‖K̂‖ (both in mass-normalised coordinates, 1/time)
# counts as no gyroscopic coupling: its first-order effect on the frequencies is
# then below this relative size.
GYROSCOPIC_RTOL = 1e-10


def _potential_gradient(lag: Lagrangian, q: Any, t: Any, args: Any) -> Any:
    """∂V/∂q = −∂L/∂q at q̇ = 0."""
    zero_velocity = jax.tree_util.tree_map(jnp.zeros_like, q)
    gradient = jax.grad(lag, argnums=0)(q, zero_velocity, t, args)
    return jax.tree_util.tree_map(jnp.negative, gradient)


def equilibrium(
    lag: Lagrangian,
    q_guess: Any,
    args: Any = None,
    *,
    t: Any = 0.0,
    rtol: float = 1e-12,
    atol: float = 1e-12,
    max_steps: int = 256,
) -> Any:
    """A configuration with ∂V/∂q = 0, found by Newton's method from `q_guess`.

    Any stationary point of V can be returned (minimum, saddle or maximum): the one
    Newton's method reaches from the guess. Classify it with `normal_modes`.
    Raises if Newton's method does not converge. For rotating frames, forces and
    constraints see `relative_equilibrium`.
    """
    lag, args = as_lagrangian(lag, args, "equilibrium")
    q_flat, unravel = ravel_pytree(q_guess)

    def residual(x, _):
        return ravel_pytree(_potential_gradient(lag, unravel(x), t, args))[0]

    solution = optx.root_find(
        residual, optx.Newton(rtol=rtol, atol=atol), q_flat, max_steps=max_steps
    )
    return unravel(solution.value)


@eqx.filter_jit  # nested derivatives dispatched op by op cost seconds
def stiffness_matrices(
    lag: Lagrangian, q_eq: Any, args: Any = None, *, t: Any = 0.0
) -> tuple[jax.Array, jax.Array]:
    """The (T, V) = (M, K) matrices of the small-oscillation problem at `q_eq`."""
    q_flat, unravel = ravel_pytree(q_eq)
    zero_velocity = jnp.zeros_like(q_flat)
    kinetic = lag.mass_matrix(q_eq, unravel(zero_velocity), t, args)
    potential = -jax.hessian(
        lambda x: lag(unravel(x), unravel(zero_velocity), t, args)
    )(q_flat)
    return kinetic, potential


@eqx.filter_jit  # nested derivatives dispatched op by op cost seconds
def gyroscopic_matrix(
    lag: Lagrangian, q_eq: Any, args: Any = None, *, t: Any = 0.0
) -> jax.Array:
    r"""$G = C - C^T$, $C = \partial^2L/\partial\dot q\,\partial q$ at $(q_0, 0)$."""
    q_flat, unravel = ravel_pytree(q_eq)
    zero_velocity = unravel(jnp.zeros_like(q_flat))

    def momentum(x):
        return ravel_pytree(lag.momentum(unravel(x), zero_velocity, t, args))[0]

    mixed = jax.jacfwd(momentum)(q_flat)
    return mixed - mixed.T


class NormalModes(eqx.Module):
    r"""What `normal_modes` returns; it unpacks as `omegas, modes = ...`.

    - `omegas` (n,), ascending: the frequency ω of each oscillating mode, and −γ for
      a purely exponential mode $e^{\gamma t}$ (so a negative entry marks an
      unstable direction, as in the course text's ω² < 0).
    - `modes` (n, n), mode k in column k, in the raveled coordinates of q: real and
      normalised to $A^TMA = 1$ without gyroscopic terms; complex (motion
      $\mathrm{Re}(a_k e^{\lambda_k t})$) and normalised to $a_k^HMa_k = 1$ with them.
    - `eigenvalues` (n,), complex: $\lambda_k = \gamma_k + i\omega_k$ of each mode.
    - `stability` (n,), int: 0 stable, 1 marginal, 2 unstable (see
      `lagjax.mechanics.stability`); `labels()` and `verdict()` give words.
    - `gyroscopic`: whether the first-order (gyroscopic) path was taken.
    """

    omegas: jax.Array
    modes: jax.Array
    eigenvalues: jax.Array
    stability: jax.Array
    gyroscopic: bool = eqx.field(static=True)

    def __iter__(self) -> Iterator[jax.Array]:
        return iter((self.omegas, self.modes))

    @property
    def growth_rates(self) -> jax.Array:
        """γ = Re λ of each mode (e-folding rate; ± pairs for conservative systems)."""
        return jnp.real(self.eigenvalues)

    def labels(self) -> tuple[str, ...]:
        """'stable', 'marginal' or 'unstable' per mode (concrete values only)."""
        return stability.labels(self.stability)

    def verdict(self) -> str:
        """'unstable' if any mode grows, else 'marginal' if any is neutral, else
        'stable' — linear (spectral) stability only."""
        return stability.verdict(self.stability)


def _congruence(cholesky: jax.Array, matrix: jax.Array) -> jax.Array:
    """L⁻¹ X L⁻ᵀ for the lower Cholesky factor L."""
    half = jsl.solve_triangular(cholesky, matrix, lower=True)
    return jsl.solve_triangular(cholesky, half.T, lower=True).T


@jax.jit
def _symmetric_modes(cholesky, stiffness) -> NormalModes:
    """The T/V path: an eigh of the symmetric, mass-normalised stiffness."""
    reduced = _congruence(cholesky, stiffness)
    # Symmetrise: the two triangular solves leave round-off asymmetry.
    squared, vectors = jnp.linalg.eigh(0.5 * (reduced + reduced.T))
    modes = jsl.solve_triangular(cholesky.T, vectors, lower=False)
    omegas = jnp.sign(squared) * jnp.sqrt(jnp.abs(squared))
    root = jnp.sqrt(jnp.abs(squared)).astype(jnp.result_type(squared, 1j))
    eigenvalues = jnp.where(squared >= 0, 1j * root, root)
    codes = stability.classify(eigenvalues, conservative=True)
    return NormalModes(omegas, modes, eigenvalues, codes, gyroscopic=False)


@jax.jit
def _gyroscopic_modes(cholesky, stiffness, gyro) -> NormalModes:
    """The first-order path: eig of [[0, 1], [−K̂, −Ĝ]], one eigenvalue per pair."""
    n = stiffness.shape[0]
    k_hat = _congruence(cholesky, stiffness)
    g_hat = _congruence(cholesky, gyro)
    first_order = jnp.block(
        [[jnp.zeros((n, n)), jnp.eye(n)], [-0.5 * (k_hat + k_hat.T), -g_hat]]
    )
    values, vectors = jnp.linalg.eig(first_order)
    # Pick every eigenvalue with Im > 0 and, among the real ones, the larger half
    # by Re: one λ from each ± / conjugate pair of the Hamiltonian spectrum.
    imag_floor = 1e-14 * jnp.max(jnp.abs(values))
    category = jnp.where(
        values.imag > imag_floor, 2, jnp.where(values.imag < -imag_floor, 0, 1)
    )
    chosen = jnp.lexsort((-values.real, -category))[:n]
    lam, x = values[chosen], vectors[:n, chosen]
    oscillating = category[chosen] == 2
    omegas = jnp.where(oscillating, lam.imag, -jnp.abs(lam.real))
    order = jnp.argsort(omegas)
    omegas, lam, x = omegas[order], lam[order], x[:, order]
    # η = L⁻ᵀx, so ηᴴMη = xᴴx: unit x is M-normalised η.
    x = x / jnp.linalg.norm(x, axis=0, keepdims=True)
    modes = jsl.solve_triangular(cholesky.T, x, lower=False)
    biggest = jnp.take_along_axis(
        modes, jnp.argmax(jnp.abs(modes), axis=0)[None, :], axis=0
    )
    modes = modes * (jnp.abs(biggest) / biggest)
    codes = stability.classify(lam, conservative=True)
    return NormalModes(omegas, modes, lam, codes, gyroscopic=True)


class _Expansion(NamedTuple):
    cholesky: jax.Array
    potential: jax.Array
    gyro: jax.Array
    residual: jax.Array
    norms: tuple[jax.Array, jax.Array]
    basis: jax.Array | None
    surface_residual: jax.Array | None


# Compiled as a whole: op-by-op dispatch of the nested derivatives costs seconds.
@eqx.filter_jit
def _expansion(lag: Lagrangian, q_eq: Any, args: Any, t: Any) -> _Expansion:
    """M, K, G at q_eq (reduced to the constraint surface if there is one), the
    residual generalized force, and the norms of the mass-normalised K and G."""
    q_flat, unravel = ravel_pytree(q_eq)
    kinetic, potential = stiffness_matrices(lag, q_eq, args, t=t)
    gyro = gyroscopic_matrix(lag, q_eq, args, t=t)
    acceleration = lag.acceleration(q_eq, unravel(jnp.zeros_like(q_flat)), t, args)
    residual = kinetic @ ravel_pytree(acceleration)[0]
    basis = surface_residual = None
    if lag.constraints is not None:
        (kinetic, potential, gyro), basis, surface_residual = (
            reduce_to_constraint_surface(lag, q_eq, args, t, (kinetic, potential, gyro))
        )
        residual = basis.T @ residual  # the normal part is the constraint force
    cholesky = _positive_cholesky(kinetic)
    norms = (
        jnp.linalg.norm(_congruence(cholesky, potential)),
        jnp.linalg.norm(_congruence(cholesky, gyro)),
    )
    return _Expansion(
        cholesky, potential, gyro, residual, norms, basis, surface_residual
    )


def _refuse_no_coordinates(q_eq: Any) -> None:
    if ravel_pytree(q_eq)[0].size == 0:
        raise ValueError(
            "q_eq has no coordinates (size 0): normal modes need at least one; pass "
            "the equilibrium with one entry per coordinate, e.g. jnp.array([0.0])"
        )


def _refuse_unsupported(lag: Lagrangian) -> None:
    """Trace-time refusal of systems whose small oscillations are not M, G, K."""
    if lag.force is not None or lag.dissipation is not None:
        raise ValueError(
            "normal_modes describes conservative small oscillations, but this "
            "Lagrangian has a generalized force or a dissipation function, which "
            "would be ignored. Use lj.linearize(lag, (q_eq, qdot_eq), args) for the "
            "eigenvalues with damping and forcing, or drop force/dissipation for the "
            "undamped modes."
        )


def _positive_cholesky(kinetic: jax.Array) -> jax.Array:
    cholesky = jnp.linalg.cholesky(kinetic)
    return eqx.error_if(
        cholesky,
        ~jnp.all(jnp.isfinite(cholesky)),
        "The kinetic matrix T = ∂²L/∂q̇∂q̇ at q_eq is not positive definite, so the "
        "small oscillations have no normal modes there.",
    )


def _choose_gyroscopic(gyroscopic, k_hat_norm, g_hat_norm):
    """(take the first-order path?, is G negligible?) from the user's choice."""
    negligible = g_hat_norm <= GYROSCOPIC_RTOL * jnp.sqrt(k_hat_norm)
    if gyroscopic is None and stability.is_concrete(negligible):
        return not bool(negligible), negligible
    return bool(gyroscopic), negligible


_GYRO_MESSAGE = (
    "∂²L/∂q̇∂q has an antisymmetric (gyroscopic: Coriolis, magnetic, spin) part at "
    "q_eq, which the T/V normal-mode problem would ignore. Call "
    "normal_modes(..., gyroscopic=True) (inside jax.jit the detection cannot branch)."
)


def normal_modes(
    lag: Lagrangian,
    q_eq: Any,
    args: Any = None,
    *,
    t: Any = 0.0,
    gyroscopic: bool | None = None,
    check_equilibrium: bool = True,
    equilibrium_tol: float = stability.EQUILIBRIUM_TOL,
) -> NormalModes:
    r"""Normal-mode frequencies and shapes about the equilibrium `q_eq`.

    **Arguments:**
    - `lag`, `q_eq`, `args`, `t`: the system and the point (a pytree like q).
    - `gyroscopic`: None (default) detects the antisymmetric part G of
      $\partial^2L/\partial\dot q\partial q$ from the values and takes the
      first-order path when it is present; True forces that path; False forces the
      T/V path and raises if G is not negligible. Inside `jax.jit` the values are
      not known at trace time: None then takes the T/V path with a run-time error
      if G is present, so the gyroscopic terms are never dropped silently.
    - `check_equilibrium`: refuse (True, default) a point where the residual
      generalized force $\partial L/\partial q - \frac{d}{dt}\frac{\partial
      L}{\partial\dot q}$ at $\dot q = 0$ does not vanish; `equilibrium_tol` is the
      displacement it may correspond to, relative to |q_eq| (absolute below 1).

    **Returns:** a `NormalModes`, which unpacks as `omegas, modes` (see it for the
    conventions: ω ascending, −γ for exponential modes; modes real and
    T-normalised, `modes.T @ T @ modes = I`, without gyroscopic terms).

    Holonomic constraints are honoured: the modes live on the constraint surface
    (`lagjax.mechanics.constrained_modes`; fewer modes than coordinates, shapes in
    the full coordinates). Forces, dissipation and velocity constraints are refused
    with a pointer to `linearize`. A scene whose system is a Lagrangian is taken
    with itself as `args`; a Hamiltonian, a rigid body or a plain function is
    refused by name, with the way to get a Lagrangian (`ham.to_lagrangian()`).
    """
    lag, args = as_lagrangian(lag, args, "normal_modes")
    _refuse_no_coordinates(q_eq)
    _refuse_unsupported(lag)
    q_flat = ravel_pytree(q_eq)[0]
    expansion = _expansion(lag, q_eq, args, t)
    cholesky, potential, gyro = expansion[:3]
    if check_equilibrium and expansion.surface_residual is not None:
        cholesky = stability.check_stationary(
            cholesky,
            expansion.surface_residual,
            jnp.asarray(1.0),
            q_flat,
            tol=equilibrium_tol,
            what="constraint residual g(q_eq) (the point is off the surface)",
            remedy="Start from a point that satisfies the constraints.",
        )
    if check_equilibrium:
        cholesky = stability.check_stationary(
            cholesky,
            expansion.residual,
            jnp.linalg.norm(potential),
            q_flat,
            tol=equilibrium_tol,
            what="residual generalized force ∂L/∂q − d/dt ∂L/∂q̇ at q̇ = 0",
            remedy="Find the equilibrium first (lj.equilibrium or "
            "lj.relative_equilibrium), or pass check_equilibrium=False to expand "
            "about this point anyway.",
        )
    use_first_order, negligible = _choose_gyroscopic(gyroscopic, *expansion.norms)
    if use_first_order:
        return _in_full_coordinates(
            _gyroscopic_modes(cholesky, potential, gyro), expansion.basis
        )
    if stability.is_concrete(negligible):
        if not bool(negligible):
            raise ValueError(
                _GYRO_MESSAGE.split(" Call")[0] + " Pass gyroscopic=True (or None)."
            )
    else:
        cholesky = eqx.error_if(cholesky, ~negligible, _GYRO_MESSAGE)
    return _in_full_coordinates(_symmetric_modes(cholesky, potential), expansion.basis)


def _in_full_coordinates(result: NormalModes, basis: jax.Array | None) -> NormalModes:
    """Mode shapes a = N a_r in the raveled coordinates of q (constrained systems)."""
    if basis is None:
        return result
    return eqx.tree_at(lambda r: r.modes, result, basis @ result.modes)
