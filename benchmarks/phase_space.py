r"""Phase-space tools at scale: Hénon–Heiles chaos by MEGNO, spectra, sections.

1. **Chaotic fraction.** A uniform grid of starting points $(y, p_y)$ on the
   surface x = 0 at E = 1/12, 1/8, 1/6 ($p_x > 0$ from H = E), MEGNO ⟨Y⟩ of every
   orbit at t = `MEGNO_T`; an orbit counts as chaotic when ⟨Y⟩ > `CHAOTIC_Y`
   (regular orbits sit at ⟨Y⟩ ≤ 2 + O(ln t / t), chaotic ones at ~λt/2). The
   fraction is of the section's area, Hénon & Heiles' own measure.
2. **Cost of a 10⁴-orbit MEGNO grid** (`jax.vmap` of `lj.megno`, one jit), with
   its per orbit-step figure.
3. **The Lyapunov spectrum** of the chaotic orbit from (x, y, p_y) = (0, −0.1, 0) at
   E = 1/6 over a long horizon: the largest exponent, the two zeros, the pairing.
4. **Cross-check with the stability suite:** the double pendulum's largest
   finite-time exponent over 10 s from `lj.lyapunov_spectrum` (its first basis
   column the suite's direction) against two trajectories 10⁻⁸ apart on Dopri8 at
   rtol 10⁻¹³ (`benchmarks/stability_lyapunov.py` reports λ₁₀ = 1.99349).
5. **Sections of 10⁴ orbits** against a scipy `solve_ivp` (DOP853 at rtol 10⁻⁹,
   event location) loop over a sample of the same orbits, per orbit.

Run: `python -m benchmarks.phase_space [--quick] [--out DIR]` (writes
phase_space.json in DIR).

References: Hénon & Heiles, Astron. J. 69, 73 (1964); Cincotta & Simó, Astron.
Astrophys. Suppl. Ser. 147, 205 (2000); Benettin et al., Meccanica 15, 9 (1980).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import scipy.integrate

import lagjax as lj
from lagjax.phase_space import (
    henon_heiles,
    henon_heiles_section_states,
    section_plane,
)
from lagjax.phase_space.henon_heiles import henon_heiles_potential
from lagjax.scenes.pendulums import DoublePendulum

jax.config.update("jax_enable_x64", True)

ENERGIES = {"1/12": 1 / 12, "1/8": 1 / 8, "1/6": 1 / 6}
DT, MEGNO_T, CHAOTIC_Y = 0.05, 1000.0, 4.0
OPTIONS = dict(dt=DT, solver=lj.Yoshida4(), renormalize_every=0.5)
SHELL_SHARE = 0.5  # of the (y, p_y) box inside the E = 1/8 shell, a little less
# Near Yoshida4's accuracy at h = 0.05 (energy to ~1e-7): a like-for-like timing.
SCIPY_RTOL = 1e-9


def shell_grid(energy: float, side: int):
    """A side × side grid over the section's (y, p_y) box, kept on the shell."""
    bound = np.sqrt(2 * energy)
    ys = np.linspace(-0.6, 1.0, side)  # covers the E = 1/6 section
    return henon_heiles_section_states(energy, ys, np.linspace(-bound, bound, side))


def megno_grid(states, t1: float) -> tuple[np.ndarray, float, float]:
    """⟨Y⟩ of every state, compile seconds and run seconds."""
    system = henon_heiles()

    def one(q0, p0):
        return lj.megno(system, (q0, p0), t1, **OPTIONS)

    q0s, p0s = jnp.asarray(states[0]), jnp.asarray(states[1])
    start = time.perf_counter()
    compiled = jax.jit(jax.vmap(one)).lower(q0s, p0s).compile()
    compile_seconds = time.perf_counter() - start
    start = time.perf_counter()
    values = np.asarray(jax.block_until_ready(compiled(q0s, p0s)))
    return values, compile_seconds, time.perf_counter() - start


def chaotic_fractions(side: int, t1: float) -> dict:
    rows = {}
    for label, energy in ENERGIES.items():
        states = shell_grid(energy, side)
        values, _, run = megno_grid(states, t1)
        rows[label] = dict(
            orbits=len(values),
            chaotic_fraction=float(np.mean(values > CHAOTIC_Y)),
            median_megno_regular=float(np.median(values[values <= CHAOTIC_Y])),
            run_s=run,
        )
        print(f"E = {label}: {len(values)} orbits, chaotic fraction "
              f"{rows[label]['chaotic_fraction']:.3f} (⟨Y⟩ > {CHAOTIC_Y} at t = "
              f"{t1:g}), {run:.1f} s")  # fmt: skip
    return rows


