"""Checkpoints of a training run: the whole TrainState (resume) and the policy file beside it.

``<run_dir>/checkpoints/state_<it>.npz`` holds the full TrainState (the newest
``train.keep_checkpoints``), ``<run_dir>/policy.npz`` the policy (rl.policy). Bit-exact resume
holds on the CPU. On a GPU, XLA's default kernels (cuDNN conv backward, atomic reductions) are
not run-to-run deterministic, so a resumed run matches only up to float noise unless the process
starts with ``XLA_FLAGS=--xla_gpu_deterministic_ops=true`` (seen on an H100: the resume test
fails without it and passes with it).

With several processes (rl.distributed) every process calls the savers (the robots split over
other processes' devices are gathered) and process 0 writes; a checkpoint holds the global host
arrays, so one written by N processes resumes on any M whose devices divide the robots. Every
process reads the file it resumes from (a shared filesystem, or the file copied to each host).
"""

from __future__ import annotations

import functools
import time
from pathlib import Path
from typing import Any, Callable

import jax
import numpy as np

from mjx_stairs.rl import checkpoint
from mjx_stairs.rl import policy as policy_lib
from mjx_stairs.rl.distributed import is_main
from mjx_stairs.rl.networks import ObsLayout
from mjx_stairs.rl.policy import config_dict, layout_dict
from mjx_stairs.rl.sharding import batched, put_global, to_host
from mjx_stairs.rl.trainer import Trainer, TrainState, new_inputs_seen

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
    """Full checkpoint: the whole TrainState + config and counters as metadata. Every process
    calls it; process 0 writes.

    With ``train.checkpoint_env == "packed"`` the env state is stored as
    ``vmap(env.pack_state)`` (``env`` required) and rebuilt with ``env.unpack_state`` on load.
    """
    tc = config.train
    env_format = tc.checkpoint_env
    if env_format == "packed":
        pack, _ = _packers(env)
        state = state._replace(env_state=pack(state.env_state))
    host = to_host(state)
    if not is_main():
        return
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
        "processes": jax.process_count(),
        "saved_at": time.time(),
    }
    meta.update(extra or {})
    checkpoint.save(path, host, meta)



def load_state(path: str | Path, trainer: Trainer,
               widen: Callable[[dict], bool] | None = None) -> tuple[TrainState, dict]:
    """Read a full checkpoint into the trainer's TrainState structure, placed on its mesh.

    ``widen(saved env config) -> bool``: whether a checkpoint whose observation is shorter than
    the trainer's may be resumed with the new inputs at the end of its vector part (e.g. the
    action delay term added, trainer.appends_terms): zero weights and Adam moments for them in
    the first actor and critic layer, their normaliser entries from 256 fresh resets of the
    trainer's env (trainer.new_inputs_seen), zeros in the stored actor observation; the run
    goes on with its curriculum, optimiser and counters. A state saved before a per-step metric
    was added resumes (_step_metric)."""
    meta = checkpoint.load_metadata(path)
    if meta.get("kind") != "train_state":
        raise checkpoint.CheckpointError(f"{path}: not a train-state checkpoint")
    packed_format = meta.get("env_format", "full") == "packed"
    template = trainer.template
    if packed_format:
        pack, unpack = _packers(trainer.env)
        template = template._replace(env_state=jax.eval_shape(pack, template.env_state))
    extra = int(template.normalizer["state"].mean.shape[0]) - int(
        meta.get("layout", {}).get("obs_size", 0))
    saved_env = (meta.get("config") or {}).get("env") or {}
    widened = extra > 0 and widen is not None and widen(saved_env)
    if widened and not packed_format:
        raise checkpoint.CheckpointError(f"{path}: only a packed checkpoint "
                                         "(train.checkpoint_env='packed') resumes widened")
    at_obs = int(meta["layout"]["n_vec"]) if widened else 0
    host, meta = checkpoint.load(path, _resized(template, at_obs, extra, widen=False) if widened
                                 else template, zero_if_missing=_step_metric)
    if widened:
        host = _resized(host, at_obs, extra, widen=True,
                        seen=new_inputs_seen(trainer.env, at_obs, extra))
    if packed_format:
        bat = batched(trainer.mesh)
        packed = put_global(host.env_state,
                            jax.tree_util.tree_map(lambda _: bat, template.env_state))
        env_state = jax.device_put(unpack(packed), trainer.sharding.env_state)
        state = put_global(host._replace(env_state=None),
                           trainer.sharding._replace(env_state=None))
        return state._replace(env_state=env_state), meta
    return put_global(host, trainer.sharding), meta


