r"""The chaotic double pendulum's finite-time Lyapunov exponent, method by method.

From rest at θ = (2, 2.5) rad (`DoublePendulum`), the largest finite-time Lyapunov
exponent over T = 10 s,

$$ \lambda_T = \frac1T \sum_{k=1}^{T/\tau} \ln\lVert \Phi'_\tau(y_{k-1})\,v_{k-1}\rVert,
   \qquad v_k = \frac{\Phi'_\tau(y_{k-1})\,v_{k-1}}{\lVert\cdot\rVert}, $$

is computed by Benettin's method: the tangent vector v is carried along the
trajectory by `jax.jvp` through `lj.simulate` (diffrax's `ForwardMode` adjoint for
the adaptive solvers; lagjax's fixed-step solvers run as a `lax.scan` and need
none) and renormalised every τ = 0.5 s, with the norm of the flat state
(θ₁, θ₂, θ̇₁, θ̇₂). The same number is estimated independently from two trajectories
δ = 10⁻⁸ apart, renormalised the same way (the finite difference of the flow
instead of its derivative).

Over 10 s a separation grows by e^{λT} ≈ 5·10⁸, so the trajectory itself is only
reproducible by methods accurate to ~10⁻¹²: λ_T is a property of the trajectory,
and a method that loses it reports another trajectory's exponent. Each tangent
estimate is compared with the two-trajectory estimate on Dopri8 at rtol = 10⁻¹³
(the reference; the tangent estimate on that same integrator, in the
full table, isolates the linearisation); the last row is the spread
(max − min)/λ of the accurate estimates and the reference. The energy error is
that of the states at the renormalisation times.

Measured (full table): λ₁₀ = 1.99349 s⁻¹. GaussLegendre(3) at h = 0.005, Tsit5 at
rtol 10⁻¹⁰ and Dopri8 agree with the two-trajectory estimate to 6·10⁻⁴ (Tsit5 sets
that spread; the others are within 3·10⁻⁵), and the tangent and two-trajectory
estimates on the same integrator to 5·10⁻⁷. GaussLegendre(2) at the scene's
h = 0.0025 is 4·10⁻³ off; VariationalMidpoint at h = 10⁻³ (second order) loses the
trajectory and reports λ = 1.71.

References: Benettin, Galgani, Giorgilli & Strelcyn, Meccanica 15, 9 and 21 (1980)
(Lyapunov exponents by tangent maps, with renormalisation); Shimada & Nagashima,
Prog. Theor. Phys. 61, 1605 (1979); Ott, *Chaos in Dynamical Systems*, 2nd ed., §4.4.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import diffrax
import jax
import jax.numpy as jnp

import lagjax as lj
from benchmarks.stability_engine import Attempt, Measured, judged_row
from lagjax import diagnostics
from lagjax.scenes.pendulums import DoublePendulum

SEPARATION = 1e-8  # of the two-trajectory estimate
TWIN = Attempt("two trajectories", diffrax.Dopri8(), rtol=1e-13)  # its integrator


def _advance(scene: DoublePendulum, attempt: Attempt, segment: float, dt):
    """The flow over one segment, on the flat state (θ₁, θ₂, θ̇₁, θ̇₂)."""
    adaptive = attempt.steps is None

    def advance(state: jax.Array) -> jax.Array:
        moved = lj.simulate(
            scene, (state[:2], state[2:]), t1=segment, dt=dt, solver=attempt.solver,
            rtol=attempt.rtol, atol=attempt.rtol,
            adjoint=diffrax.ForwardMode() if adaptive else None,
        )  # fmt: skip
        return jnp.concatenate([moved.q[-1], moved.qdot[-1]])

    return advance


def _benettin(advance: Callable, segments: int, twin: bool):
    """state0 ↦ (ln-growth per segment, states at the segment ends)."""

    def grow(state, direction):
        if twin:
            moved = advance(state)
            apart = advance(state + SEPARATION * direction) - moved
            return moved, apart / SEPARATION
        return jax.jvp(advance, (state,), (direction,))

    def segment(carry, _):
        state, direction = carry
        state, stretched = grow(state, direction)
        length = jnp.linalg.norm(stretched)
        return (state, stretched / length), (jnp.log(length), state)

    def run(state0):
        direction = jnp.full(4, 0.5)  # a generic unit vector
        return jax.lax.scan(segment, (state0, direction), None, length=segments)[1]

    return run


@dataclass
class LyapunovStudy:
    """λ_T by tangent propagation per attempt, and by two nearby trajectories."""

    attempts: list[Attempt]
    horizon: float = 10.0
    segment: float = 0.5
    tolerance: float = 1e-3
    name: str = field(init=False)

    def __post_init__(self):
        self.name = f"double pendulum FTLE, T = {self.horizon:g} s"

    def rows(self, timing: dict) -> Iterator[dict]:
        scene = DoublePendulum()
        state0 = jnp.concatenate(scene.initial_state())
        twin = self._estimator(scene, TWIN, twin=True)
        timed = diagnostics.time_run(twin, state0, repeats=1, warmup=0)
        reference = float(jnp.sum(timed.output[0])) / self.horizon
        # (λ, run s, compile s) of every estimate the spread covers
        accurate = [(reference, timed.run_seconds, timed.compile_seconds)]
        exponents: dict[str, float] = {}

        def measure(attempt: Attempt) -> Measured:
            measured, exponent = self._measure(scene, attempt, reference)
            exponents[attempt.label] = exponent
            return measured

        for attempt in self.attempts:
            row = judged_row(self.name, attempt.label, self.tolerance,
                             lambda attempt=attempt: measure(attempt))  # fmt: skip
            if row["outcome"] == "accurate":
                costs = (row["run_s"], row["compile_s"])
                accurate.append((exponents[attempt.label], *costs))
            yield row
        method = "spread: accurate rows and two trajectories"
        yield judged_row(self.name, method, self.tolerance,
                         lambda: _spread(accurate, reference))  # fmt: skip

    def _estimator(self, scene, attempt: Attempt, twin: bool):
        segments = round(self.horizon / self.segment)
        dt = None if attempt.steps is None else self.horizon / attempt.steps
        return _benettin(_advance(scene, attempt, self.segment, dt), segments, twin)

    def _measure(
        self, scene, attempt: Attempt, reference: float
    ) -> tuple[Measured, float]:
        state0 = jnp.concatenate(scene.initial_state())
        estimate = self._estimator(scene, attempt, twin=False)
        timed = diagnostics.time_run(estimate, state0, repeats=1, warmup=0)
        logs, states = timed.output
        exponent = float(jnp.sum(logs)) / self.horizon
        energies = jax.vmap(lambda y: scene.system().energy(y[:2], y[2:], 0.0, scene))(
            jnp.concatenate([state0[None], states])
        )
        measured = Measured(
            abs(exponent / reference - 1),
            timed.run_seconds,
            timed.compile_seconds,
            float(diagnostics.energy_error(energies)),
            f"λ = {exponent:.7f} s⁻¹ (two trajectories: {reference:.7f})",
        )
        return measured, exponent


def _spread(estimates: list[tuple[float, float, float]], reference: float) -> Measured:
    """(max − min)/λ_ref over the accurate estimates and the two-trajectory one;
    its cost is theirs, summed."""
    if len(estimates) < 2:
        raise ValueError("no accurate tangent estimate to compare")
    exponents, run_s, compile_s = (list(column) for column in zip(*estimates))
    return Measured(
        (max(exponents) - min(exponents)) / abs(reference),
        sum(run_s),
        sum(compile_s),
        measure=f"λ from {min(exponents):.7f} to {max(exponents):.7f} s⁻¹ "
        f"({len(exponents)} estimates)",
    )


def lyapunov_study(quick: bool) -> LyapunovStudy:
    """Quick: Dopri8 against the two-trajectory estimate."""
    attempts = [
        Attempt("GaussLegendre(2), h = 0.0025", lj.GaussLegendre(stages=2), steps=4000, in_quick=False),
        Attempt("GaussLegendre(3), h = 0.005", lj.GaussLegendre(stages=3), steps=2000, in_quick=False),
        Attempt("VariationalMidpoint, h = 0.001", lj.VariationalMidpoint(), steps=10_000, in_quick=False),
        Attempt("Tsit5, rtol 1e-10", diffrax.Tsit5(), rtol=1e-10, in_quick=False),
        Attempt("Dopri8, rtol 1e-12", diffrax.Dopri8(), rtol=1e-12),
        Attempt("Dopri8, rtol 1e-13", diffrax.Dopri8(), rtol=1e-13, in_quick=False),
    ]  # fmt: skip
    return LyapunovStudy([a for a in attempts if a.in_quick or not quick])
