r"""One Lagrangian-neural-network training step: lagjax's derived q̈ against Cranmer's.

A Lagrangian neural network (Cranmer et al. 2020) is an MLP $L_\theta(q, \dot q)$;
its prediction is the Euler–Lagrange acceleration, published as

$$ \ddot q = (\nabla_{\dot q}\nabla_{\dot q}^T L)^{+}\,
   [\nabla_q L - (\nabla_q\nabla_{\dot q}^T L)\,\dot q] $$

with `jax.hessian` and the pseudo-inverse `jnp.linalg.pinv`. One training step is the
loss (mean squared error of the predicted q̈ against targets over a batch of states)
and its gradient with respect to the weights. The same `eqx.nn.MLP`, batch and loss
are timed with

- `cranmer`: the published formulation (hessian, jacobian of the gradient, pinv);
- `lagjax`: `lj.Lagrangian(net).acceleration`: a Module with array leaves takes the
  network formulation (`lagjax.mechanics.network_formulation`: one gradient and
  n + 1 Hessian–vector products in one forward-over-reverse pass, an LU solve;
  under a trace a singular mass matrix gives NaN, at the cost of one select);
- `fused-hvp`: `lagjax.mechanics.neural.network_acceleration`, the same products and solve
  without the check — the bare prediction;
- diagnostics: `closed-form` (`formulation="closed_form"`, the scalar formulation
  built for formula Lagrangians, which sends each scalar tangent through the whole
  network; only with `--closed-form`: it compiles for minutes), `dense-solve` (the
  published formula with `solve` for `pinv`: the pseudo-inverse's cost),
  `lagjax-dense` (one Jacobian of the gradient and one JVP, LU), `fwd-fwd`
  (forward-over-forward second derivatives, nested `jacfwd`), and `mlp-by-hand`:
  the Hessian of this particular MLP written out by hand, $H = \sum_l J_l^T
  \mathrm{diag}(\sigma''(z_l)\,\bar a_l) J_l$ (a forward pass carrying the three
  needed Jacobian columns, one backward pass for the adjoints $\bar a_l$) — not a
  general method, the reference for what any formulation could gain.

**The work, counted.** The step is dominated by products of the 128×128 hidden
matrix with batches of vectors; one such product over the batch is a *unit*
(2·256·128² = 8.4 MFLOP). Forward-over-reverse q̈ needs per state 1 primal + 1
reverse + (n + 1) tangent + (n + 1) tangent-reverse products = 8 units at n = 2; the
gradient with respect to the weights then costs each product twice more (its input
adjoint and its weight gradient): ~24 units. The published route takes ~41 (XLA's
own count, printed as MFLOP). The hand-derived MLP Hessian needs 1 + (n + 1) + 1 =
5 forward units (the fewest found), ~15 with the gradient. Even if the gradient
cost only the weight gradients of those 5 products (no input adjoints at all) — 10
units, 84 MFLOP — the published step's 348 MFLOP would bound the gain at ~4×: the
issue's 5× is out of reach with the same network, batch and precision, and the
measured ceiling is the hand-derived row (1.9×; 1.5× for the general formulation).
(Also tried: a custom VJP by the adjoint of q̈'s linear system — the gradient as
one mixed second derivative λᵀ∂F/∂θ — 4 % fewer FLOPs but 4.5× slower, its
per-state weight gradients materialised under `vmap`.)

Targets are the double pendulum's exact accelerations (m = l = 1, g = 9.81) at
random states. Compile time is reported apart; run time is the median of repeats,
the variants alternated within each repeat; `--clock cpu` times process CPU
(robust on a loaded machine). The ratios are the result.

References: M. Cranmer, S. Greydanus, S. Hoyer, P. Battaglia, D. Spergel, S. Ho,
"Lagrangian Neural Networks", ICLR 2020 Workshop (arXiv:2003.04630), eq. (6);
B. A. Pearlmutter, "Fast exact multiplication by the Hessian" (1994).

Run: `python -m benchmarks.lnn_training [--batch B] [--width W] [--repeats R]
[--clock cpu] [--closed-form]`.
"""

from __future__ import annotations

import argparse
import statistics
import time

import jax

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import lagjax as lj  # noqa: E402
from benchmarks.kepler_saved import CLOCKS  # noqa: E402
from lagjax._linalg.small_solves import solve_dense  # noqa: E402
from lagjax.cli.demo import handwritten_acceleration  # noqa: E402
from lagjax.mechanics.euler_lagrange import dense_system  # noqa: E402
from lagjax.mechanics.neural import network_acceleration  # noqa: E402


class LagrangianMLP(eqx.Module):
    """L(q, q̇) = MLP([q, q̇]) → scalar: the network of an LNN."""

    mlp: eqx.nn.MLP

    def __call__(self, q, qdot):
        return self.mlp(jnp.concatenate([q, qdot]))