def grid_cost(orbits: int, t1: float) -> dict:
    side = int(np.ceil(np.sqrt(orbits / SHELL_SHARE)))
    states = shell_grid(1 / 8, side)
    states = tuple(x[:orbits] for x in states)
    values, compile_s, run_s = megno_grid(states, t1)
    steps = len(values) * t1 / DT
    row = dict(orbits=len(values), t1=t1, compile_s=compile_s, run_s=run_s,
               ns_per_orbit_step=1e9 * run_s / steps)  # fmt: skip
    print(f"MEGNO grid: {len(values)} orbits × {t1 / DT:.0f} steps: {run_s:.1f} s "
          f"run ({row['ns_per_orbit_step']:.0f} ns per orbit-step), "
          f"{compile_s:.1f} s compile")  # fmt: skip
    return row


def chaotic_spectrum(t1: float) -> dict:
    states = henon_heiles_section_states(1 / 6, [-0.1], [0.0])
    y0 = jax.tree_util.tree_map(lambda x: jnp.asarray(x[0]), states)
    start = time.perf_counter()
    spectrum = lj.lyapunov_spectrum(henon_heiles(), y0, t1, dt=DT,
                                    solver=lj.Yoshida4(), renormalize_every=1.0)  # fmt: skip
    exponents = np.asarray(spectrum.exponents)
    half = np.asarray(spectrum.running[len(spectrum.ts) // 2])
    row = dict(t1=t1, exponents=exponents.tolist(), at_half_t1=half.tolist(),
               max_abs_sum=float(jnp.max(jnp.abs(spectrum.running.sum(axis=1)))),
               seconds=time.perf_counter() - start)  # fmt: skip
    print(
        f"HH E = 1/6 spectrum over t = {t1:g}: {np.round(exponents, 5)} "
        f"(t1/2: {np.round(half, 5)}); max |sum| {row['max_abs_sum']:.1e}"
    )
    return row


def double_pendulum_check() -> dict:
    scene = DoublePendulum()
    q0, qdot0 = scene.initial_state()
    direction = jnp.full(4, 0.5)
    # An orthonormal basis whose first column is the suite's tangent direction.
    basis, _ = jnp.linalg.qr(jnp.column_stack([direction, jnp.eye(4)[:, :3]]))
    basis = basis * jnp.sign(basis[:, :1].T @ direction)
    spectrum = lj.lyapunov_spectrum(
        scene, (q0, qdot0), 10.0, dt=0.005, solver=lj.GaussLegendre(stages=3),
        renormalize_every=0.5, basis=basis,
    )  # fmt: skip
    largest_first_column = float(spectrum.running[-1, 0])

    def advance(state):
        run = lj.simulate(scene, (state[:2], state[2:]), t1=0.5,
                          solver=diffrax.Dopri8(), rtol=1e-13, atol=1e-13)  # fmt: skip
        return jnp.concatenate([run.q[-1], run.qdot[-1]])

    state, log_sum = jnp.concatenate([q0, qdot0]), 0.0
    for _ in range(20):
        moved = advance(state)
        apart = (advance(state + 1e-8 * direction) - moved) / 1e-8
        log_sum += float(jnp.log(jnp.linalg.norm(apart)))
        state, direction = moved, apart / jnp.linalg.norm(apart)
    twin = log_sum / 10.0
    row = dict(spectrum_largest=largest_first_column, two_trajectories=twin,
               relative_difference=abs(largest_first_column / twin - 1),
               exponents=np.asarray(spectrum.exponents).tolist())  # fmt: skip
    print(
        f"double pendulum λ₁₀: spectrum {largest_first_column:.5f}, two "
        f"trajectories {twin:.5f} (relative {row['relative_difference']:.1e})"
    )
    return row


def _scipy_section(state: np.ndarray, t1: float) -> np.ndarray:
    """Times of the upward x = 0 crossings of one orbit: DOP853 with event location.

    The start, on the plane, is not a crossing (scipy reports it at t = 0).
    """

    def rate(_, y):
        x, yy, px, py = y
        return [px, py, -x - 2 * x * yy, -yy - x**2 + yy**2]

    def plane(_, y):
        return y[0]

    plane.direction = 1.0
    solution = scipy.integrate.solve_ivp(rate, (0.0, t1), state, method="DOP853",
                                         events=plane, rtol=SCIPY_RTOL, atol=SCIPY_RTOL)  # fmt: skip
    times = solution.t_events[0]
    return times[times > 1e-9]


def _energy_error_at_crossings(section, energy: float) -> float:
    kinetic = 0.5 * np.sum(np.asarray(section.p) ** 2, axis=-1)
    potential = np.asarray(jax.vmap(jax.vmap(henon_heiles_potential))(section.q))
    stored = np.isfinite(np.asarray(section.ts))
    return float(np.max(np.abs(kinetic + potential - energy)[stored]))


def _scipy_comparison(q0s, p0s, section, t1: float, sample: int) -> dict:
    """scipy's time per orbit, and its crossings against lagjax's on a sample."""
    states = np.concatenate([q0s, p0s], axis=1)[:sample]
    start = time.perf_counter()
    scipy_times = [_scipy_section(state, t1) for state in states]
    per_orbit = (time.perf_counter() - start) / len(states)
    counts = np.asarray([len(times) for times in scipy_times])
    # The first crossings, before chaos separates the two integrations.
    early = max(
        float(np.max(np.abs(times[:3] - np.asarray(section.ts[k, :3]))))
        for k, times in enumerate(scipy_times)
    )
    return dict(
        scipy_per_orbit_ms=1e3 * per_orbit,
        crossing_counts_agree=float(
            np.mean(counts == np.asarray(section.count[:sample]))
        ),
        first_crossings_max_dt=early,
    )


def section_cost(orbits: int, t1: float, scipy_sample: int) -> dict:
    side = int(np.ceil(np.sqrt(orbits / SHELL_SHARE)))
    q0s, p0s = (x[:orbits] for x in shell_grid(1 / 8, side))
    system = henon_heiles()

    def run():
        return jax.block_until_ready(lj.poincare_section(
            system, (jnp.asarray(q0s), jnp.asarray(p0s)), t1, section_plane, dt=DT,
            solver=lj.Yoshida4(), max_crossings=int(t1 / 4),
        ))  # fmt: skip

    start = time.perf_counter()
    run()
    first = time.perf_counter() - start
    start = time.perf_counter()
    section = run()
    warm = time.perf_counter() - start
    row = dict(orbits=len(q0s), t1=t1, lagjax_s=warm, lagjax_first_call_s=first,
               lagjax_per_orbit_ms=1e3 * warm / len(q0s),
               energy_error=_energy_error_at_crossings(section, 1 / 8),
               **_scipy_comparison(q0s, p0s, section, t1, scipy_sample))  # fmt: skip
    row["ratio"] = row["scipy_per_orbit_ms"] / row["lagjax_per_orbit_ms"]
    print(
        f"section of {len(q0s)} orbits to t = {t1:g}: {warm:.1f} s warm "
        f"({first:.1f} s first call), {row['lagjax_per_orbit_ms']:.2f} ms/orbit; "
        f"scipy DOP853 (rtol {SCIPY_RTOL:g}) + events "
        f"{row['scipy_per_orbit_ms']:.1f} ms/orbit (ratio {row['ratio']:.0f}×); "
        f"crossing counts agree on {100 * row['crossing_counts_agree']:.0f}% of the "
        f"sample, first three times to {row['first_crossings_max_dt']:.1e}; energy "
        f"at the crossings to {row['energy_error']:.1e}"
    )
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes")
    parser.add_argument("--out", type=Path, default=None)
    options = parser.parse_args()
    quick = options.quick
    report = dict(
        chaotic_fraction=chaotic_fractions(side=20 if quick else 60,
                                           t1=200.0 if quick else MEGNO_T),
        megno_grid=grid_cost(orbits=500 if quick else 10_000,
                             t1=200.0 if quick else MEGNO_T),
        spectrum=chaotic_spectrum(t1=2_000.0 if quick else 50_000.0),
        double_pendulum=double_pendulum_check(),
        sections=section_cost(orbits=500 if quick else 10_000,
                              t1=200.0 if quick else 1_000.0,
                              scipy_sample=5 if quick else 20),
    )  # fmt: skip
    if options.out is not None:
        options.out.mkdir(parents=True, exist_ok=True)
        (options.out / "phase_space.json").write_text(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
