"""The compiled training loop and the host loop around it.

``make_train(config, env)`` returns ``(init, chunk)``:

- ``init(rng) -> TrainState``: params, Adam state, normaliser, the batched env state (all robots
  reset with ``jax.vmap(env.reset)``), RNG, counters, running episode stats.
- ``chunk(state) -> (state, metrics)``: ONE jitted call running ``train.iterations_per_chunk``
  iterations as a ``lax.scan`` of (rollout scan of ``unroll_length`` steps for all robots ->
  GAE -> PPO update -> normaliser update). The state argument is donated.

``config`` is any object with attributes ``ppo`` (PPOConfig), ``network`` (NetworkConfig) and
``train`` (TrainConfig), e.g. ``LearnerConfig`` below or the env engineer's ExperimentConfig. If it
is a dataclass, the whole of it is saved in checkpoints and ``config.json``.

``env`` follows brax's Env interface, unbatched, with the auto-reset inside ``step``; obs is a dict
{"state", "privileged_state"} of [D] vectors laid out as [vec | map]; ``env.map_shape`` is the
map's (h, w) or () and ``env.action_size`` the action size; ``state.info["truncation"]`` and
``state.info["final_obs"]`` drive the bootstrap on timeouts (missing -> treated as 0 / obs).

Data parallel: robots are split over all local devices (a 1-D Mesh named "batch"); the env
state, running episode stats and rollout are sharded on their robot axis, everything else is
replicated; XLA (GSPMD) inserts the gradient averaging. One device works unchanged.

``run(config, env, run_dir=None, resume=False, on_chunk=None)`` is the host loop: progress,
metrics (``metrics.jsonl``, TensorBoard under ``tb/``), checkpoints under ``checkpoints/``.

Run directory ``<log_dir>/<experiment>__<seed>__<YYYYmmdd-HHMMSS>/``::

    config.json                  the whole config (JSON of the dataclasses)
    metrics.jsonl                one line per chunk: iteration, env_steps, wall_time, perf/*,
                                 episode/*, loss/*, opt/*, value/*, every env metric
    tb/                          TensorBoard scalars (x axis: env steps)
    checkpoints/state_<it>.npz   full TrainState (the newest ``keep_checkpoints``)
    policy.npz                   params + normaliser + network config + obs layout (eval/export)

Bit-exact resume holds on the CPU. On a GPU, XLA's default kernels (cuDNN conv backward,
atomic reductions) are not run-to-run deterministic, so a resumed run matches only up to float
noise unless the process starts with ``XLA_FLAGS=--xla_gpu_deterministic_ops=true`` (seen on an
H100: the resume test fails without it and passes with it).
"""

from __future__ import annotations

import functools
import json
import math
import signal
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding
from jax.sharding import PartitionSpec as P

from mjx_stairs.rl import checkpoint, networks, normalizer, optim, policy, ppo
from mjx_stairs.rl import logger as logging_utils
from mjx_stairs.rl.networks import NetworkConfig, ObsLayout
from mjx_stairs.rl.policy import OBS_KEYS, config_dict, layout_dict
from mjx_stairs.rl.ppo import PPOConfig

BATCH_AXIS = "batch"


@dataclass(frozen=True)
class TrainConfig:
    """Scale, schedule, run naming, logging and checkpointing of a training run."""

    experiment: str = field(default="default", metadata={"help": "run name prefix"})
    seed: int = field(default=0, metadata={"help": "master seed (params, env, sampling)"})
    num_envs: int = field(default=4096, metadata={"help": "robots in parallel (all devices)"})
    unroll_length: int = field(default=24, metadata={"help": "steps per robot per iteration"})
    iterations_per_chunk: int = field(
        default=10, metadata={"help": "iterations per compiled chunk (host sees every K)"}
    )
    total_iterations: int = field(
        default=1500, metadata={"help": "stop at this iteration (rounded up to whole chunks)"}
    )
    max_env_steps: int = field(
        default=0, metadata={"help": "stop once this many env steps are done in total (0 = off)"}
    )
    time_budget_s: float = field(
        default=0.0,
        metadata={"help": "wall-clock seconds for this invocation; checkpoint and stop before "
                  "the next chunk would overrun it (0 = off)"},
    )
    log_dir: str = field(default="runs", metadata={"help": "parent of the run directories"})
    checkpoint_every: int = field(
        default=10, metadata={"help": "full checkpoint every N chunks (and always at the end)"}
    )
    keep_checkpoints: int = field(
        default=3, metadata={"help": "full checkpoints kept per run (0 = all)"}
    )
    rollout_values: str = field(
        default="batched",
        metadata={"help": "'batched': the critic's values of the rollout (V(obs_t), V(final "
                  "obs_t), the bootstrap) in one encoder pass after the rollout scan; "
                  "'per_step': inside the scan, beside each action (same values, smaller "
                  "batches)"},
    )
    checkpoint_env: str = field(
        default="full",
        metadata={"help": "'full': the whole batched env state (bit-exact resume); 'packed': "
                  "env.pack_state (~20x smaller; resume exact up to float rounding)"},
    )
    tensorboard: bool = field(default=True, metadata={"help": "write TensorBoard scalars"})
    progress: bool = field(default=True, metadata={"help": "tqdm progress bar"})
    console: bool = field(default=True, metadata={"help": "print a metrics block per chunk"})


