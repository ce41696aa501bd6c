"""PPO: GAE with truncation apart from termination, the clipped loss, minibatch SGD.

The update follows brax's scan hierarchy, as module-level functions:
``update`` (one training step: num_epochs x ``sgd_step``) -> ``sgd_step`` (one epoch: shuffle,
split into minibatches, scan ``minibatch_step``) -> ``minibatch_step`` (loss, grads, KL-adaptive
lr, clip, Adam). Everything is pure jnp, so it runs inside the trainer's compiled chunk.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Any, Callable, Literal, NamedTuple

import jax
import jax.numpy as jnp

from mjx_stairs.rl import networks, normalizer, optim
from mjx_stairs.rl.networks import NetworkConfig, ObsLayout

Params = Any


@dataclass(frozen=True)
class PPOConfig:
    """PPO hyperparameters; defaults are the protocol's figures."""

    learning_rate: float = field(default=1e-3, metadata={"help": "initial Adam learning rate"})
    lr_schedule: Literal["adaptive", "fixed"] = field(
        default="adaptive", metadata={"help": "'adaptive' (KL-driven, rsl_rl) or 'fixed'"}
    )
    desired_kl: float = field(default=0.01, metadata={"help": "target KL of the adaptive lr"})
    min_lr: float = field(default=1e-5, metadata={"help": "lower bound of the adaptive lr"})
    max_lr: float = field(default=1e-2, metadata={"help": "upper bound of the adaptive lr"})
    num_epochs: int = field(default=5, metadata={"help": "passes over each rollout"})
    num_minibatches: int = field(default=4, metadata={"help": "minibatches per epoch"})
    discount: float = field(default=0.995, metadata={"help": "gamma"})
    gae_lambda: float = field(default=0.995, metadata={"help": "GAE lambda"})
    clip_eps: float = field(default=0.2, metadata={"help": "surrogate ratio clip"})
    value_clip_eps: float = field(
        default=0.2, metadata={"help": "value clip around the rollout value (0 = unclipped loss)"}
    )
    entropy_coef: float = field(default=0.005, metadata={"help": "entropy bonus weight"})
    max_std: float = field(
        default=0.0,
        metadata={"help": "upper bound of the policy std, applied after each Adam step (0 = none)"},
    )
    value_loss_coef: float = field(default=1.0, metadata={"help": "value loss weight"})
    mirror_loss_coef: float = field(
        default=0.0,
        metadata={"help": "weight of the left-right symmetry loss: mean squared difference of the "
                  "mean action on mirrored observations and the mirrored mean action "
                  "(env.symmetry; 0 = off)"},
    )
    max_grad_norm: float = field(default=1.0, metadata={"help": "global-norm clip (0 = off)"})
    normalize_advantages: bool = field(
        default=True, metadata={"help": "normalise advantages per minibatch"}
    )
    adam_b1: float = field(default=0.9, metadata={"help": "Adam beta1"})
    adam_b2: float = field(default=0.999, metadata={"help": "Adam beta2"})
    adam_eps: float = field(default=1e-8, metadata={"help": "Adam epsilon"})


class Batch(NamedTuple):
    """Training data; leading axes [T, B] after the rollout, [N] flattened, [M, N / M] split.

    obs / critic_obs are raw (unnormalised) actor and privileged observations [..., D]."""

    obs: jax.Array
    critic_obs: jax.Array
    action: jax.Array  # [..., A]
    log_prob: jax.Array  # [...] behaviour log-prob
    mean: jax.Array  # [..., A] behaviour policy mean
    value: jax.Array  # [...] value at rollout time
    advantage: jax.Array  # [...]
    target: jax.Array  # [...] value target (advantage + value)


# ----------------------------------------------------------------------------- forward