def make_network(key, coordinates: int = 2, width: int = 128, depth: int = 2):
    """Softplus MLP, as in Cranmer et al. (smooth: its Hessian is not zero)."""
    mlp = eqx.nn.MLP(
        2 * coordinates, "scalar", width, depth, activation=jax.nn.softplus, key=key
    )
    return LagrangianMLP(mlp)


def cranmer_acceleration(lagrangian, q, qdot):
    """The published LNN acceleration: hessian, mixed Jacobian, pseudo-inverse."""
    mass = jax.hessian(lagrangian, argnums=1)(q, qdot)
    mixed = jax.jacobian(jax.jacobian(lagrangian, argnums=1), argnums=0)(q, qdot)
    force = jax.grad(lagrangian, argnums=0)(q, qdot)
    return jnp.linalg.pinv(mass) @ (force - mixed @ qdot)


def dense_solve_acceleration(lagrangian, q, qdot):
    """The published formulation with `jnp.linalg.solve` instead of pinv."""
    mass = jax.hessian(lagrangian, argnums=1)(q, qdot)
    mixed = jax.jacobian(jax.jacobian(lagrangian, argnums=1), argnums=0)(q, qdot)
    force = jax.grad(lagrangian, argnums=0)(q, qdot)
    return jnp.linalg.solve(mass, force - mixed @ qdot)


def forward_forward_acceleration(lagrangian, q, qdot):
    """Second derivatives forward-over-forward (nested `jacfwd`), LU solve."""
    mass = jax.jacfwd(jax.jacfwd(lagrangian, argnums=1), argnums=1)(q, qdot)
    mixed = jax.jacfwd(jax.jacfwd(lagrangian, argnums=1), argnums=0)(q, qdot)
    force = jax.grad(lagrangian, argnums=0)(q, qdot)
    return jnp.linalg.solve(mass, force - mixed @ qdot)


def lagjax_acceleration(lagrangian, q, qdot):
    """lagjax's derived Euler–Lagrange acceleration (default `check`)."""
    return lj.Lagrangian(lagrangian).acceleration(q, qdot)


def closed_form_acceleration(lagrangian, q, qdot):
    """lagjax's formulation for formula Lagrangians (scalar for ≤ 6 coordinates)."""
    return lj.Lagrangian(lagrangian, formulation="closed_form").acceleration(q, qdot)


def lagjax_dense_acceleration(lagrangian, q, qdot):
    """lagjax's dense formulation (used above SCALAR_COORDINATE_LIMIT), LU solve."""
    mass, rhs = dense_system(lambda a, b, t: lagrangian(a, b), q, qdot, 0.0 * q[0])
    return solve_dense(mass, rhs)[0]


def mlp_by_hand_acceleration(lagrangian, q, qdot):
    """q̈ of a `LagrangianMLP` with softplus from its Hessian written out by hand.

    For z_l = W_l a_{l-1} + b_l, a_l = σ(z_l) and a linear output, the Hessian of L
    in the input directions D is Σ_l (J_l D)ᵀ diag(σ''(z_l) ā_l) (J_l D), J_l = ∂z_l/∂x
    and ā_l = ∂L/∂a_l (one backward pass); D = [(0, e_1), …, (0, e_n), (q̇, 0)].
    """
    layers, n = lagrangian.mlp.layers, q.shape[0]
    directions = (
        jnp.concatenate(
            [
                jnp.concatenate([jnp.zeros((n, n)), jnp.eye(n)], axis=1),
                jnp.zeros((1, 2 * n)),
            ]
        )
        .at[n, :n]
        .set(qdot)
    )
    activation, jacobian = jnp.concatenate([q, qdot]), directions.T
    pre, columns = [], []
    for layer in layers[:-1]:
        z, dz = layer.weight @ activation + layer.bias, layer.weight @ jacobian
        pre.append(z)
        columns.append(dz)
        activation, jacobian = jax.nn.softplus(z), jax.nn.sigmoid(z)[:, None] * dz
    adjoint, hessian = layers[-1].weight[0], jnp.zeros((n + 1, n + 1))
    for z, dz, layer in zip(pre[::-1], columns[::-1], layers[-2::-1]):
        slope = jax.nn.sigmoid(z)
        hessian = hessian + dz.T @ ((adjoint * slope * (1 - slope))[:, None] * dz)
        adjoint = layer.weight.T @ (adjoint * slope)
    return jnp.linalg.solve(hessian[:n, :n], adjoint[:n] - hessian[:n, n])


VARIANTS = {
    "cranmer": cranmer_acceleration,
    "lagjax": lagjax_acceleration,
    "fused-hvp": network_acceleration,
    "dense-solve": dense_solve_acceleration,
    "lagjax-dense": lagjax_dense_acceleration,
    "fwd-fwd": forward_forward_acceleration,
    "mlp-by-hand": mlp_by_hand_acceleration,
    "closed-form": closed_form_acceleration,
}
DEFAULT_VARIANTS = tuple(name for name in VARIANTS if name != "closed-form")