@dataclass(frozen=True)
class LearnerConfig:
    """The learner's part of an experiment; ExperimentConfig adds ``env`` beside these."""

    ppo: PPOConfig = field(default_factory=PPOConfig)
    network: NetworkConfig = field(default_factory=NetworkConfig)
    train: TrainConfig = field(default_factory=TrainConfig)


class TrainState(NamedTuple):
    """Everything a resume needs. B = num_envs (sharded over devices on this axis)."""

    params: networks.Params
    opt_state: optim.AdamState
    normalizer: dict[str, normalizer.RunningStats]  # {"state": ..., "privileged_state": ...}
    env_state: Any  # brax State, every leaf [B, ...]
    rng: jax.Array  # [2] uint32 PRNGKey
    iteration: jax.Array  # [] int32 iterations done
    ep_return: jax.Array  # [B] return of each robot's running episode
    ep_length: jax.Array  # [B] steps of each robot's running episode


class Transition(NamedTuple):
    """One rollout step for all robots; stacked to [T, B, ...] by the rollout scan."""

    obs: jax.Array  # [B, D] actor obs (raw)
    critic_obs: jax.Array  # [B, D] privileged obs (raw)
    action: jax.Array  # [B, A]
    log_prob: jax.Array  # [B]
    mean: jax.Array  # [B, A]
    value: jax.Array | None  # [B] V(obs_t) (None inside the scan with 'batched' values)
    reward: jax.Array  # [B]
    done: jax.Array  # [B]
    truncation: jax.Array  # [B]
    final_value: jax.Array | None  # [B] V(final obs of step t) (likewise)
    final_critic_obs: jax.Array | None  # [B, D] privileged final obs ('batched' values only)


# ----------------------------------------------------------------------------- env glue


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


# ----------------------------------------------------------------------------- sharding


def make_mesh(devices: list | None = None) -> Mesh:
    """1-D mesh over all local devices (or ``devices``), axis name "batch"."""
    devs = jax.local_devices() if devices is None else devices
    return Mesh(np.array(devs), (BATCH_AXIS,))


def state_sharding(state: TrainState, mesh: Mesh) -> TrainState:
    """Shardings for a TrainState (or its eval_shape): robot axis split, the rest replicated."""
    rep = NamedSharding(mesh, P())
    bat = NamedSharding(mesh, P(BATCH_AXIS))

    def batched(x):
        return bat if len(getattr(x, "shape", ())) >= 1 else rep

    return TrainState(
        params=jax.tree_util.tree_map(lambda _: rep, state.params),
        opt_state=jax.tree_util.tree_map(lambda _: rep, state.opt_state),
        normalizer=jax.tree_util.tree_map(lambda _: rep, state.normalizer),
        env_state=jax.tree_util.tree_map(batched, state.env_state),
        rng=rep,
        iteration=rep,
        ep_return=bat,
        ep_length=bat,
    )


def shard_state(state: TrainState, mesh: Mesh) -> TrainState:
    """Place a (host) TrainState on the mesh."""
    return jax.device_put(state, state_sharding(state, mesh))


def _constrain(tree: Any, mesh: Mesh, axis: int) -> Any:
    """Pin the robot/sample axis ``axis`` of every leaf to the mesh (no-op where it won't split)."""
    n = mesh.devices.size
    if n == 1:
        return tree

    def one(x):
        if x.ndim <= axis or x.shape[axis] % n:
            return x
        spec = P(*([None] * axis), BATCH_AXIS)
        return jax.lax.with_sharding_constraint(x, NamedSharding(mesh, spec))

    return jax.tree_util.tree_map(one, tree)