def norm_obs(
    norm: dict[str, normalizer.RunningStats], stream: str, x: jax.Array, net_cfg: NetworkConfig
) -> jax.Array:
    """Normalise one observation stream ("state" or "privileged_state") when enabled."""
    if not net_cfg.normalize_obs:
        return x
    return normalizer.normalize(norm[stream], x, net_cfg.obs_clip)


def policy_mean(params, norm, obs, net_cfg: NetworkConfig, layout: ObsLayout) -> jax.Array:
    """Actor mean from raw actor obs: [..., D] -> [..., A]."""
    return networks.actor_mean(params, norm_obs(norm, "state", obs, net_cfg), layout,
                               conv_impl=net_cfg.conv_impl)


def critic_value(params, norm, critic_obs, net_cfg: NetworkConfig, layout: ObsLayout) -> jax.Array:
    """Value from raw privileged obs: [..., D] -> [...]."""
    return networks.value(params, norm_obs(norm, "privileged_state", critic_obs, net_cfg), layout,
                          conv_impl=net_cfg.conv_impl)


def policy_mean_and_value(
    params, norm, obs, critic_obs, net_cfg: NetworkConfig, layout: ObsLayout
) -> tuple[jax.Array, jax.Array]:
    """policy_mean(obs) and critic_value(critic_obs) through one encoder pass: [N, D] x 2."""
    return networks.actor_critic(
        params,
        norm_obs(norm, "state", obs, net_cfg),
        norm_obs(norm, "privileged_state", critic_obs, net_cfg),
        layout,
        conv_impl=net_cfg.conv_impl,
    )


# ----------------------------------------------------------------------------- GAE


def compute_gae(
    truncation: jax.Array,
    termination: jax.Array,
    rewards: jax.Array,
    values: jax.Array,
    bootstrap_value: jax.Array,
    lambda_: float,
    discount: float,
    truncation_value: jax.Array,
) -> tuple[jax.Array, jax.Array]:
    """Generalised advantage estimation over a rollout with auto-resets.

    Args (all [T, B] float except bootstrap_value [B]):
      truncation: 1 where the episode ended at t by timeout (bootstrap from the final obs).
      termination: 1 where the episode ended at t in a terminal state (next value 0). When both
        are set, termination wins.
      rewards: r_t.
      values: V(obs_t).
      bootstrap_value: V(obs_T), the observation after the last step.
      truncation_value: V(final obs of step t), the obs before the auto-reset.
    Returns:
      (advantages [T, B], value_targets [T, B] = advantages + values), gradient-stopped.
    """
    boundary = jnp.maximum(truncation, termination)
    next_values = jnp.concatenate([values[1:], bootstrap_value[None]], axis=0)
    next_values = jnp.where(truncation > 0, truncation_value, next_values)
    next_values = jnp.where(termination > 0, 0.0, next_values)
    deltas = rewards + discount * next_values - values
    decay = discount * lambda_ * (1.0 - boundary)

    def step(acc, xs):
        delta, d = xs
        acc = delta + d * acc
        return acc, acc

    _, adv = jax.lax.scan(step, jnp.zeros_like(bootstrap_value), (deltas, decay), reverse=True)
    adv = jax.lax.stop_gradient(adv)
    return adv, jax.lax.stop_gradient(adv + values)


# ----------------------------------------------------------------------------- loss


