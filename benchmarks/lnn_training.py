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
- `lagjax`: `lj.Lagrangian(net).acceleration` (scalar formulation for ≤ 6
  coordinates; under a trace a singular mass matrix gives NaN, at no cost);
- `dense-solve` (diagnostic): the published formulation with a linear solve in place
  of pinv, to separate the cost of the pseudo-inverse (an SVD) from the derivation;
- `lagjax-dense` (diagnostic): lagjax's dense formulation (`_dense_system`, one
  Jacobian of the gradient and one JVP) with LU, which the library uses above
  `SCALAR_COORDINATE_LIMIT` coordinates;
- `fused-hvp`: `lagjax.neural.network_acceleration`, the least work a network-sized
  L needs: one gradient and n + 1 Hessian-vector products batched in one
  forward-over-reverse pass.

Targets are the double pendulum's exact accelerations (m = l = 1, g = 9.81) at
random states. Compile time is reported apart; run time is the median of repeats,
the variants alternated within each repeat (the machine is shared and noisy: the
ratios are the result).

References: M. Cranmer, S. Greydanus, S. Hoyer, P. Battaglia, D. Spergel, S. Ho,
"Lagrangian Neural Networks", ICLR 2020 Workshop (arXiv:2003.04630), eq. (6).

Run: `python -m benchmarks.lnn_training [--batch B] [--width W] [--repeats R]`.
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
from lagjax.demo import handwritten_acceleration  # noqa: E402
from lagjax.mechanics.euler_lagrange import _dense_system  # noqa: E402
from lagjax.mechanics.linalg import solve_dense  # noqa: E402
from lagjax.neural import network_acceleration  # noqa: E402


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


def lagjax_acceleration(lagrangian, q, qdot):
    """lagjax's derived Euler–Lagrange acceleration (default `check`)."""
    return lj.Lagrangian(lagrangian).acceleration(q, qdot)


def lagjax_dense_acceleration(lagrangian, q, qdot):
    """lagjax's dense formulation (used above SCALAR_COORDINATE_LIMIT), LU solve."""
    mass, rhs = _dense_system(lambda a, b, t: lagrangian(a, b), q, qdot, 0.0 * q[0])
    return solve_dense(mass, rhs)[0]


VARIANTS = {
    "cranmer": cranmer_acceleration,
    "lagjax": lagjax_acceleration,
    "dense-solve": dense_solve_acceleration,
    "lagjax-dense": lagjax_dense_acceleration,
    "fused-hvp": network_acceleration,
}


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


def double_pendulum_batch(key, batch: int):
    """Random double-pendulum states and their exact accelerations."""
    key_q, key_v = jax.random.split(key)
    q = jax.random.uniform(key_q, (batch, 2), minval=-jnp.pi, maxval=jnp.pi)
    qdot = jax.random.normal(key_v, (batch, 2))
    target = jax.vmap(handwritten_acceleration)(q, qdot)
    return q, qdot, target


def run(batch: int, width: int, repeats: int, variants=tuple(VARIANTS)) -> dict:
    network = make_network(jax.random.key(0), width=width)
    inputs = (network, *double_pendulum_batch(jax.random.key(1), batch))
    compiled, compile_s, values = {}, {}, {}
    for name in variants:
        start = time.perf_counter()
        compiled[name] = training_step(VARIANTS[name])
        loss, grads = jax.block_until_ready(compiled[name](*inputs))
        compile_s[name] = time.perf_counter() - start
        values[name] = (loss, grads)
    times: dict[str, list[float]] = {name: [] for name in variants}
    for _ in range(repeats):
        for name in variants:  # alternated: the machine is shared
            start = time.perf_counter()
            jax.block_until_ready(compiled[name](*inputs))
            times[name].append(time.perf_counter() - start)
    reference_loss, reference_grads = values[variants[0]]
    agreement = {}
    for name in variants:
        loss, grads = values[name]
        flat_ref = jax.tree_util.tree_leaves(eqx.filter(reference_grads, eqx.is_array))
        flat = jax.tree_util.tree_leaves(eqx.filter(grads, eqx.is_array))
        scale = max(float(jnp.max(jnp.abs(g))) for g in flat_ref)
        gap = max(float(jnp.max(jnp.abs(a - b))) for a, b in zip(flat, flat_ref))
        agreement[name] = (abs(float(loss - reference_loss)), gap / scale)
    median = {name: statistics.median(times[name]) for name in variants}
    return dict(compile_s=compile_s, median_s=median, agreement=agreement)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=256)
    parser.add_argument("--width", type=int, default=128)
    parser.add_argument("--repeats", type=int, default=30)
    options = parser.parse_args()
    result = run(options.batch, options.width, options.repeats)
    base = result["median_s"]["cranmer"]
    print(
        f"LNN training step, double pendulum, batch {options.batch}, "
        f"MLP 4-{options.width}-{options.width}-1 softplus, "
        f"{jax.devices()[0].platform}, median of {options.repeats}"
    )
    print(
        f"{'variant':14s} {'compile s':>10s} {'step ms':>9s} {'speed-up':>9s}"
        f" {'|Δloss|':>9s} {'grad rel gap':>13s}"
    )
    for name, median in result["median_s"].items():
        loss_gap, grad_gap = result["agreement"][name]
        print(
            f"{name:14s} {result['compile_s'][name]:10.2f} {1e3 * median:9.3f} "
            f"{base / median:8.2f}x {loss_gap:9.1e} {grad_gap:13.1e}"
        )


if __name__ == "__main__":
    main()