# ----------------------------------------------------------------------------- compiled parts


def init_state(rng: jax.Array, *, config, env, layout: ObsLayout) -> TrainState:
    """Fresh TrainState; all robots reset."""
    tc: TrainConfig = config.train
    k_params, k_env, k_train = jax.random.split(rng, 3)
    params = networks.init_params(
        k_params, config.network, layout.n_vec, layout.map_shape, env.action_size
    )
    env_state = jax.vmap(env.reset)(jax.random.split(k_env, tc.num_envs))
    zeros = jnp.zeros((tc.num_envs,), jnp.float32)
    return TrainState(
        params=params,
        opt_state=optim.adam_init(params, config.ppo.learning_rate),
        normalizer={k: normalizer.init_stats(layout.obs_size) for k in OBS_KEYS},
        env_state=env_state,
        rng=k_train,
        iteration=jnp.zeros((), jnp.int32),
        ep_return=zeros,
        ep_length=zeros,
    )


def _robot_sums(per_robot: dict[str, jax.Array]) -> dict[str, jax.Array]:
    """{name: [B]} -> {name: sum over the robots}, as one reduction of the stacked [n, B]:
    one kernel per env step instead of one per metric (~40 tiny kernels, ~9 ms per iteration
    of 24 steps at 4096 robots on an H100)."""
    names = sorted(per_robot)
    stacked = jnp.stack([per_robot[k].astype(jnp.float32) for k in names])
    return dict(zip(names, jnp.sum(stacked, axis=1), strict=True))


def rollout_step(carry, key, *, env, params, norm, net_cfg: NetworkConfig, layout: ObsLayout,
                 mesh: Mesh, per_step_values: bool = True):
    """Act with the current policy, step every robot, record the transition.

    With ``per_step_values`` the critic's V(obs_t) and V(final obs_t) are computed here (one
    fused actor-critic pass and one critic pass on B maps); without, the transition carries the
    privileged final obs instead and ``rollout`` computes both values after the scan.
    """
    env_state, ep_return, ep_length = carry
    obs = env_state.obs["state"]
    critic_obs = env_state.obs["privileged_state"]
    if per_step_values:
        mean, value = ppo.policy_mean_and_value(params, norm, obs, critic_obs, net_cfg, layout)
    else:
        mean = ppo.policy_mean(params, norm, obs, net_cfg, layout)
        value = None
    action = networks.sample(key, mean, params["log_std"])
    log_prob = networks.log_prob(mean, params["log_std"], action)

    next_state = jax.vmap(env.step)(env_state, action)
    next_state = _constrain(next_state, mesh, 0)
    done = next_state.done.astype(jnp.float32)
    truncation = _truncation(next_state).astype(jnp.float32)
    final_obs = _final_obs(next_state)["privileged_state"]
    if per_step_values:
        final_value = ppo.critic_value(params, norm, final_obs, net_cfg, layout)
        final_obs = None
    else:
        final_value = None

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
    tr = Transition(obs, critic_obs, action, log_prob, mean, value, next_state.reward.astype(
        jnp.float32), done, truncation, final_value, final_obs)
    return (next_state, ep_return, ep_length), (tr, env_metrics, ep_stats)


def rollout(state: TrainState, key: jax.Array, *, config, env, layout: ObsLayout, mesh: Mesh):
    """The rollout of one iteration with ``state.params``: T steps of every robot.

    Returns ``((env_state, ep_return, ep_length), tr, env_metrics, ep_stats, bootstrap)``:
    ``tr`` is a Transition [T, B, ...] with ``value`` and ``final_value`` filled in and
    ``final_critic_obs`` None; ``bootstrap`` [B] is V(obs_T).
    """
    nc: NetworkConfig = config.network
    mode = config.train.rollout_values
    step = functools.partial(
        rollout_step, env=env, params=state.params, norm=state.normalizer, net_cfg=nc,
        layout=layout, mesh=mesh, per_step_values=mode == "per_step",
    )
    carry, (tr, env_metrics, ep_stats) = jax.lax.scan(
        step, (state.env_state, state.ep_return, state.ep_length),
        jax.random.split(key, config.train.unroll_length),
    )
    tr = _constrain(tr, mesh, 1)
    last_obs = carry[0].obs["privileged_state"]
    if mode == "per_step":
        bootstrap = ppo.critic_value(state.params, state.normalizer, last_obs, nc, layout)
    else:
        # one critic pass over [2T + 1, B] maps: V(obs_t), V(final obs_t), V(obs_T)
        T = tr.critic_obs.shape[0]
        stacked = jnp.concatenate([tr.critic_obs, tr.final_critic_obs, last_obs[None]], axis=0)
        values = ppo.critic_value(state.params, state.normalizer,
                                  _constrain(stacked, mesh, 1), nc, layout)
        tr = tr._replace(value=values[:T], final_value=values[T:2 * T], final_critic_obs=None)
        bootstrap = values[2 * T]
    return carry, tr, env_metrics, ep_stats, bootstrap