def ppo_loss(
    params: Params,
    norm: dict[str, normalizer.RunningStats],
    batch: Batch,
    old_log_std: jax.Array,
    cfg: PPOConfig,
    net_cfg: NetworkConfig,
    layout: ObsLayout,
    mirror: Any = None,
) -> tuple[jax.Array, dict[str, jax.Array]]:
    """Clipped surrogate + (clipped) value loss - entropy bonus on one minibatch [N, ...] (+ the
    symmetry loss with `cfg.mirror_loss_coef` and `mirror`)."""
    mean, value = policy_mean_and_value(params, norm, batch.obs, batch.critic_obs, net_cfg, layout)
    log_std = params["log_std"]
    log_prob = networks.log_prob(mean, log_std, batch.action)

    adv = batch.advantage
    if cfg.normalize_advantages:
        adv = (adv - jnp.mean(adv)) / (jnp.std(adv) + 1e-8)
    ratio = jnp.exp(log_prob - batch.log_prob)
    surr = ratio * adv
    surr_clipped = jnp.clip(ratio, 1.0 - cfg.clip_eps, 1.0 + cfg.clip_eps) * adv
    policy_loss = -jnp.mean(jnp.minimum(surr, surr_clipped))

    v_loss = jnp.square(value - batch.target)
    if cfg.value_clip_eps > 0:
        v_clipped = batch.value + jnp.clip(
            value - batch.value, -cfg.value_clip_eps, cfg.value_clip_eps
        )
        v_loss = jnp.maximum(v_loss, jnp.square(v_clipped - batch.target))
    value_loss = jnp.mean(v_loss)

    ent = networks.entropy(log_std)
    loss = policy_loss + cfg.value_loss_coef * value_loss - cfg.entropy_coef * ent

    kl = jnp.mean(networks.gaussian_kl(
        jax.lax.stop_gradient(batch.mean), old_log_std,
        jax.lax.stop_gradient(mean), jax.lax.stop_gradient(log_std),
    ))
    clip_frac = jnp.mean((jnp.abs(ratio - 1.0) > cfg.clip_eps).astype(jnp.float32))
    aux = {
        "loss/total": loss,
        "loss/policy": policy_loss,
        "loss/value": value_loss,
        "loss/entropy": ent,
        "loss/kl": kl,
        "loss/clip_fraction": clip_frac,
        "policy/std": jnp.mean(jnp.exp(log_std)),
    }
    if cfg.mirror_loss_coef > 0:
        sym = mirror_loss(params, norm, batch.obs, mean, net_cfg, layout, mirror)
        loss = loss + cfg.mirror_loss_coef * sym
        aux.update({"loss/total": loss, "loss/mirror": sym})
    return loss, aux


def mirror_loss(params, norm, obs, mean, net_cfg: NetworkConfig, layout: ObsLayout,
                mirror: Any) -> jax.Array:
    """Mean squared difference of the policy's mean on the mirrored observations and its mean
    `mean` [N, A] mirrored, the latter a fixed target (rsl_rl's mirror loss). `mirror`: the env's
    (env.symmetry.Mirror: .obs and .act, each a signed permutation with .apply(x))."""
    if mirror is None:
        raise ValueError("ppo.mirror_loss_coef > 0 needs the env's left-right mirror (env.mirror)")
    mirrored = policy_mean(params, norm, mirror.obs.apply(obs), net_cfg, layout)
    target = jax.lax.stop_gradient(mirror.act.apply(mean))
    return jnp.mean(jnp.sum(jnp.square(mirrored - target), axis=-1))


# ----------------------------------------------------------------------------- SGD


def minibatch_step(
    carry: tuple[Params, optim.AdamState],
    batch: Batch,
    *,
    norm: dict[str, normalizer.RunningStats],
    old_log_std: jax.Array,
    cfg: PPOConfig,
    net_cfg: NetworkConfig,
    layout: ObsLayout,
    mirror: Any = None,
) -> tuple[tuple[Params, optim.AdamState], dict[str, jax.Array]]:
    """Loss and grads on one minibatch, KL-adapted lr (rsl_rl: before the step), clip, Adam."""
    params, opt_state = carry
    grad_fn = jax.value_and_grad(ppo_loss, has_aux=True)
    (_, aux), grads = grad_fn(params, norm, batch, old_log_std, cfg, net_cfg, layout, mirror)
    if cfg.lr_schedule == "adaptive":
        lr = optim.adapt_lr(opt_state.lr, aux["loss/kl"], cfg.desired_kl, cfg.min_lr, cfg.max_lr)
        opt_state = opt_state._replace(lr=lr)
    grads, grad_norm = optim.clip_by_global_norm(grads, cfg.max_grad_norm)
    params, opt_state = optim.adam_update(
        grads, opt_state, params, cfg.adam_b1, cfg.adam_b2, cfg.adam_eps
    )
    if cfg.max_std > 0:  # projected step: the std stays where exploration still means something
        params = dict(params, log_std=jnp.minimum(params["log_std"], math.log(cfg.max_std)))
    aux = dict(aux, **{"opt/grad_norm": grad_norm, "opt/lr": opt_state.lr})
    return (params, opt_state), aux


