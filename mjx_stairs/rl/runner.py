"""The host side of training: ``run`` reads like rsl_rl's ``learn``.

    state = start (fresh, from a policy file, or resumed from a checkpoint)
    per chunk: rollout -> GAE -> PPO update  (K iterations in one compiled call, rl.trainer)
               -> log (rl.logger) -> save (rl.checkpointer)

until ``train.total_iterations`` (rounded up to whole chunks), ``max_env_steps``, the
``time_budget_s`` or a signal. With several processes (rl.distributed) every process runs this
loop on its own devices; they agree on the run directory (process 0's) and on when to stop, and
only process 0 logs and writes files. The run directory,
``<log_dir>/<experiment>__<seed>__<YYYYmmdd-HHMMSS>/``::

    config.json                  the whole config (JSON of the dataclasses)
    metrics.jsonl                one line per chunk: iteration, env_steps, wall_time, perf/*,
                                 episode/*, loss/*, opt/*, value/*, every env metric
    tb/                          TensorBoard scalars (x axis: env steps)
    checkpoints/state_<it>.npz   full TrainState (the newest ``keep_checkpoints``)
    policy.npz                   params + normaliser + network config + obs layout (rl.policy)
"""

from __future__ import annotations

import json
import math
import signal
import time
import warnings
from pathlib import Path
from typing import Any, Callable, NamedTuple

import jax
import numpy as np
from jax.sharding import Mesh

from mjx_stairs import atomic
from mjx_stairs.rl import checkpoint, distributed, logger
from mjx_stairs.rl.checkpointer import Checkpointer, load_state
from mjx_stairs.rl.policy import config_dict
from mjx_stairs.rl.sharding import put_global, to_host
from mjx_stairs.rl.trainer import (
    Trainer,
    TrainState,
    appends_terms,
    build_trainer,
    compiled_chunk,
    start_from_policy,
)


class TrainingDiverged(ValueError):
    """The PPO update went non-finite: the run stopped without saving the diverged state."""


class RunResult(NamedTuple):
    run_dir: Path
    state: TrainState
    metrics: dict[str, Any]  # last chunk's record
    stop_reason: str