def rollout_batch(tr: Transition, bootstrap: jax.Array, pc: PPOConfig,
                  mesh: Mesh) -> tuple[ppo.Batch, jax.Array]:
    """GAE over a rollout [T, B] -> (the PPO Batch [B, T, ...], termination [T, B])."""
    termination = tr.done * (1.0 - tr.truncation)
    adv, target = ppo.compute_gae(
        tr.truncation, termination, tr.reward, tr.value, bootstrap, pc.gae_lambda, pc.discount,
        tr.final_value,
    )
    batch = ppo.Batch(
        obs=tr.obs, critic_obs=tr.critic_obs, action=tr.action, log_prob=tr.log_prob,
        mean=tr.mean, value=tr.value, advantage=adv, target=target,
    )
    # [T, B] -> [B, T] so the flattened sample axis stays contiguous per device.
    batch = jax.tree_util.tree_map(lambda x: jnp.swapaxes(x, 0, 1), batch)
    return _constrain(batch, mesh, 0), termination


def updated_normalizer(norm: dict[str, normalizer.RunningStats], tr: Transition,
                       nc: NetworkConfig) -> dict[str, normalizer.RunningStats]:
    """The observation statistics merged with this rollout's observations (when enabled)."""
    if not nc.normalize_obs:
        return norm
    return {
        "state": normalizer.update_stats(norm["state"], tr.obs),
        "privileged_state": normalizer.update_stats(norm["privileged_state"], tr.critic_obs),
    }


def training_iteration(state: TrainState, _, *, config, env, layout: ObsLayout, mesh: Mesh):
    """Rollout (scan of T steps) -> GAE -> PPO update -> normaliser update; one iteration."""
    pc: PPOConfig = config.ppo
    nc: NetworkConfig = config.network
    rng, k_roll, k_update = jax.random.split(state.rng, 3)
    with jax.named_scope("rollout"):  # scopes name the pieces in a profiler trace
        (env_state, ep_return, ep_length), tr, env_metrics, ep_stats, bootstrap = rollout(
            state, k_roll, config=config, env=env, layout=layout, mesh=mesh
        )
    batch, termination = rollout_batch(tr, bootstrap, pc, mesh)
    with jax.named_scope("ppo_update"):
        params, opt_state, upd_metrics = ppo.update(
            state.params, state.opt_state, state.normalizer, batch, k_update, pc, nc, layout,
            constrain=lambda b: _constrain(b, mesh, 1),
        )
    norm = updated_normalizer(state.normalizer, tr, nc)
    metrics = {k: jnp.mean(v) for k, v in env_metrics.items()}
    metrics.update(upd_metrics)
    metrics["value/mean"] = jnp.mean(tr.value)
    metrics["value/target_mean"] = jnp.mean(batch.target)
    metrics["episode/terminations"] = jnp.sum(termination)
    metrics["episode/truncations"] = jnp.sum(tr.truncation)
    metrics.update({f"_ep/{k}": jnp.sum(v) for k, v in ep_stats.items()})
    new_state = TrainState(
        params=params, opt_state=opt_state, normalizer=norm, env_state=env_state, rng=rng,
        iteration=state.iteration + 1, ep_return=ep_return, ep_length=ep_length,
    )
    return new_state, metrics


