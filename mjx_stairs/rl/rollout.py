"""The rollout of one training iteration: T steps of every robot with the current policy.

``env`` follows brax's Env interface, unbatched, with the auto-reset inside ``step``; obs is a dict
{"state", "privileged_state"} of [D] vectors laid out as [vec | map]; ``env.map_shape`` is the
map's (h, w) or () and ``env.action_size`` the action size; ``state.info["truncation"]`` and
``state.info["final_obs"]`` drive the bootstrap on timeouts (missing -> treated as 0 / obs).

Inside the scan each step only acts (actor pass) and records the privileged observations; the
critic's values V(obs_t), V(final obs_t) and the bootstrap V(obs_T) are computed after the scan
in one encoder pass over [2T + 1, B] maps.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax.sharding import Mesh

from mjx_stairs.rl import networks, ppo
from mjx_stairs.rl.networks import NetworkConfig, ObsLayout
from mjx_stairs.rl.policy import OBS_KEYS
from mjx_stairs.rl.sharding import constrain


class Transition(NamedTuple):
    """One rollout step for all robots; stacked to [T, B, ...] by the rollout scan."""

    obs: jax.Array  # [B, D] actor obs (raw)
    critic_obs: jax.Array  # [B, D] privileged obs (raw)
    action: jax.Array  # [B, A]
    log_prob: jax.Array  # [B]
    mean: jax.Array  # [B, A]
    value: jax.Array | None  # [B] V(obs_t) (None inside the scan: computed after it)
    reward: jax.Array  # [B]
    done: jax.Array  # [B]
    truncation: jax.Array  # [B]
    final_value: jax.Array | None  # [B] V(final obs of step t) (likewise)
    final_critic_obs: jax.Array | None  # [B, D] privileged final obs (None after the rollout)


def obs_layout(env) -> ObsLayout:
    """ObsLayout from the env: D from the reset obs shapes, map from ``env.map_shape``."""
    obs = jax.eval_shape(env.reset, jax.random.PRNGKey(0)).obs
    if not isinstance(obs, dict) or any(k not in obs for k in OBS_KEYS):
        raise ValueError(f"env obs must be a dict with keys {OBS_KEYS}, got {type(obs)}")
    d = obs["state"].shape[-1]
    if obs["privileged_state"].shape[-1] != d:
        raise ValueError(
            f"obs 'state' ({d}) and 'privileged_state' ({obs['privileged_state'].shape[-1]}) "
            "must have the same size"
        )
    map_shape = tuple(int(x) for x in getattr(env, "map_shape", ()) or ())
    n_map = math.prod(map_shape) if map_shape else 0
    if n_map > d:
        raise ValueError(f"env.map_shape {map_shape} is larger than the obs size {d}")
    return ObsLayout(n_vec=d - n_map, map_shape=map_shape)


def _truncation(env_state) -> jax.Array:
    return env_state.info.get("truncation", jnp.zeros_like(env_state.done))


def _final_obs(env_state) -> dict[str, jax.Array]:
    return env_state.info.get("final_obs", env_state.obs)


def _robot_sums(per_robot: dict[str, jax.Array]) -> dict[str, jax.Array]:
    """{name: [B]} -> {name: sum over the robots}, as one reduction of the stacked [n, B]:
    one kernel per env step instead of one per metric (~40 tiny kernels, ~9 ms per iteration
    of 24 steps at 4096 robots on an H100)."""
    names = sorted(per_robot)
    stacked = jnp.stack([per_robot[k].astype(jnp.float32) for k in names])
    return dict(zip(names, jnp.sum(stacked, axis=1), strict=True))


def rollout_step(carry, key, *, env, params, norm, net_cfg: NetworkConfig, layout: ObsLayout,
                 mesh: Mesh):
    """Act with the current policy, step every robot, record the transition (values None: the
    transition carries the privileged final obs, and ``rollout`` computes the values)."""
    env_state, ep_return, ep_length = carry
    obs = env_state.obs["state"]
    critic_obs = env_state.obs["privileged_state"]
    mean = ppo.policy_mean(params, norm, obs, net_cfg, layout)
    action = networks.sample(key, mean, params["log_std"])
    log_prob = networks.log_prob(mean, params["log_std"], action)

    next_state = constrain(jax.vmap(env.step)(env_state, action), mesh, 0)
    done = next_state.done.astype(jnp.float32)
    truncation = _truncation(next_state).astype(jnp.float32)
    final_obs = _final_obs(next_state)["privileged_state"]

    ep_return = ep_return + next_state.reward
    ep_length = ep_length + 1.0
    per_robot = {f"_ep/{k}": v for k, v in (
        ("count", done), ("return_sum", done * ep_return), ("length_sum", done * ep_length))}
    per_robot.update(next_state.metrics)
    per_robot["reward/total"] = next_state.reward
    ep_return = ep_return * (1.0 - done)
    ep_length = ep_length * (1.0 - done)
    sums = _robot_sums(per_robot)
    n = done.shape[0]
    ep_stats = {k.removeprefix("_ep/"): v for k, v in sums.items() if k.startswith("_ep/")}
    env_metrics = {k: v / n for k, v in sums.items() if not k.startswith("_ep/")}
    tr = Transition(obs, critic_obs, action, log_prob, mean, None, next_state.reward.astype(
        jnp.float32), done, truncation, None, final_obs)
    return (next_state, ep_return, ep_length), (tr, env_metrics, ep_stats)


def rollout(state, key: jax.Array, *, config, env, layout: ObsLayout, mesh: Mesh):
    """The rollout of one iteration with ``state.params`` (a trainer.TrainState): T steps of
    every robot.

    Returns ``((env_state, ep_return, ep_length), tr, env_metrics, ep_stats, bootstrap)``:
    ``tr`` is a Transition [T, B, ...] with ``value`` and ``final_value`` filled in and
    ``final_critic_obs`` None; ``bootstrap`` [B] is V(obs_T).
    """
    nc: NetworkConfig = config.network
    step = functools.partial(rollout_step, env=env, params=state.params, norm=state.normalizer,
                             net_cfg=nc, layout=layout, mesh=mesh)
    carry, (tr, env_metrics, ep_stats) = jax.lax.scan(
        step, (state.env_state, state.ep_return, state.ep_length),
        jax.random.split(key, config.train.unroll_length),
    )
    tr = constrain(tr, mesh, 1)
    last_obs = carry[0].obs["privileged_state"]
    # one critic pass over [2T + 1, B] maps: V(obs_t), V(final obs_t), V(obs_T)
    T = tr.critic_obs.shape[0]
    stacked = jnp.concatenate([tr.critic_obs, tr.final_critic_obs, last_obs[None]], axis=0)
    values = ppo.critic_value(state.params, state.normalizer, constrain(stacked, mesh, 1), nc,
                              layout)
    tr = tr._replace(value=values[:T], final_value=values[T:2 * T], final_critic_obs=None)
    return carry, tr, env_metrics, ep_stats, values[2 * T]
