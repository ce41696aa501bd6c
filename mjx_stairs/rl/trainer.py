"""The compiled part of training: the trainer state, one iteration, a chunk of K, sharding.

``make_train(config, env)`` returns ``(init, chunk)``:

- ``init(rng) -> TrainState``: params, Adam state, normaliser, the batched env state (all robots
  reset with ``jax.vmap(env.reset)``), RNG, counters, running episode stats.
- ``chunk(state) -> (state, metrics)``: ONE jitted call running ``train.iterations_per_chunk``
  iterations as a ``lax.scan`` of (rollout scan of ``unroll_length`` steps for all robots ->
  GAE -> PPO update -> normaliser update). The state argument is donated.

``config`` is any object with attributes ``ppo`` (PPOConfig), ``network`` (NetworkConfig) and
``train`` (TrainConfig), e.g. ``LearnerConfig`` below or study.experiment's ExperimentConfig.
The env is described in rl.rollout; robots are split over the devices of every process
(rl.sharding, rl.distributed), and every reduction over them is global: one batch of
``num_envs`` robots trains the same on one device, several, or several processes.
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Literal, NamedTuple

import jax
import jax.numpy as jnp
from jax.sharding import Mesh

from mjx_stairs.rl import checkpoint, networks, normalizer, optim, ppo
from mjx_stairs.rl import policy as policy_lib
from mjx_stairs.rl.networks import NetworkConfig, ObsLayout
from mjx_stairs.rl.policy import OBS_KEYS
from mjx_stairs.rl.ppo import PPOConfig
from mjx_stairs.rl.rollout import Transition, obs_layout, rollout
from mjx_stairs.rl.sharding import batched, constrain, make_mesh, put_global, replicated


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
    checkpoint_env: Literal["full", "packed"] = field(
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


def state_sharding(state: TrainState, mesh: Mesh) -> TrainState:
    """Shardings for a TrainState (or its eval_shape): robot axis split, the rest replicated."""
    rep, bat = replicated(mesh), batched(mesh)

    def per_robot(x):
        return bat if len(getattr(x, "shape", ())) >= 1 else rep

    return TrainState(
        params=jax.tree_util.tree_map(lambda _: rep, state.params),
        opt_state=jax.tree_util.tree_map(lambda _: rep, state.opt_state),
        normalizer=jax.tree_util.tree_map(lambda _: rep, state.normalizer),
        env_state=jax.tree_util.tree_map(per_robot, state.env_state),
        rng=rep,
        iteration=rep,
        ep_return=bat,
        ep_length=bat,
    )


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



# ----------------------------------------------------------------------------- one iteration


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
    return constrain(batch, mesh, 0), termination


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
            constrain=lambda b: constrain(b, mesh, 1),
            mirror=env.mirror if pc.mirror_loss_coef > 0 else None,
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
        if k.startswith("_ep/") or k.endswith(("#num", "#den")):
            continue
        out[k] = jnp.mean(v)
    for k in per_iter:  # an env's ratio metric X#num over X#den: X (nan where X#den is 0)
        if k.endswith("#num") and k[:-4] + "#den" in per_iter:
            den = jnp.sum(per_iter[k[:-4] + "#den"])
            out[k[:-4]] = jnp.where(den > 0, jnp.sum(per_iter[k]) / jnp.maximum(den, 1e-9),
                                    jnp.nan)
    out["opt/lr"] = per_iter["opt/lr"][-1]
    count = jnp.sum(per_iter["_ep/count"])
    out["episode/count"] = count
    out["episode/return"] = jnp.sum(per_iter["_ep/return_sum"]) / jnp.maximum(count, 1.0)
    out["episode/length"] = jnp.sum(per_iter["_ep/length_sum"]) / jnp.maximum(count, 1.0)
    out["episode/terminations"] = jnp.sum(per_iter["episode/terminations"])
    out["episode/truncations"] = jnp.sum(per_iter["episode/truncations"])
    for k in per_iter:  # episode_success[_X] over done[_X]: success[_X]
        if k.startswith("episode_success") and "done" + k[15:] in per_iter:
            # success rate of the episodes that ended in this chunk (both are means over T x B)
            ended = jnp.sum(per_iter["done" + k[15:]])
            out["success" + k[15:]] = jnp.sum(per_iter[k]) / jnp.maximum(ended, 1e-9)
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
    """Sizes that must divide (the configs' string options are Literal: checked at load)."""
    tc, pc = config.train, config.ppo
    n_dev = mesh.devices.size
    if tc.num_envs % n_dev:
        raise ValueError(f"train.num_envs={tc.num_envs} must divide over {n_dev} devices")
    if not pc.mirror_loss_coef >= 0:
        raise ValueError(f"ppo.mirror_loss_coef must be >= 0, got {pc.mirror_loss_coef}")
    n = tc.num_envs * tc.unroll_length
    if n % pc.num_minibatches:
        raise ValueError(
            f"num_envs * unroll_length = {n} does not split into ppo.num_minibatches="
            f"{pc.num_minibatches}"
        )


_TRAINERS: dict[tuple, tuple[Any, Trainer]] = {}



def _compiled_config(config) -> LearnerConfig:
    """The part of a config the compiled functions depend on (host-only fields dropped)."""
    tc = config.train
    return LearnerConfig(
        ppo=config.ppo,
        network=config.network,
        train=TrainConfig(num_envs=tc.num_envs, unroll_length=tc.unroll_length,
                          iterations_per_chunk=tc.iterations_per_chunk),
    )


def build_trainer(config, env, mesh: Mesh | None = None) -> Trainer:
    """make_train plus what the host loop needs (layout, mesh, shardings, state template).

    Trainers are cached per (compile-relevant config, env object, devices), so repeated
    ``run`` calls in one process (tests, resume) reuse the compiled chunk.
    """
    mesh = make_mesh() if mesh is None else mesh
    _check(config, mesh)
    if config.ppo.mirror_loss_coef > 0 and getattr(env, "mirror", None) is None:
        raise ValueError(f"ppo.mirror_loss_coef = {config.ppo.mirror_loss_coef} needs an env "
                         "with a left-right mirror (env.mirror); this env has none")
    config = _compiled_config(config)
    key = (config, id(env), tuple(d.id for d in mesh.devices.flat))
    hit = _TRAINERS.get(key)
    if hit is not None and hit[0] is env:
        return hit[1]
    trainer = _build_trainer(config, env, mesh)
    _TRAINERS[key] = (env, trainer)
    return trainer


def _build_trainer(config, env, mesh: Mesh) -> Trainer:
    """The jitted init and chunk with their shardings (the state argument donated)."""
    layout = obs_layout(env)
    init_fn = functools.partial(init_state, config=config, env=env, layout=layout)
    template = jax.eval_shape(init_fn, jax.random.PRNGKey(0))
    sharding = state_sharding(template, mesh)
    init = jax.jit(init_fn, out_shardings=sharding)
    chunk_fn = functools.partial(run_chunk, config=config, env=env, layout=layout, mesh=mesh)
    chunk = jax.jit(chunk_fn, in_shardings=(sharding,), out_shardings=(sharding, replicated(mesh)),
                    donate_argnums=0)
    return Trainer(init, chunk, layout, mesh, sharding, template, env)


def make_train(config, env, mesh: Mesh | None = None):
    """``(init, chunk)``: ``init(rng) -> TrainState``; ``chunk(state) -> (state, metrics)``
    runs ``config.train.iterations_per_chunk`` iterations in one compiled call (state donated).
    """
    t = build_trainer(config, env, mesh)
    return t.init, t.chunk



_COMPILED: dict[int, Any] = {}



def compiled_chunk(trainer: Trainer, state: TrainState) -> tuple[Callable, float]:
    """(AOT-compiled chunk, compile seconds), cached: the first chunk's timing then excludes
    compilation (0 s for a cached one)."""
    hit = _COMPILED.get(id(trainer))
    if hit is not None and hit[0] is trainer:
        return hit[1], 0.0
    t0 = time.time()
    compiled = trainer.chunk.lower(state).compile()
    _COMPILED[id(trainer)] = (trainer, compiled)
    return compiled, time.time() - t0


def appends_terms(saved_env: dict, history: int, delay: bool, damping: bool = False) -> bool:
    """Whether an observation of `history` steps (the delay term, the damping term) only appends
    terms to the vector part of the one a policy of env config `saved_env` observed
    (env.observation's order: ..., goal, history, action delay, joint damping)."""
    def optional(h: int, d: bool, m: bool) -> list:
        return [t for t, on in ((("history", h), h > 0), ("delay", d), ("damping", m)) if on]

    old = optional(int(saved_env.get("obs_history", 0)),
                   bool(saved_env.get("obs_action_delay", False)),
                   bool(saved_env.get("obs_joint_damping", False)))
    new = optional(history, bool(delay), bool(damping))
    return len(new) > len(old) and new[:len(old)] == old


def new_inputs_seen(env, at: int, extra: int, n: int = 256) -> dict[str, jax.Array]:
    """The `extra` inputs at index `at` of each observation stream over `n` fresh resets of
    `env`: what a widened normaliser starts from (policy.appended_stats)."""
    obs = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(0), n)).obs
    return {k: obs[k][:, at:at + extra] for k in OBS_KEYS}