def reduce_chunk_metrics(per_iter: dict[str, jax.Array]) -> dict[str, jax.Array]:
    """[K] per-iteration metrics -> chunk scalars: means; episode stats pooled; lr = last."""
    out = {}
    for k, v in per_iter.items():
        if k.startswith("_ep/"):
            continue
        out[k] = jnp.mean(v)
    out["opt/lr"] = per_iter["opt/lr"][-1]
    count = jnp.sum(per_iter["_ep/count"])
    out["episode/count"] = count
    out["episode/return"] = jnp.sum(per_iter["_ep/return_sum"]) / jnp.maximum(count, 1.0)
    out["episode/length"] = jnp.sum(per_iter["_ep/length_sum"]) / jnp.maximum(count, 1.0)
    out["episode/terminations"] = jnp.sum(per_iter["episode/terminations"])
    out["episode/truncations"] = jnp.sum(per_iter["episode/truncations"])
    if "episode_success" in per_iter and "done" in per_iter:
        # success rate of the episodes that ended in this chunk (both are means over T x B)
        ended = jnp.sum(per_iter["done"])
        out["success"] = jnp.sum(per_iter["episode_success"]) / jnp.maximum(ended, 1e-9)
    return out


def run_chunk(state: TrainState, *, config, env, layout: ObsLayout, mesh: Mesh):
    """K training iterations as one lax.scan; returns (state, chunk metrics)."""
    it = functools.partial(training_iteration, config=config, env=env, layout=layout, mesh=mesh)
    state, per_iter = jax.lax.scan(it, state, None, length=config.train.iterations_per_chunk)
    return state, reduce_chunk_metrics(per_iter)


# ----------------------------------------------------------------------------- make_train


class Trainer(NamedTuple):
    init: Callable[[jax.Array], TrainState]
    chunk: Callable[[TrainState], tuple[TrainState, dict]]
    layout: ObsLayout
    mesh: Mesh
    sharding: TrainState  # shardings of the TrainState
    template: TrainState  # ShapeDtypeStructs of the TrainState
    env: Any  # the env the trainer was built for


def _check(config, mesh: Mesh) -> None:
    tc, pc = config.train, config.ppo
    n_dev = mesh.devices.size
    if tc.num_envs % n_dev:
        raise ValueError(f"train.num_envs={tc.num_envs} must divide over {n_dev} devices")
    n = tc.num_envs * tc.unroll_length
    if n % pc.num_minibatches:
        raise ValueError(
            f"num_envs * unroll_length = {n} does not split into ppo.num_minibatches="
            f"{pc.num_minibatches}"
        )
    if tc.checkpoint_env not in ("full", "packed"):
        raise ValueError(f"train.checkpoint_env must be 'full' or 'packed', not "
                         f"{tc.checkpoint_env!r}")
    if tc.rollout_values not in ("batched", "per_step"):
        raise ValueError(f"train.rollout_values must be 'batched' or 'per_step', not "
                         f"{tc.rollout_values!r}")
    if pc.lr_schedule not in ("adaptive", "fixed"):
        raise ValueError(f"ppo.lr_schedule must be 'adaptive' or 'fixed', not {pc.lr_schedule!r}")


_TRAINERS: dict[tuple, tuple[Any, Trainer]] = {}


def _compiled_config(config) -> LearnerConfig:
    """The part of a config the compiled functions depend on (host-only fields dropped)."""
    tc = config.train
    return LearnerConfig(
        ppo=config.ppo,
        network=config.network,
        train=TrainConfig(num_envs=tc.num_envs, unroll_length=tc.unroll_length,
                          iterations_per_chunk=tc.iterations_per_chunk,
                          rollout_values=tc.rollout_values),
    )


def build_trainer(config, env, mesh: Mesh | None = None) -> Trainer:
    """make_train plus what the host loop needs (layout, mesh, shardings, state template).

    Trainers are cached per (compile-relevant config, env object, devices), so repeated
    ``run`` calls in one process (tests, resume) reuse the compiled chunk.
    """
    mesh = make_mesh() if mesh is None else mesh
    _check(config, mesh)
    config = _compiled_config(config)
    key = (config, id(env), tuple(d.id for d in mesh.devices.flat))
    hit = _TRAINERS.get(key)
    if hit is not None and hit[0] is env:
        return hit[1]
    trainer = _build_trainer(config, env, mesh)
    _TRAINERS[key] = (env, trainer)
    return trainer


