r"""The same equations of motion the way one would write them without lagjax.

Three routes to compare lagjax with, for each scene of the work-precision report:

1. **Hand-written**, `Peer.vector_field(xp, y)`: the first-order system for
   $y = (q, \dot q)$ written out by hand once, for `xp = jax.numpy` (integrated with
   `diffrax.diffeqsolve`, as a JAX user would) and for `xp = numpy` (integrated
   with `scipy.integrate.solve_ivp`).
2. **SymPy**: `Peer.sympy_lagrangian(sp, q, qd)` is the scene's L in SymPy;
   `derive_with_sympy` runs `sympy.physics.mechanics.LagrangesMethod`, lambdifies
   the mass matrix and forcing vector, and returns a numpy right-hand side that
   solves $M\ddot q = f$ at every call — the textbook route, timed with its
   derivation.
3. scipy's `solve_ivp` (DOP853; LSODA and Radau for stiff problems) on either.

Each peer reads its parameters and start from the lagjax scene it stands beside, so
the routes integrate the same problem; a route that derived different equations
shows up as an error that does not converge to the reference. Runs are compared
through `comparable(xp, y)` — (q, q̇) for most scenes, (R, ω) for the rigid body,
whose routes use different coordinates. scipy and SymPy are optional: every use is
behind `have_scipy()` / `have_sympy()`.

References: SymPy documentation, `sympy.physics.mechanics` (Lagrange's method);
SciPy documentation, `scipy.integrate.solve_ivp`; Hairer, Lubich & Wanner,
*Geometric Numerical Integration*, §I.5 (Fermi–Pasta–Ulam), §I.2 (Hénon–Heiles).
"""

from __future__ import annotations

import importlib.util
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

Module = Any  # numpy, jax.numpy or sympy: anything with sin, cos, sqrt


def have_scipy() -> bool:
    return importlib.util.find_spec("scipy") is not None


def have_sympy() -> bool:
    return importlib.util.find_spec("sympy") is not None


def _position_velocity(xp: Module, y: Any) -> Any:
    return y


@dataclass(frozen=True)
class Peer:
    """A scene's equations written by hand, and its Lagrangian written in SymPy.

    `initial_state` is the flat y0 of `vector_field`; `sympy_initial` the flat
    (q0, q̇0) of the SymPy route, with `sympy_comparable(xp, y)` mapping its states.
    """

    vector_field: Callable[[Module, Any], Any]
    initial_state: np.ndarray
    sympy_lagrangian: Callable[[Module, list, list], Any] | None = None
    comparable: Callable[[Module, Any], Any] = _position_velocity
    sympy_initial: np.ndarray | None = None
    sympy_comparable: Callable[[Module, Any], Any] = _position_velocity


def _flat(*parts: Any) -> np.ndarray:
    return np.concatenate([np.ravel(np.asarray(p, dtype=float)) for p in parts])


# --- Hand-written equations, one scene each -----------------------------------------


def kepler(scene: Any) -> Peer:
    """q̈ = −μ q/|q|³ (Cartesian, m = 1 drops out)."""
    mu = float(scene.gravitational_parameter)

    def field(xp, y):
        q, v = y[:2], y[2:]
        cube = (q[0] ** 2 + q[1] ** 2) ** 1.5
        return xp.concatenate([v, -mu * q / cube])

    def lagrangian(sp, q, qd):
        return (qd[0] ** 2 + qd[1] ** 2) / 2 + mu / sp.sqrt(q[0] ** 2 + q[1] ** 2)

    q0, p0 = scene.initial_state()
    return Peer(field, _flat(q0, p0 / scene.mass), lagrangian)


def pendulum(scene: Any) -> Peer:
    """θ̈ = −(g/l) sin θ."""
    g, length = float(scene.gravity), float(scene.length)

    def field(xp, y):
        return xp.stack([y[1], -(g / length) * xp.sin(y[0])])

    def lagrangian(sp, q, qd):
        return length**2 * qd[0] ** 2 / 2 + g * length * sp.cos(q[0])

    theta0, p0 = scene.initial_state()
    return Peer(field, _flat(theta0, p0 / (scene.mass * length**2)), lagrangian)