def shuffle_minibatches(data: Batch, key: jax.Array, m: int) -> Batch:
    """A random permutation of the flattened batch [N, ...], split into m minibatches
    [m, N / m, ...]."""
    n = data.advantage.shape[0]
    perm = jax.random.permutation(key, n)
    return jax.tree_util.tree_map(
        lambda x: jnp.take(x, perm, axis=0).reshape(m, n // m, *x.shape[1:]), data
    )


def sgd_step(
    carry: tuple[Params, optim.AdamState, jax.Array],
    _: Any,
    *,
    data: Batch,
    norm: dict[str, normalizer.RunningStats],
    old_log_std: jax.Array,
    cfg: PPOConfig,
    net_cfg: NetworkConfig,
    layout: ObsLayout,
    constrain: Callable[[Batch], Batch],
    mirror: Any = None,
) -> tuple[tuple[Params, optim.AdamState, jax.Array], dict[str, jax.Array]]:
    """One epoch: shuffle the flattened batch [N, ...], split into M minibatches, scan them."""
    params, opt_state, rng = carry
    rng, key = jax.random.split(rng)
    shuffled = constrain(shuffle_minibatches(data, key, cfg.num_minibatches))
    step = functools.partial(
        minibatch_step, norm=norm, old_log_std=old_log_std, cfg=cfg, net_cfg=net_cfg,
        layout=layout, mirror=mirror,
    )
    (params, opt_state), aux = jax.lax.scan(step, (params, opt_state), shuffled)
    return (params, opt_state, rng), aux


def update(
    params: Params,
    opt_state: optim.AdamState,
    norm: dict[str, normalizer.RunningStats],
    data: Batch,
    rng: jax.Array,
    cfg: PPOConfig,
    net_cfg: NetworkConfig,
    layout: ObsLayout,
    constrain: Callable[[Batch], Batch] = lambda b: b,
    mirror: Any = None,
) -> tuple[Params, optim.AdamState, dict[str, jax.Array]]:
    """One PPO training step on a rollout Batch [T, B, ...]: num_epochs x num_minibatches.

    ``constrain`` may pin the sharding of the split minibatches [M, N / M, ...] (data parallel);
    ``mirror`` is the observation's and action's mirror for ``cfg.mirror_loss_coef``.
    Returns new params, optimiser state and the loss metrics averaged over all minibatches
    (``opt/lr`` is the value after the last minibatch).
    """
    n = data.advantage.shape[0] * data.advantage.shape[1]
    if n % cfg.num_minibatches:
        raise ValueError(
            f"batch of {n} transitions does not split into {cfg.num_minibatches} minibatches"
        )
    flat = jax.tree_util.tree_map(lambda x: x.reshape(n, *x.shape[2:]), data)
    epoch = functools.partial(
        sgd_step, data=flat, norm=norm, old_log_std=params["log_std"], cfg=cfg,
        net_cfg=net_cfg, layout=layout, constrain=constrain, mirror=mirror,
    )
    (params, opt_state, _), aux = jax.lax.scan(
        epoch, (params, opt_state, rng), None, length=cfg.num_epochs
    )
    metrics = jax.tree_util.tree_map(jnp.mean, aux)
    metrics["opt/lr"] = opt_state.lr
    return params, opt_state, metrics