def _build_trainer(config, env, mesh: Mesh) -> Trainer:
    layout = obs_layout(env)
    init_fn = functools.partial(init_state, config=config, env=env, layout=layout)
    template = jax.eval_shape(init_fn, jax.random.PRNGKey(0))
    sharding = state_sharding(template, mesh)
    rep = NamedSharding(mesh, P())
    init = jax.jit(init_fn, out_shardings=sharding)
    chunk_fn = functools.partial(run_chunk, config=config, env=env, layout=layout, mesh=mesh)
    chunk = jax.jit(chunk_fn, in_shardings=(sharding,), out_shardings=(sharding, rep),
                    donate_argnums=0)
    return Trainer(init, chunk, layout, mesh, sharding, template, env)


def make_train(config, env, mesh: Mesh | None = None):
    """``(init, chunk)``: ``init(rng) -> TrainState``; ``chunk(state) -> (state, metrics)``
    runs ``config.train.iterations_per_chunk`` iterations in one compiled call (state donated).
    """
    t = build_trainer(config, env, mesh)
    return t.init, t.chunk


# ----------------------------------------------------------------------------- checkpoints


_PACKERS: dict[int, tuple[Any, Callable, Callable]] = {}


def _packers(env) -> tuple[Callable, Callable]:
    """Jitted, batched ``env.pack_state`` / ``env.unpack_state`` (cached per env)."""
    if not (hasattr(env, "pack_state") and hasattr(env, "unpack_state")):
        raise ValueError("train.checkpoint_env='packed' needs env.pack_state and "
                         "env.unpack_state")
    hit = _PACKERS.get(id(env))
    if hit is None or hit[0] is not env:
        hit = (env, jax.jit(jax.vmap(env.pack_state)), jax.jit(jax.vmap(env.unpack_state)))
        _PACKERS[id(env)] = hit
    return hit[1], hit[2]


def save_state(path: str | Path, state: TrainState, config, layout: ObsLayout,
               extra: dict | None = None, env=None) -> None:
    """Full checkpoint: the whole TrainState + config and counters as metadata.

    With ``train.checkpoint_env == "packed"`` the env state is stored as
    ``vmap(env.pack_state)`` (``env`` required) and rebuilt with ``env.unpack_state`` on load.
    """
    tc = config.train
    env_format = tc.checkpoint_env
    if env_format == "packed":
        pack, _ = _packers(env)
        state = state._replace(env_state=pack(state.env_state))
    host = jax.device_get(state)
    it = int(host.iteration)
    meta = {
        "kind": "train_state",
        "iteration": it,
        "env_steps": it * tc.num_envs * tc.unroll_length,
        "env_format": env_format,
        "config": config_dict(config),
        "layout": layout_dict(layout),
        "action_size": int(host.params["log_std"].shape[0]),
        "jax_version": jax.__version__,
        "saved_at": time.time(),
    }
    meta.update(extra or {})
    checkpoint.save(path, host, meta)


def load_state(path: str | Path, trainer: Trainer) -> tuple[TrainState, dict]:
    """Read a full checkpoint into the trainer's TrainState structure, placed on its mesh."""
    meta = checkpoint.load_metadata(path)
    if meta.get("kind") != "train_state":
        raise checkpoint.CheckpointError(f"{path}: not a train-state checkpoint")
    if meta.get("env_format", "full") == "packed":
        pack, unpack = _packers(trainer.env)
        packed_t = jax.eval_shape(pack, trainer.template.env_state)
        host, meta = checkpoint.load(path, trainer.template._replace(env_state=packed_t))
        bat = NamedSharding(trainer.mesh, P(BATCH_AXIS))
        packed = jax.device_put(host.env_state, jax.tree_util.tree_map(lambda _: bat, packed_t))
        env_state = jax.device_put(unpack(packed), trainer.sharding.env_state)
        state = jax.device_put(host._replace(env_state=None),
                               trainer.sharding._replace(env_state=None))
        return state._replace(env_state=env_state), meta
    host, meta = checkpoint.load(path, trainer.template)
    return jax.device_put(host, trainer.sharding), meta


def save_policy(path: str | Path, state: TrainState, config, layout: ObsLayout) -> None:
    """Policy-only file of a TrainState (see ``policy.save_policy``)."""
    policy.save_policy(path, state.params, state.normalizer,
                       int(jax.device_get(state.iteration)), config, layout)