def double_pendulum(scene: Any) -> Peer:
    """The textbook closed form for m₁ = m₂ = 1, l₁ = l₂ = 1 (e.g. Goldstein §1.6)."""
    if not (np.allclose(scene.masses, 1.0) and np.allclose(scene.lengths, 1.0)):
        raise ValueError("the hand-written double pendulum assumes unit masses, rods")
    g = float(scene.gravity)

    def field(xp, y):
        t1, t2, w1, w2 = y[0], y[1], y[2], y[3]
        delta = t1 - t2
        den = 2.0 - xp.cos(delta) ** 2
        a1 = (
            -xp.sin(delta) * (w2**2 + w1**2 * xp.cos(delta))
            - g * (2.0 * xp.sin(t1) - xp.sin(t2) * xp.cos(delta))
        ) / den
        a2 = (
            2.0 * xp.sin(delta) * w1**2
            + xp.sin(delta) * xp.cos(delta) * w2**2
            + 2.0 * g * (xp.sin(t1) * xp.cos(delta) - xp.sin(t2))
        ) / den
        return xp.stack([w1, w2, a1, a2])

    def lagrangian(sp, q, qd):
        kinetic = qd[0] ** 2 + qd[1] ** 2 / 2 + qd[0] * qd[1] * sp.cos(q[0] - q[1])
        return kinetic + g * (2 * sp.cos(q[0]) + sp.cos(q[1]))

    return Peer(field, _flat(*scene.initial_state()), lagrangian)


def henon_heiles(scene: Any) -> Peer:
    """ẍ = −x − 2xy, ÿ = −y − x² + y²."""

    def field(xp, y):
        x, z, vx, vz = y[0], y[1], y[2], y[3]
        return xp.stack([vx, vz, -x - 2 * x * z, -z - x**2 + z**2])

    def lagrangian(sp, q, qd):
        x, z = q
        potential = (x**2 + z**2) / 2 + x**2 * z - z**3 / 3
        return (qd[0] ** 2 + qd[1] ** 2) / 2 - potential

    return Peer(field, _flat(*scene.initial_state()), lagrangian)


