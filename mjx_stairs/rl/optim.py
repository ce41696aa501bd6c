"""Adam with bias correction, global-norm clipping and the KL-adaptive learning rate (no optax).

The optimiser state is a NamedTuple pytree, so it jits, shards (replicated) and checkpoints like
the params. The learning rate lives in the state because the adaptive schedule changes it on
device between minibatches.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

Params = Any


class AdamState(NamedTuple):
    """count: [] int32 steps taken; mu, nu: first/second moments shaped like the params;
    lr: [] float32 current learning rate."""

    count: jax.Array
    mu: Params
    nu: Params
    lr: jax.Array


def adam_init(params: Params, lr: float) -> AdamState:
    zeros = jax.tree_util.tree_map(jnp.zeros_like, params)
    return AdamState(
        count=jnp.zeros((), jnp.int32),
        mu=zeros,
        nu=jax.tree_util.tree_map(jnp.zeros_like, params),
        lr=jnp.asarray(lr, jnp.float32),
    )


def global_norm(tree: Params) -> jax.Array:
    """sqrt of the sum of squares of every leaf: []."""
    leaves = jax.tree_util.tree_leaves(tree)
    return jnp.sqrt(sum(jnp.sum(jnp.square(x)) for x in leaves))


def clip_by_global_norm(grads: Params, max_norm: float) -> tuple[Params, jax.Array]:
    """Scale grads by min(1, max_norm / norm) (torch.nn.utils.clip_grad_norm_); returns the
    clipped grads and the norm before clipping. max_norm <= 0 disables clipping."""
    norm = global_norm(grads)
    if max_norm <= 0:
        return grads, norm
    scale = jnp.minimum(1.0, max_norm / (norm + 1e-6))
    return jax.tree_util.tree_map(lambda g: g * scale, grads), norm


def adam_update(
    grads: Params,
    state: AdamState,
    params: Params,
    b1: float = 0.9,
    b2: float = 0.999,
    eps: float = 1e-8,
) -> tuple[Params, AdamState]:
    """One Adam step (torch.optim.Adam semantics) at ``state.lr``:
    m = b1 m + (1 - b1) g;  v = b2 v + (1 - b2) g^2;  p -= lr * m_hat / (sqrt(v_hat) + eps)."""
    count = state.count + 1
    t = count.astype(jnp.float32)
    mu = jax.tree_util.tree_map(lambda m, g: b1 * m + (1.0 - b1) * g, state.mu, grads)
    nu = jax.tree_util.tree_map(lambda v, g: b2 * v + (1.0 - b2) * g * g, state.nu, grads)
    c1 = 1.0 - b1**t
    c2 = 1.0 - b2**t
    lr = state.lr

    def step(p, m, v):
        return p - lr * (m / c1) / (jnp.sqrt(v / c2) + eps)

    new_params = jax.tree_util.tree_map(step, params, mu, nu)
    return new_params, AdamState(count=count, mu=mu, nu=nu, lr=lr)


def adapt_lr(
    lr: jax.Array,
    kl: jax.Array,
    target_kl: float,
    min_lr: float = 1e-5,
    max_lr: float = 1e-2,
    factor: float = 1.5,
) -> jax.Array:
    """rsl_rl's schedule: kl > 2 target -> lr / factor; kl < target / 2 -> lr * factor;
    result clipped to [min_lr, max_lr]."""
    lr = jnp.where(kl > 2.0 * target_kl, lr / factor, lr)
    lr = jnp.where((kl < 0.5 * target_kl) & (kl > 0.0), lr * factor, lr)
    return jnp.clip(lr, min_lr, max_lr)