def start_from_policy(state: TrainState, path: str | Path, trainer: Trainer) -> TrainState:
    """Replace the params and normaliser of a fresh state by those of a policy file (stage 2
    starts from stage 1). The Adam moments, RNG and counters stay fresh."""
    saved = policy.load_policy(path)
    want = jax.tree_util.tree_map(jnp.shape, (state.params, state.normalizer))
    got = jax.tree_util.tree_map(jnp.shape, (saved.params, saved.normalizer))
    if want != got:
        raise checkpoint.CheckpointError(
            f"{path}: policy shapes do not fit this experiment's network and observation layout"
        )
    params = jax.device_put(saved.params, trainer.sharding.params)
    norm = jax.device_put(saved.normalizer, trainer.sharding.normalizer)
    return state._replace(params=params, normalizer=norm)


# ----------------------------------------------------------------------------- host loop


_COMPILED: dict[int, Any] = {}


def _compiled_chunk(trainer: Trainer, state: TrainState):
    """AOT-compiled chunk (so the first chunk's timing excludes compilation), cached."""
    hit = _COMPILED.get(id(trainer))
    if hit is None or hit[0] is not trainer:
        hit = (trainer, trainer.chunk.lower(state).compile())
        _COMPILED[id(trainer)] = hit
    return hit[1]


class RunResult(NamedTuple):
    run_dir: Path
    state: TrainState
    metrics: dict[str, Any]  # last chunk's record
    stop_reason: str


def _config_diff(a: dict, b: dict, prefix: str = "") -> list[str]:
    out = []
    for k in sorted(set(a) | set(b)):
        key = f"{prefix}.{k}" if prefix else k
        va, vb = a.get(k), b.get(k)
        if isinstance(va, dict) and isinstance(vb, dict):
            out.extend(_config_diff(va, vb, key))
        elif va != vb:
            out.append(f"{key}: {va!r} -> {vb!r}")
    return out


class _StopFlag:
    """Set by SIGTERM/SIGINT: finish the running chunk, checkpoint, exit."""

    def __init__(self):
        self.reason = ""
        self._old = {}

    def __enter__(self):
        try:
            for sig in (signal.SIGTERM, signal.SIGINT):
                self._old[sig] = signal.signal(sig, self._handle)
        except ValueError:  # not in the main thread
            self._old = {}
        return self

    def _handle(self, signum, _frame):
        if self.reason:  # second signal: give up at once
            raise KeyboardInterrupt
        self.reason = f"signal {signal.Signals(signum).name}"

    def __exit__(self, *exc):
        for sig, h in self._old.items():
            signal.signal(sig, h)
        return False