def fermi_pasta_ulam(scene: Any) -> Peer:
    """Unit masses; forces from the stiff pairs and the quartic springs (walls at 0)."""
    omega, size = float(scene.frequency), 2 * scene.pairs

    def field(xp, y):
        q, v = y[:size], y[size:]
        stiff = q[1::2] - q[0::2]
        walled = xp.concatenate([xp.zeros(1), q, xp.zeros(1)])
        soft = walled[1::2] - walled[0::2]
        # ∂V/∂q: each spring pulls its two ends in opposite directions.
        stiff_grad = xp.stack([-stiff, stiff], axis=-1).reshape(-1) * omega**2 / 2
        soft_grad = xp.stack([-4 * soft**3, 4 * soft**3], axis=-1).reshape(-1)
        return xp.concatenate([v, -(stiff_grad + soft_grad[1:-1])])

    def lagrangian(sp, q, qd):
        walled = [0, *q, 0]
        stiff = sum((q[2 * i + 1] - q[2 * i]) ** 2 for i in range(size // 2))
        soft = sum(
            (walled[2 * i + 1] - walled[2 * i]) ** 4 for i in range(size // 2 + 1)
        )
        return sum(v**2 for v in qd) / 2 - omega**2 / 4 * stiff - soft

    return Peer(field, _flat(*scene.initial_state()), lagrangian)


def foucault(scene: Any) -> Peer:
    """Newton in the Earth's frame with the rod's tension as a Lagrange multiplier.

    r̈ = a − λr with a = −2ω×ṙ − ω×(ω×r) − g ẑ, and |r| = l fixes λ through
    r·r̈ + |ṙ|² = 0.
    """
    lat, rate = float(scene.latitude), float(scene.earth_rate)
    g, length = float(scene.gravity), float(scene.length)
    omega = rate * np.array([-np.cos(lat), 0.0, np.sin(lat)])

    def cross(xp, a, b):
        return xp.stack(
            [
                a[1] * b[2] - a[2] * b[1],
                a[2] * b[0] - a[0] * b[2],
                a[0] * b[1] - a[1] * b[0],
            ]
        )

    def field(xp, y):
        x, z_east, vx, vy = y[0], y[1], y[2], y[3]
        height = -xp.sqrt(length**2 - x**2 - z_east**2)
        r = xp.stack([x, z_east, height])
        v = xp.stack([vx, vy, -(x * vx + z_east * vy) / height])
        w, down = xp.asarray(omega), xp.asarray([0.0, 0.0, g])
        free = -2 * cross(xp, w, v) - cross(xp, w, cross(xp, w, r)) - down
        tension = (xp.sum(v * v) + xp.sum(r * free)) / length**2
        return xp.stack([vx, vy, free[0] - tension * r[0], free[1] - tension * r[1]])

    def lagrangian(sp, q, qd):
        height = -sp.sqrt(length**2 - q[0] ** 2 - q[1] ** 2)
        r = sp.Matrix([q[0], q[1], height])
        v = sp.Matrix([qd[0], qd[1], -(q[0] * qd[0] + q[1] * qd[1]) / height])
        inertial = v + sp.Matrix(omega.tolist()).cross(r)
        return inertial.dot(inertial) / 2 - g * height

    return Peer(field, _flat(*scene.initial_state()), lagrangian)


def _euler_zxz_omega(xp: Module, angles: Any, rates: Any) -> list:
    """Body angular velocity from z-x-z Euler angles (Goldstein eq. 4.87)."""
    _, theta, psi = angles
    phi_dot, theta_dot, psi_dot = rates
    return [
        phi_dot * xp.sin(theta) * xp.sin(psi) + theta_dot * xp.cos(psi),
        phi_dot * xp.sin(theta) * xp.cos(psi) - theta_dot * xp.sin(psi),
        phi_dot * xp.cos(theta) + psi_dot,
    ]


def free_rigid_body(scene: Any) -> Peer:
    """Euler's equations Π̇ = Π × ω with q̇ = ½ q ⊗ (0, ω); SymPy in Euler angles."""
    from lagjax.rigid.euler_angles import euler_zxz_to_rotation

    moments = np.asarray(scene.moments, dtype=float)

    def field(xp, y):
        qw, qx, qy, qz = y[0], y[1], y[2], y[3]
        pi = y[4:]
        om = pi / xp.asarray(moments)
        spin = xp.stack(
            [
                pi[1] * om[2] - pi[2] * om[1],
                pi[2] * om[0] - pi[0] * om[2],
                pi[0] * om[1] - pi[1] * om[0],
            ]
        )
        q_rate = 0.5 * xp.stack(
            [
                -qx * om[0] - qy * om[1] - qz * om[2],
                qw * om[0] + qy * om[2] - qz * om[1],
                qw * om[1] + qz * om[0] - qx * om[2],
                qw * om[2] + qx * om[1] - qy * om[0],
            ]
        )
        return xp.concatenate([q_rate, spin])

    def comparable(xp, y):
        from lagjax.rigid.quaternion import quaternion_to_matrix

        rotation = quaternion_to_matrix(jnp.asarray(y[:4]))
        return jnp.concatenate([rotation.ravel(), jnp.asarray(y[4:]) / moments])

    def lagrangian(sp, q, qd):
        omega = _euler_zxz_omega(sp, q, qd)
        return sum(i * w**2 for i, w in zip(moments.tolist(), omega)) / 2

    def sympy_comparable(xp, y):
        rotation = euler_zxz_to_rotation(jnp.asarray(y[:3]))
        omega = jnp.stack(_euler_zxz_omega(jnp, y[:3], y[3:]))
        return jnp.concatenate([rotation.ravel(), omega])

    quaternion, momentum = scene.initial_body_state()
    return Peer(
        field,
        _flat(quaternion, momentum),
        lagrangian,
        comparable,
        _flat(*scene.initial_state()),
        sympy_comparable,
    )


# --- Integrating a peer -----------------------------------------------------------


def diffrax_final(peer: Peer, solver: Any, t1: float, rtol: float, ts: Any = None):
    """y0 → comparable final state (or states at `ts`): diffeqsolve, PID control."""
    term = diffrax.ODETerm(lambda t, y, args: peer.vector_field(jnp, y))
    saveat = diffrax.SaveAt(t1=True) if ts is None else diffrax.SaveAt(ts=ts)

    def run(y0):
        solution = diffrax.diffeqsolve(
            term,
            solver,
            0.0,
            t1,
            None,
            y0,
            saveat=saveat,
            stepsize_controller=diffrax.PIDController(rtol=rtol, atol=rtol),
            max_steps=10**6,
        )
        states = jax.vmap(lambda y: peer.comparable(jnp, y))(solution.ys)
        return states[-1] if ts is None else states

    return run


@dataclass(frozen=True)
class NumpyRoute:
    """A numpy right-hand side f(t, y), its start and its comparable-state map."""

    rhs: Callable[[float, np.ndarray], np.ndarray]
    initial_state: np.ndarray
    comparable: Callable[[Module, Any], Any]
    derivation_seconds: float = 0.0


def hand_written_numpy(peer: Peer) -> NumpyRoute:
    return NumpyRoute(
        lambda t, y: peer.vector_field(np, y), peer.initial_state, peer.comparable
    )


def scipy_run(route: NumpyRoute, t1: float, method: str, rtol: float):
    """A no-argument callable: `solve_ivp` on the route; states at every step."""
    from scipy.integrate import solve_ivp

    def run():
        solution = solve_ivp(
            route.rhs,
            (0.0, t1),
            route.initial_state,
            method=method,
            rtol=rtol,
            atol=rtol,
        )
        if not solution.success:
            raise RuntimeError(f"solve_ivp {method}: {solution.message}")
        return solution.y.T

    return run


def lagranges_equations(
    lagrangian: Callable[[Module, list, list], Any], size: int
) -> tuple[Any, list, list]:
    """SymPy's `LagrangesMethod` for L(sp, q, q̇), its equations formed.

    Returns (method, [x, v], substitutions): plain symbols for q and q̇, to
    lambdify with, and the substitutions that put them in place of q and q̇.
    """
    import sympy as sp
    from sympy.physics.mechanics import LagrangesMethod, dynamicsymbols

    q = list(dynamicsymbols(f"q1:{size + 1}"))
    qd = [coordinate.diff(dynamicsymbols._t) for coordinate in q]
    method = LagrangesMethod(lagrangian(sp, q, qd), q)
    method.form_lagranges_equations()
    x, v = sp.symbols(f"x0:{size}"), sp.symbols(f"v0:{size}")
    plain = list(zip(qd, v)) + list(zip(q, x))  # derivatives first
    return method, [x, v], plain


def derive_with_sympy(
    lagrangian: Callable[[Module, list, list], Any], size: int
) -> tuple[Callable[[float, np.ndarray], np.ndarray], float]:
    """(numpy f(t, y) with y = (q, q̇), seconds to derive and lambdify) via SymPy.

    `LagrangesMethod` gives M(q, q̇) q̈ = f(q, q̇); both are lambdified and q̈ is
    found by a numeric solve at every call. Solving symbolically (`rhs()`) instead
    swells the expressions and takes far longer for more than two coordinates.
    """
    import sympy as sp
    import sympy.physics.mechanics  # loaded before the clock starts

    start = time.perf_counter()
    method, symbols, plain = lagranges_equations(lagrangian, size)
    mass = sp.lambdify(symbols, method.mass_matrix.subs(plain), "numpy")
    forcing = sp.lambdify(symbols, method.forcing.subs(plain), "numpy")
    seconds = time.perf_counter() - start

    def rhs(t, y):
        position, velocity = y[:size], y[size:]
        matrix = np.asarray(mass(position, velocity), dtype=float).reshape(size, size)
        force = np.asarray(forcing(position, velocity), dtype=float).reshape(size)
        return np.concatenate([velocity, np.linalg.solve(matrix, force)])

    return rhs, seconds


def sympy_numpy(peer: Peer) -> NumpyRoute:
    """The SymPy route for a peer (it must have a `sympy_lagrangian`)."""
    assert peer.sympy_lagrangian is not None
    start = peer.initial_state if peer.sympy_initial is None else peer.sympy_initial
    rhs, seconds = derive_with_sympy(peer.sympy_lagrangian, start.size // 2)
    return NumpyRoute(rhs, start, peer.sympy_comparable, seconds)