def _step_metric(tree_path: str) -> bool:
    """An entry of the env state's metrics: the env rewrites every one each step (a metric added
    after a state was saved starts as zeros, which the first step replaces)."""
    return tree_path.startswith((".env_state.metrics[", ".env_state['metrics']["))  # full, packed


def _resized(state: TrainState, at_obs: int, extra: int, widen: bool,
             seen: dict | None = None) -> TrainState:
    """The leaves of a packed TrainState that an observation `extra` floats longer at the end of
    its vector part (index `at_obs` of the narrow one) changes: narrow arrays widened (widen:
    policy.append_inputs for the params and Adam moments, policy.appended_stats from the new inputs
    `seen` per stream, zeros in the stored observation), else the narrow shapes of a template
    of ShapeDtypeStructs."""
    def narrow(x, axis=0):
        shape = list(x.shape)
        shape[axis] -= extra
        return jax.ShapeDtypeStruct(tuple(shape), x.dtype)

    def narrow_layers(params):
        return {**params, **{n: [{**params[n][0], "w": narrow(params[n][0]["w"])},
                                 *params[n][1:]] for n in ("actor", "critic")}}

    if widen:
        layers = functools.partial(policy_lib.append_inputs, extra=extra)
        stats = lambda k, st: policy_lib.appended_stats(st, at_obs, extra, seen[k])  # noqa: E731
        obs = lambda x: np.insert(x, [at_obs] * extra, 0.0, axis=1)  # noqa: E731
    else:
        layers = narrow_layers
        stats = lambda k, st: st._replace(mean=narrow(st.mean), m2=narrow(st.m2))  # noqa: E731
        obs = functools.partial(narrow, axis=1)
    opt = state.opt_state
    return state._replace(
        params=layers(state.params), opt_state=opt._replace(mu=layers(opt.mu), nu=layers(opt.nu)),
        normalizer={k: stats(k, v) for k, v in state.normalizer.items()},
        env_state={**state.env_state, "obs": obs(state.env_state["obs"])})


def save_policy(path: str | Path, state: TrainState, config, layout: ObsLayout) -> None:
    """The policy file of a TrainState (rl.policy.save_policy), written by process 0."""
    params, norm, it = to_host((state.params, state.normalizer, state.iteration))
    if is_main():
        policy_lib.save_policy(path, params, norm, int(it), config, layout)


class Checkpointer:
    """Writes a run's checkpoints: every ``train.checkpoint_every`` chunks and at the end."""

    def __init__(self, run_dir: Path, config, trainer: Trainer, saved_iteration: int = -1):
        self.run_dir = Path(run_dir)
        self.directory = self.run_dir / "checkpoints"
        self.config = config
        self.trainer = trainer
        self.saved_iteration = saved_iteration  # the iteration of the newest checkpoint
        self.save_s = 0.0  # the longest save so far (the time budget keeps room for one)
        self._chunks = 0

    def save(self, state: TrainState) -> None:
        """The full state, the policy file, then the oldest checkpoints pruned."""
        t = time.time()
        it = int(jax.device_get(state.iteration))
        save_state(checkpoint.checkpoint_path(self.directory, it), state, self.config,
                   self.trainer.layout, env=self.trainer.env)
        save_policy(self.run_dir / "policy.npz", state, self.config, self.trainer.layout)
        if is_main():
            checkpoint.prune(self.directory, self.config.train.keep_checkpoints)
        self.save_s = max(self.save_s, time.time() - t)
        self.saved_iteration = it

    def after_chunk(self, state: TrainState) -> None:
        """Save when ``checkpoint_every`` chunks have run since the last save."""
        self._chunks += 1
        every = self.config.train.checkpoint_every
        if every > 0 and self._chunks >= every:
            self.save(state)
            self._chunks = 0

    def finish(self, state: TrainState, iteration: int) -> None:
        """Save unless the newest checkpoint already holds ``iteration``."""
        if self.saved_iteration != iteration:
            self.save(state)