def run(
    config,
    env,
    run_dir: str | Path | None = None,
    resume: bool | str | Path = False,
    on_chunk: Callable[[dict[str, Any]], bool | None] | None = None,
    mesh: Mesh | None = None,
) -> RunResult:
    """Train until ``train.total_iterations`` (rounded up to whole chunks), ``max_env_steps``,
    the ``time_budget_s`` or a signal; checkpoint and return.

    run_dir: None -> a new ``<log_dir>/<experiment>__<seed>__<time>`` (or, with resume=True,
      the newest such directory).
    resume: True -> continue from the newest ``<run_dir>/checkpoints/state_*.npz``; a path ->
      continue from that state file (e.g. one carried from another machine), logging into
      ``run_dir`` (a new run directory when None).
    on_chunk(record): called after each chunk with the logged record; returning True stops.
    """
    t_start = time.time()
    tc: TrainConfig = config.train
    trainer = build_trainer(config, env, mesh)
    steps_per_iter = tc.num_envs * tc.unroll_length
    K = tc.iterations_per_chunk
    resume_file = None if isinstance(resume, bool) else Path(resume)

    if run_dir is None:
        if resume is True:
            run_dir = logging_utils.latest_run_dir(tc.log_dir, tc.experiment, tc.seed)
            if run_dir is None:
                raise FileNotFoundError(
                    f"--resume: no run '{tc.experiment}__{tc.seed}__*' under {tc.log_dir}"
                )
        else:
            run_dir = logging_utils.new_run_dir(tc.log_dir, tc.experiment, tc.seed)
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    ckpt_dir = run_dir / "checkpoints"

    if resume:
        path = resume_file if resume_file is not None else checkpoint.latest_checkpoint(ckpt_dir)
        if path is None:
            raise checkpoint.CheckpointError(f"{ckpt_dir}: no checkpoint to resume from")
        state, meta = load_state(path, trainer)
        diff = _config_diff(meta.get("config", {}), config_dict(config))
        if diff:
            warnings.warn(f"resuming {path} with a changed config: {'; '.join(diff)}",
                          stacklevel=2)
        logging_utils.truncate_jsonl(run_dir / "metrics.jsonl", int(meta["iteration"]))
        print(f"resumed {path} at iteration {meta['iteration']}", flush=True)
    else:
        state = trainer.init(jax.random.PRNGKey(tc.seed))
        init_from = getattr(config, "init_from", "")
        if init_from:
            state = start_from_policy(state, init_from, trainer)
            print(f"initialised params and normaliser from {init_from}", flush=True)
        (run_dir / "config.json").write_text(json.dumps(config_dict(config), indent=2))

    t0 = time.time()
    compiled = _compiled_chunk(trainer, state)
    compile_s = time.time() - t0

    iteration = int(jax.device_get(state.iteration))
    n_chunks_total = -(-tc.total_iterations // K)
    target_iter = n_chunks_total * K
    logger = logging_utils.MetricsLogger(run_dir, tensorboard=tc.tensorboard)
    bar = None
    if tc.progress:
        from tqdm import tqdm

        bar = tqdm(total=target_iter * steps_per_iter, initial=iteration * steps_per_iter,
                   unit="step", unit_scale=True, dynamic_ncols=True)
    record: dict[str, Any] = {}
    stop_reason = ""
    chunk_s_est = 0.0
    save_s_est = 0.0
    chunks_since_ckpt = 0
    saved_iteration = iteration if resume is True else -1

    def checkpoint_now(st: TrainState) -> None:
        nonlocal save_s_est, saved_iteration
        t = time.time()
        it = int(jax.device_get(st.iteration))
        save_state(checkpoint.checkpoint_path(ckpt_dir, it), st, config, trainer.layout,
                   env=trainer.env)
        save_policy(run_dir / "policy.npz", st, config, trainer.layout)
        checkpoint.prune(ckpt_dir, tc.keep_checkpoints)
        save_s_est = max(save_s_est, time.time() - t)
        saved_iteration = it

    try:
        with _StopFlag() as flag:
            while True:
                if iteration >= target_iter:
                    stop_reason = "total_iterations"
                elif tc.max_env_steps > 0 and iteration * steps_per_iter >= tc.max_env_steps:
                    stop_reason = "max_env_steps"
                elif tc.time_budget_s > 0 and (
                    time.time() - t_start + 1.2 * chunk_s_est + 1.5 * save_s_est + 1.0
                    > tc.time_budget_s
                ):
                    stop_reason = "time_budget"
                elif flag.reason:
                    stop_reason = flag.reason
                if stop_reason:
                    break
                t = time.time()
                state, metrics = compiled(state)
                metrics = {k: float(v) for k, v in jax.device_get(metrics).items()}
                chunk_s = time.time() - t
                chunk_s_est = chunk_s
                iteration += K
                env_steps = iteration * steps_per_iter
                record = {
                    "iteration": iteration,
                    "env_steps": env_steps,
                    "wall_time": time.time() - t_start,
                    "perf/chunk_s": chunk_s,
                    "perf/steps_per_s": K * steps_per_iter / chunk_s,
                    "perf/compile_s": compile_s,
                    **metrics,
                }
                logger.log(record, step=env_steps)
                if bar is not None:
                    bar.update(K * steps_per_iter)
                    post = {"ret": f"{metrics['episode/return']:.3g}"}
                    for k in ("level", "success"):
                        if k in metrics:
                            post[k] = f"{metrics[k]:.3g}"
                    bar.set_postfix(post, refresh=False)
                if tc.console:
                    text = logging_utils.console_block(record, target_iter)
                    if bar is not None:
                        bar.write(text)
                    else:
                        print(text, flush=True)
                chunks_since_ckpt += 1
                if tc.checkpoint_every > 0 and chunks_since_ckpt >= tc.checkpoint_every:
                    checkpoint_now(state)
                    chunks_since_ckpt = 0
                if on_chunk is not None and on_chunk(record):
                    stop_reason = "on_chunk"
                    break
            if saved_iteration != iteration:
                checkpoint_now(state)
    finally:
        if bar is not None:
            bar.close()
        logger.close()
    msg = (f"stopped ({stop_reason}) at iteration {iteration}, "
           f"{iteration * steps_per_iter:,} env steps; run dir {run_dir}")
    print(msg, flush=True)
    return RunResult(run_dir, state, record, stop_reason)
