"""A trained policy as a file: save, load, act, value, and the config it was trained with.

A policy file (``policy.npz``, written by the trainer next to its checkpoints) holds the params
and the observation normaliser as arrays, and as JSON metadata the network config, the
observation layout, the action size and the whole experiment config of the run. Readers of a
policy (evaluation, play, export) import this module, never the trainer (brax keeps
``load_policy`` in its checkpoint module for the same reason).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from mjx_stairs.config import ConfigError, from_dict, to_dict
from mjx_stairs.rl import checkpoint, networks, normalizer, ppo
from mjx_stairs.rl.networks import NetworkConfig, ObsLayout

STD_EPS = normalizer.STD_EPS

OBS_KEYS = ("state", "privileged_state")
"""The observation streams: the actor's (noisy) and the critic's (privileged, clean)."""


class Policy(NamedTuple):
    params: networks.Params
    normalizer: dict[str, normalizer.RunningStats]
    network: NetworkConfig
    layout: ObsLayout
    action_size: int
    metadata: dict


def config_dict(config) -> dict[str, Any]:
    """The plain dict of an experiment config (or of its ppo / network / train parts)."""
    if dataclasses.is_dataclass(config):
        return to_dict(config)
    return {k: to_dict(getattr(config, k)) for k in ("ppo", "network", "train")}


def layout_dict(layout: ObsLayout) -> dict[str, Any]:
    """The observation layout as saved in checkpoints and policy files."""
    return {"n_vec": layout.n_vec, "map_shape": list(layout.map_shape),
            "obs_size": layout.obs_size, "obs_keys": list(OBS_KEYS),
            "order": "[vec (n_vec) | map (row-major h*w)]"}


def save_policy(path: str | Path, params: networks.Params,
                norm: dict[str, normalizer.RunningStats], iteration: int, config,
                layout: ObsLayout) -> None:
    """Policy-only file for eval/export: params + normaliser + network config + obs layout."""
    tree = {"params": jax.device_get(params), "normalizer": jax.device_get(norm)}
    tc = config.train
    meta = {
        "kind": "policy",
        "iteration": int(iteration),
        "env_steps": int(iteration) * tc.num_envs * tc.unroll_length,
        "network": to_dict(config.network),
        "config": config_dict(config),
        "layout": layout_dict(layout),
        "action_size": int(tree["params"]["log_std"].shape[0]),
    }
    checkpoint.save(path, tree, meta)


RETIRED_CONV_IMPLS = ("row", "row_bf16")
"""conv_impls that only old measurements used (the row-Toeplitz encoder, the same function as
"xla" in float32): a policy trained with one is computed with "auto"."""


def _current_network(saved: dict[str, Any]) -> dict[str, Any]:
    """A saved network table in today's NetworkConfig: retired options mapped to their
    successors ("init" was always "orthogonal", the only init left)."""
    out = {k: v for k, v in saved.items() if k != "init"}
    if out.get("conv_impl") in RETIRED_CONV_IMPLS:
        out["conv_impl"] = "auto"
    return out


def load_policy(path: str | Path) -> Policy:
    """Read a policy file written by ``save_policy`` (validated against its own metadata).

    A policy trained with a bfloat16 or a retired conv_impl is loaded with conv_impl "auto"
    (float32); its metadata keeps what it was trained with."""
    meta = checkpoint.load_metadata(path)
    if meta.get("kind") != "policy":
        raise checkpoint.CheckpointError(f"{path}: not a policy file (kind={meta.get('kind')})")
    try:
        net_cfg = from_dict(NetworkConfig, _current_network(meta["network"]))
        layout = ObsLayout(int(meta["layout"]["n_vec"]), tuple(meta["layout"]["map_shape"]))
        a = int(meta["action_size"])
    except (KeyError, ConfigError, TypeError, ValueError) as e:
        raise checkpoint.CheckpointError(f"{path}: bad policy metadata ({e})") from None
    if net_cfg.conv_impl in networks.REDUCED_PRECISION_IMPLS:
        # eval, play, the critic map and export compute the policy in float32, as a robot
        # would run it; a bfloat16 encoder is a training-speed setting (meta keeps what it was)
        net_cfg = dataclasses.replace(net_cfg, conv_impl="auto")
    template = jax.eval_shape(lambda: {
        "params": networks.init_params(jax.random.PRNGKey(0), net_cfg, layout.n_vec,
                                       layout.map_shape, a),
        "normalizer": {k: normalizer.init_stats(layout.obs_size) for k in OBS_KEYS},
    })
    tree, meta = checkpoint.load(path, template)
    return Policy(tree["params"], tree["normalizer"], net_cfg, layout, a, meta)


def append_inputs(params: networks.Params, extra: int) -> networks.Params:
    """Actor-critic params, or Adam moments shaped like them, with `extra` more inputs at the end
    of the first actor and critic layer's (the vector part ends the features): zero rows."""
    out = dict(params)
    for name in ("actor", "critic"):
        first = params[name][0]
        w = first["w"]
        out[name] = [{**first, "w": jnp.concatenate([w, jnp.zeros((extra, w.shape[1]), w.dtype)])},
                     *params[name][1:]]
    return out