def acceleration_loss(acceleration, network, q, qdot, target):
    """Mean squared error of the predicted q̈ over a batch of states."""
    predicted = jax.vmap(lambda a, b: acceleration(network, a, b))(q, qdot)
    return jnp.mean((predicted - target) ** 2)


def training_step(acceleration):
    """(loss, gradient w.r.t. the weights) of one batch: the LNN training step."""

    @eqx.filter_jit
    def step(network, q, qdot, target):
        return eqx.filter_value_and_grad(
            lambda net: acceleration_loss(acceleration, net, q, qdot, target)
        )(network)

    return step


def compiled_step(acceleration, network, batch):
    """The training step compiled for this network and batch, and XLA's FLOP count."""
    weights, structure = eqx.partition(network, eqx.is_array)

    def step(weights, q, qdot, target):
        return eqx.filter_value_and_grad(
            lambda w: acceleration_loss(
                acceleration, eqx.combine(w, structure), q, qdot, target
            )
        )(weights)

    compiled = jax.jit(step).lower(weights, *batch).compile()
    cost = compiled.cost_analysis()
    cost = cost[0] if isinstance(cost, list) else cost
    return (lambda: compiled(weights, *batch)), float(cost.get("flops", "nan"))


def double_pendulum_batch(key, batch: int):
    """Random double-pendulum states and their exact accelerations."""
    key_q, key_v = jax.random.split(key)
    q = jax.random.uniform(key_q, (batch, 2), minval=-jnp.pi, maxval=jnp.pi)
    qdot = jax.random.normal(key_v, (batch, 2))
    target = jax.vmap(handwritten_acceleration)(q, qdot)
    return q, qdot, target


def _relative_gap(grads, reference) -> float:
    flat_ref = jax.tree_util.tree_leaves(reference)
    scale = max(float(jnp.max(jnp.abs(g))) for g in flat_ref)
    gaps = [
        jnp.max(jnp.abs(a - b))
        for a, b in zip(jax.tree_util.tree_leaves(grads), flat_ref)
    ]
    return max(float(g) for g in gaps) / scale


def run(
    batch: int,
    width: int,
    repeats: int,
    variants=DEFAULT_VARIANTS,
    clock=time.perf_counter,
) -> dict:
    network = make_network(jax.random.key(0), width=width)
    data = double_pendulum_batch(jax.random.key(1), batch)
    steps, compile_s, flops, values = {}, {}, {}, {}
    for name in variants:
        start = time.perf_counter()
        steps[name], flops[name] = compiled_step(VARIANTS[name], network, data)
        values[name] = jax.block_until_ready(steps[name]())
        compile_s[name] = time.perf_counter() - start
    times: dict[str, list[float]] = {name: [] for name in variants}
    for _ in range(repeats):
        for name in variants:  # alternated: the machine is shared
            start = clock()
            jax.block_until_ready(steps[name]())
            times[name].append(clock() - start)
    reference_loss, reference_grads = values[variants[0]]
    agreement = {
        name: (
            abs(float(values[name][0] - reference_loss)),
            _relative_gap(values[name][1], reference_grads),
        )
        for name in variants
    }
    median = {name: statistics.median(times[name]) for name in variants}
    return dict(compile_s=compile_s, median_s=median, agreement=agreement, flops=flops)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=256)
    parser.add_argument("--width", type=int, default=128)
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--clock", choices=sorted(CLOCKS), default="wall")
    parser.add_argument("--closed-form", action="store_true")
    options = parser.parse_args()
    variants = tuple(VARIANTS) if options.closed_form else DEFAULT_VARIANTS
    result = run(
        options.batch, options.width, options.repeats, variants, CLOCKS[options.clock]
    )
    base, base_flops = result["median_s"]["cranmer"], result["flops"]["cranmer"]
    unit = 2 * options.batch * options.width**2  # one hidden matrix over the batch
    print(
        f"LNN training step, double pendulum, batch {options.batch}, "
        f"MLP 4-{options.width}-{options.width}-1 softplus, "
        f"{jax.devices()[0].platform}, {options.clock} clock, median of "
        f"{options.repeats}; units of {unit / 1e6:.1f} MFLOP"
    )
    print(
        f"{'variant':13s} {'compile s':>9s} {'step ms':>8s} {'speed-up':>8s} "
        f"{'MFLOP':>7s} {'units':>6s} {'FLOP ratio':>10s} {'|Δloss|':>8s} {'grad gap':>8s}"
    )
    for name, median in result["median_s"].items():
        loss_gap, grad_gap = result["agreement"][name]
        flops = result["flops"][name]
        print(
            f"{name:13s} {result['compile_s'][name]:9.2f} {1e3 * median:8.2f} "
            f"{base / median:7.2f}x {flops / 1e6:7.1f} {flops / unit:6.1f} "
            f"{base_flops / flops:9.2f}x {loss_gap:8.1e} {grad_gap:8.1e}"
        )


if __name__ == "__main__":
    main()