def start_from_policy(state: TrainState, path: str | Path, trainer: Trainer,
                      history: int = 0, std: float = 0.0, delay: bool = False,
                      damping: bool = False) -> TrainState:
    """Replace the params and normaliser of a fresh state by those of a policy file (stage 2
    starts from stage 1). The Adam moments, RNG and counters stay fresh. `std` > 0: the policy's
    exploration std (every action) is set to it, e.g. to explore again from a policy whose std
    has shrunk (a fine-tune on new terrain; 0 keeps the saved one). An experiment whose
    observation adds terms at the end of the saved policy's vector part (`history` steps of
    env.obs_history over a policy without history, the action delay term of
    env.obs_action_delay) starts from it through policy.widen_for_history: it acts as the
    saved policy at the start."""
    saved = policy_lib.load_policy(path)
    want = jax.tree_util.tree_map(jnp.shape, (state.params, state.normalizer))
    extra = int(state.normalizer["state"].mean.shape[0]) - saved.layout.obs_size
    if extra > 0 and appends_terms(policy_lib.saved_config(saved, "env") or {}, history, delay,
                                   damping):
        saved = policy_lib.widen_for_history(
            saved, extra, new_inputs_seen(trainer.env, saved.layout.n_vec, extra))
    got = jax.tree_util.tree_map(jnp.shape, (saved.params, saved.normalizer))
    if want != got:
        raise checkpoint.CheckpointError(
            f"{path}: policy shapes do not fit this experiment's network and observation layout"
        )
    params = dict(saved.params)
    if std > 0:
        params["log_std"] = jnp.full_like(params["log_std"], math.log(std))
    params = put_global(params, trainer.sharding.params)
    norm = put_global(saved.normalizer, trainer.sharding.normalizer)
    return state._replace(params=params, normalizer=norm)