def appended_stats(st: normalizer.RunningStats, at: int, extra: int,
               seen: jax.Array | None = None) -> normalizer.RunningStats:
    """Running statistics with `extra` more entries at index `at`, under the saved count: mean
    0, variance 1; or, given `seen` [N, extra] (the new inputs as the env gives them, e.g. over
    fresh resets), their mean and variance (1 where constant), so that the new inputs are scaled
    as the others from the first step: the running update barely moves entries under a count of
    ~3e8 (the delay term of generalist_from_stage1_mix_told, values 0-1, read mean 0.06 and std
    0.96 after 400 iterations under a unit start)."""
    mean, var = jnp.zeros((extra,)), jnp.ones((extra,))
    if seen is not None:
        seen = jnp.asarray(seen, jnp.float32).reshape(-1, extra)
        mean, var = seen.mean(0), seen.var(0)
        var = jnp.where(var > 1e-8, var, 1.0)
    count = jnp.maximum(st.count, 1.0)
    return normalizer.RunningStats(st.count, jnp.insert(st.mean, at, mean.astype(st.mean.dtype)),
                                   jnp.insert(st.m2, at, (var * count).astype(st.m2.dtype)))


def widen_for_history(policy: Policy, extra: int,
                      seen: dict[str, jax.Array] | None = None) -> Policy:
    """A policy given `extra` more vector inputs (history over a policy without, the delay term)
    at the end of its vector part, where env.observation puts the history terms: zero weights
    for them in the first actor and critic layer, a unit normaliser (mean 0, variance 1; or
    per stream the statistics of `seen`, see appended_stats), so the widened policy acts and values
    exactly as the given one until training uses them (a history policy fine-tuned from a
    published one; trainer.start_from_policy)."""
    at_obs = policy.layout.n_vec
    norm = {k: appended_stats(v, at_obs, extra, None if seen is None else seen[k])
            for k, v in policy.normalizer.items()}
    layout = ObsLayout(at_obs + extra, policy.layout.map_shape)
    return policy._replace(params=append_inputs(policy.params, extra), normalizer=norm,
                           layout=layout)


def policy_action(policy: Policy, obs: jax.Array, rng: jax.Array | None = None) -> jax.Array:
    """Action for raw actor obs [..., D]: the mean, or a sample when ``rng`` is given. The policy
    computes in float32 whatever precision the physics ran in (float64 evaluations)."""
    obs = obs.astype(jnp.float32)
    mean = ppo.policy_mean(policy.params, policy.normalizer, obs, policy.network, policy.layout)
    if rng is None:
        return mean
    return networks.sample(rng, mean, policy.params["log_std"])


def policy_value(policy: Policy, critic_obs: jax.Array) -> jax.Array:
    """Critic value for raw privileged obs [..., D] -> [...]."""
    return ppo.critic_value(policy.params, policy.normalizer, critic_obs, policy.network,
                            policy.layout)


def normaliser_constants(policy: Policy, stream: str = "state"
                         ) -> tuple[np.ndarray, np.ndarray, float] | None:
    """(mean [D], std + STD_EPS [D], clip) of one observation stream (OBS_KEYS: the actor's
    "state", the critic's "privileged_state") as the policy applies them, or None when the
    policy does not normalise observations."""
    if not policy.network.normalize_obs:
        return None
    stats = jax.tree_util.tree_map(np.asarray, policy.normalizer[stream])
    mean = np.asarray(stats.mean, np.float32)
    denom = np.asarray(normalizer.std(stats) + normalizer.STD_EPS, np.float32)
    return mean, denom, float(policy.network.obs_clip)


def saved_config(policy: Policy, part: str) -> dict[str, Any] | None:
    """The part (e.g. "env") of the experiment config the policy was trained with, as the plain
    dict saved in its file; None for a file that does not carry it."""
    return policy.metadata.get("config", {}).get(part)
