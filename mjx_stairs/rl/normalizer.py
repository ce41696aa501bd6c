"""Running observation mean/std (parallel Welford merge), part of the training state.

Each observation stream ("state" for the actor, "privileged_state" for the critic) keeps its own
statistics: the streams share a layout but the actor's is noisy, so their variances differ.
The trainer holds ``{stream: RunningStats}``; normalise with ``normalize(stats, x, clip)``.

Statistics are updated once per iteration, after the PPO update, with all observations of that
iteration's rollout, so the normaliser in effect during a rollout is the same one the update
sees (the ratio starts at exactly 1). The first iteration therefore runs with mean 0, std 1.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

STD_EPS = 1e-2  # added to the std, as rsl_rl's EmpiricalNormalization


class RunningStats(NamedTuple):
    """count: [] float32 samples seen; mean: [D]; m2: [D] sum of squared deviations."""

    count: jax.Array
    mean: jax.Array
    m2: jax.Array


def init_stats(size: int) -> RunningStats:
    return RunningStats(
        count=jnp.zeros((), jnp.float32),
        mean=jnp.zeros((size,), jnp.float32),
        m2=jnp.zeros((size,), jnp.float32),
    )


def update_stats(stats: RunningStats, x: jax.Array) -> RunningStats:
    """Merge a batch [..., D] into the stats (Chan et al. parallel algorithm)."""
    x = x.reshape(-1, x.shape[-1]).astype(jnp.float32)
    n_b = jnp.asarray(x.shape[0], jnp.float32)
    mean_b = jnp.mean(x, axis=0)
    m2_b = jnp.sum(jnp.square(x - mean_b), axis=0)
    n = stats.count + n_b
    delta = mean_b - stats.mean
    mean = stats.mean + delta * (n_b / n)
    m2 = stats.m2 + m2_b + jnp.square(delta) * (stats.count * n_b / n)
    return RunningStats(count=n, mean=mean, m2=m2)


def std(stats: RunningStats) -> jax.Array:
    """Population std [D]; 1 before any sample."""
    var = jnp.where(stats.count > 0, stats.m2 / jnp.maximum(stats.count, 1.0), 1.0)
    return jnp.sqrt(var)


def normalize(stats: RunningStats, x: jax.Array, clip: float = 0.0) -> jax.Array:
    """(x - mean) / (std + STD_EPS), clipped to +-clip when clip > 0: [..., D] -> [..., D]."""
    y = (x - stats.mean) / (std(stats) + STD_EPS)
    if clip > 0:
        y = jnp.clip(y, -clip, clip)
    return y