def _config_diff(a: dict, b: dict, prefix: str = "", inert: dict | None = None) -> list[str]:
    """Every value that differs, as "key: old -> new"; a key in `inert` (the env's
    RESUME_INERT: {key: why}) is said to do nothing on a resume, and why."""
    out = []
    for k in sorted(set(a) | set(b)):
        key = f"{prefix}.{k}" if prefix else k
        va, vb = a.get(k), b.get(k)
        if isinstance(va, dict) and isinstance(vb, dict):
            out.extend(_config_diff(va, vb, key, inert))
        elif va != vb:
            why = (inert or {}).get(key)
            out.append(f"{key}: {va!r} -> {vb!r}"
                       + (f" (no effect on a resumed run: {why})" if why else ""))
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
    """Train until a stop (module docstring); checkpoint and return.

    run_dir: None -> a new ``<log_dir>/<experiment>__<seed>__<time>`` (or, with resume=True,
      the newest such directory).
    resume: True -> continue from the newest ``<run_dir>/checkpoints/state_*.npz``; a path ->
      continue from that state file (e.g. one carried from another machine), logging into
      ``run_dir`` (a new run directory when None).
    on_chunk(record): called after each chunk with the logged record; returning True stops
      (on every process: each one's metrics are the same global values).
    """
    t_start = time.time()
    tc = config.train
    trainer = build_trainer(config, env, mesh)
    run_dir = _run_dir(tc, run_dir, resume)
    state = _start(trainer, config, run_dir, resume, getattr(env, "RESUME_INERT", {}))
    compiled, compile_s = compiled_chunk(trainer, state)
    iteration = int(jax.device_get(state.iteration))
    K, steps_per_iter = tc.iterations_per_chunk, tc.num_envs * tc.unroll_length
    target = -(-tc.total_iterations // K) * K
    saver = Checkpointer(run_dir, config, trainer, iteration if resume is True else -1)
    log = _logger(run_dir, tc, steps_per_iter, iteration, target)
    record: dict[str, Any] = {}
    chunk_s, asked = 0.0, ""
    try:
        with _StopFlag() as flag:
            while not (stop := distributed.agree(asked or _stop_reason(
                    tc, iteration, target, t_start, chunk_s, saver.save_s, flag.reason))):
                t = time.time()
                state, metrics = compiled(state)  # K x (rollout -> GAE -> PPO update)
                metrics = {k: float(v) for k, v in jax.device_get(metrics).items()}
                chunk_s = time.time() - t
                iteration += K
                record = {"iteration": iteration, "env_steps": iteration * steps_per_iter,
                          "wall_time": time.time() - t_start, "perf/chunk_s": chunk_s,
                          "perf/steps_per_s": K * steps_per_iter / chunk_s,
                          "perf/compile_s": compile_s, **metrics}
                log.log(record)  # a diverged chunk's row too: the curve shows where
                if bad := _non_finite(record):
                    asked = f"diverged ({bad})"  # the loop stops; this state is not saved
                    continue
                saver.after_chunk(state)
                if on_chunk is not None and on_chunk(record):
                    asked = "on_chunk"
            if not (diverged := stop.startswith("diverged")):
                saver.finish(state, iteration)
    finally:
        log.close()
    if diverged:
        raise _diverged(stop, iteration, record, run_dir)
    _say(f"stopped ({stop}) at iteration {iteration}, {iteration * steps_per_iter:,} env steps; "
         f"run dir {run_dir}")
    return RunResult(run_dir, state, record, stop)


def _diverged(stop: str, iteration: int, record: dict[str, Any], run_dir: Path) -> TrainingDiverged:
    last = checkpoint.latest_checkpoint(run_dir / "checkpoints")
    return TrainingDiverged(
        f"training {stop} in the chunk ending at iteration {iteration} "
        f"(nan_reset {record.get('nan_reset', float('nan')):.3g} of robot-steps); nothing of "
        f"it was saved, the newest checkpoint is {last or 'none'}")


def _non_finite(record: dict[str, Any]) -> str:
    """The PPO losses and gradient norm of a chunk's record that are not finite ("" if none):
    a NaN there has already reached the parameters (a physics blow-up's rewards do it: the
    generalist in the lean physics with implicit damping, 2026-11-27, trained 1790 iterations of
    NaN before this check)."""
    bad = [f"{k} is {v}" for k, v in record.items()
           if (k.startswith("loss/") or k == "opt/grad_norm") and not math.isfinite(v)]
    return ", ".join(bad)


def _stop_reason(tc, iteration: int, target: int, t_start: float, chunk_s: float,
                 save_s: float, signal_reason: str) -> str:
    """Why the run stops before its next chunk, or "" to go on (the time budget keeps room for
    one more chunk and one save)."""
    if iteration >= target:
        return "total_iterations"
    if tc.max_env_steps > 0 and iteration * tc.num_envs * tc.unroll_length >= tc.max_env_steps:
        return "max_env_steps"
    if tc.time_budget_s > 0 and (
        time.time() - t_start + 1.2 * chunk_s + 1.5 * save_s + 1.0 > tc.time_budget_s
    ):
        return "time_budget"
    return signal_reason


def _run_dir(tc, run_dir: str | Path | None, resume: bool | str | Path) -> Path:
    """The given run directory, the newest of this experiment and seed (resume=True), or new;
    process 0 chooses and creates it, the others take its choice."""
    chosen = ""
    if distributed.is_main():
        try:
            chosen = str(_choose_run_dir(tc, run_dir, resume))
        except FileNotFoundError as e:
            chosen = f"\0{e}"
    chosen = distributed.main_text(chosen)
    if chosen.startswith("\0"):
        raise FileNotFoundError(chosen[1:])
    return Path(chosen)


def _choose_run_dir(tc, run_dir: str | Path | None, resume: bool | str | Path) -> Path:
    if run_dir is None:
        if resume is True:
            run_dir = logger.latest_run_dir(tc.log_dir, tc.experiment, tc.seed)
            if run_dir is None:
                raise FileNotFoundError(
                    f"--resume: no run '{tc.experiment}__{tc.seed}__*' under {tc.log_dir}"
                )
        else:
            run_dir = logger.new_run_dir(tc.log_dir, tc.experiment, tc.seed)
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    return run_dir


def _start(trainer: Trainer, config, run_dir: Path, resume: bool | str | Path,
           inert: dict | None = None) -> TrainState:
    """The state to train from: resumed from a checkpoint (a changed config warned of, `inert`
    keys as doing nothing), or fresh (params and normaliser from ``config.init_from`` when set);
    a fresh run writes config.json (process 0)."""
    main = distributed.is_main()
    env = getattr(config, "env", None)  # the observation's layout (rl knows no env config)
    hist, delay = getattr(env, "obs_history", 0), getattr(env, "obs_action_delay", False)
    damping = getattr(env, "obs_joint_damping", False)
    if resume:
        ckpt_dir = run_dir / "checkpoints"
        path = checkpoint.latest_checkpoint(ckpt_dir) if resume is True else Path(resume)
        if path is None:
            raise checkpoint.CheckpointError(f"{ckpt_dir}: no checkpoint to resume from")
        state, meta = load_state(path, trainer,
                                 widen=lambda saved: appends_terms(saved, hist, delay, damping))
        diff = _config_diff(meta.get("config", {}), config_dict(config), inert=inert)
        if diff and main:
            warnings.warn(f"resuming {path} with a changed config: {'; '.join(diff)}",
                          stacklevel=3)
        if main:
            logger.truncate_jsonl(run_dir / "metrics.jsonl", int(meta["iteration"]))
            if not (run_dir / "config.json").exists():  # resumed into a new run dir
                _write_config(run_dir, config)
        _say(f"resumed {path} at iteration {meta['iteration']}")
        return _reseeded(state, meta, config, trainer)
    state = trainer.init(jax.random.PRNGKey(config.train.seed))
    init_from = getattr(config, "init_from", "")
    if init_from:
        std = getattr(config, "init_from_std", 0.0)
        state = start_from_policy(state, init_from, trainer, history=hist, std=std,
                                  delay=delay, damping=damping)
        _say(f"initialised params and normaliser from {init_from}"
             + (f", exploration std {std}" if std else ""))
    if main:
        _write_config(run_dir, config)
    return state


def _reseeded(state: TrainState, meta: dict, config, trainer: Trainer) -> TrainState:
    """A resumed state under the seed it was saved with: unchanged (the resume is exact). Under
    another ``train.seed``: its key folded with the new seed, so that runs continued from one
    state under two seeds draw two streams (replicates of a continuation, where a seed change
    would otherwise change nothing but the run directory's name)."""
    saved = meta.get("config", {}).get("train", {}).get("seed")
    seed = config.train.seed
    if saved is None or saved == seed:
        return state
    key = jax.random.fold_in(to_host(state.rng), seed)
    _say(f"reseeded: the saved state's train.seed {saved} -> {seed}")
    return state._replace(rng=put_global(np.asarray(key), trainer.sharding.rng))


def _write_config(run_dir: Path, config) -> None:
    """The run's config.json (the whole config as JSON), written atomically."""
    atomic.write_text(run_dir / "config.json", json.dumps(config_dict(config), indent=2))


def _logger(run_dir: Path, tc, steps_per_iter: int, iteration: int, target: int):
    """The run's RunLogger on process 0, a SilentLogger elsewhere."""
    if not distributed.is_main():
        return logger.SilentLogger()
    return logger.RunLogger(run_dir, steps_per_iteration=steps_per_iter, iteration=iteration,
                            target_iteration=target, tensorboard=tc.tensorboard,
                            progress=tc.progress, console=tc.console)


def _say(text: str) -> None:
    """Print on process 0 only."""
    if distributed.is_main():
        print(text, flush=True)
