"""Throughput in one process, one model and atlas, one robot count at a time.

(a) physics only: `decimation` MJX steps per policy step with random torques, no env logic;
(b) the env: reset/step with observations, rewards, terminations, curriculum and auto-reset,
    random actions;
(r) the trainer's rollout alone: (b) plus policy inference and the critic's values, no update;
(c) full training: rollout + PPO update, the trainer's compiled chunk.
Each is reported as env (policy) steps per second after warm-up, with compile times and the
device's peak memory.
"""

from __future__ import annotations

import dataclasses
import json
import platform
import time
from typing import Any

import jax
import jax.numpy as jnp
from mujoco import mjx

from mjx_stairs.rl.rollout import rollout
from mjx_stairs.rl.trainer import build_trainer
from mjx_stairs.sim import robot as rb
from mjx_stairs.study.experiment import ExperimentConfig, make_env


def _time(fn, arg, repeats: int) -> tuple[float, float, Any]:
    """(compile seconds, median run seconds, last output) of a jitted fn(arg) -> same type."""
    t0 = time.time()
    compiled = jax.jit(fn).lower(arg).compile()
    compile_s = time.time() - t0
    out = compiled(arg)
    jax.block_until_ready(out)
    times = []
    for _ in range(repeats):
        t = time.time()
        out = compiled(out)
        jax.block_until_ready(out)
        times.append(time.time() - t)
    times.sort()
    return compile_s, times[len(times) // 2], out


def bench_physics(env, robots: int, steps: int, repeats: int) -> dict[str, float]:
    """(a) MJX physics only, random torques within the limits."""
    mx = env.robot.mjx_model
    limit = jnp.asarray(rb.TORQUE_LIMIT)
    dec = env.config.decimation
    keys = jax.random.split(jax.random.PRNGKey(0), robots)
    reset = jax.jit(jax.vmap(env.reset))(keys)
    data = reset.pipeline_state

    def policy_step(carry, _):
        d, k = carry
        k, sub = jax.random.split(k)
        tau = jax.random.uniform(sub, (robots, 12), minval=-1.0, maxval=1.0) * limit * 0.3

        def physics(d, _):
            return jax.vmap(lambda x, t: mjx.step(mx, x.replace(ctrl=t)))(d, tau), None

        d = jax.lax.scan(physics, d, None, length=dec)[0]
        return (d, k), None

    fn = lambda c: jax.lax.scan(policy_step, c, None, length=steps)[0]
    compile_s, run_s, _ = _time(fn, (data, jax.random.PRNGKey(1)), repeats)
    return {"compile_s": compile_s, "steps_per_s": robots * steps / run_s}


def bench_env(env, robots: int, steps: int, repeats: int) -> dict[str, float]:
    """(b) the full env step with random actions."""
    keys = jax.random.split(jax.random.PRNGKey(0), robots)
    state = jax.jit(jax.vmap(env.reset))(keys)

    def one(carry, _):
        s, k = carry
        k, sub = jax.random.split(k)
        a = jax.random.uniform(sub, (robots, env.action_size), minval=-1.0, maxval=1.0)
        return (jax.vmap(env.step)(s, a), k), None

    fn = lambda c: jax.lax.scan(one, c, None, length=steps)[0]
    compile_s, run_s, _ = _time(fn, (state, jax.random.PRNGKey(1)), repeats)
    return {"compile_s": compile_s, "steps_per_s": robots * steps / run_s}


def bench_train(config: ExperimentConfig, env, repeats: int) -> dict[str, float]:
    """(c) the trainer's compiled chunk: rollout + GAE + PPO update."""
    trainer = build_trainer(config, env)
    state = trainer.init(jax.random.PRNGKey(0))
    t0 = time.time()
    compiled = trainer.chunk.lower(state).compile()
    compile_s = time.time() - t0
    state, m = compiled(state)
    jax.block_until_ready(m)
    times = []
    for _ in range(repeats):
        t = time.time()
        state, m = compiled(state)
        jax.block_until_ready(m)
        times.append(time.time() - t)
    times.sort()
    tc = config.train
    steps = tc.num_envs * tc.unroll_length * tc.iterations_per_chunk
    return {"compile_s": compile_s, "steps_per_s": steps / times[len(times) // 2]}


def bench_rollout(config: ExperimentConfig, env, repeats: int) -> dict[str, float]:
    """(r) the trainer's rollout (policy inference, env steps, critic values), no update:
    ``iterations_per_chunk`` rollouts with fixed params as one scan, like the chunk."""
    trainer = build_trainer(config, env)
    state = trainer.init(jax.random.PRNGKey(0))
    kw = dict(config=config, env=env, layout=trainer.layout, mesh=trainer.mesh)

    def one(st, _):
        k, sub = jax.random.split(st.rng)
        (env_state, ep_return, ep_length), t, _, _, boot = rollout(st, sub, **kw)
        st = st._replace(env_state=env_state, ep_return=ep_return, ep_length=ep_length, rng=k)
        # keep the values and the recorded batch live, as the update would read them
        return st, jnp.sum(t.value) + jnp.sum(t.final_value) + jnp.sum(boot) + jnp.sum(
            t.log_prob) + jnp.sum(t.obs[..., 0]) + jnp.sum(t.critic_obs[..., 0])

    fn = lambda s: jax.lax.scan(one, s, None, length=config.train.iterations_per_chunk)[0]
    compile_s, run_s, _ = _time(fn, state, max(2, repeats // 2))
    tc = config.train
    steps = tc.num_envs * tc.unroll_length * tc.iterations_per_chunk
    return {"compile_s": compile_s, "steps_per_s": steps / run_s}


PARTS = ("physics", "env", "rollout", "train")  # (a), (b), (r), (c)


def _split(row: dict[str, Any], steps_per_iteration: int) -> dict[str, float]:
    """Seconds of one training iteration spent in each layer, from the rates of one run."""
    sec = {k: steps_per_iteration / row[k]["steps_per_s"] for k in PARTS if k in row}
    out = {}
    layers = [("physics", None, "physics"), ("env_overhead", "physics", "env"),
              ("policy_and_values", "env", "rollout"), ("update", "rollout", "train")]
    for name, below, top in layers:
        if top in sec and (below is None or below in sec):
            out[name] = sec[top] - (sec[below] if below else 0.0)
    return out


def _memory() -> dict[str, float]:
    stats = jax.devices()[0].memory_stats() or {}
    return {k: stats[k] / 2**30 for k in ("peak_bytes_in_use", "bytes_limit") if k in stats}


def run_bench(
    config: ExperimentConfig,
    robots: list[int],
    steps: int = 24,
    repeats: int = 5,
    parts: tuple[str, ...] = PARTS,
) -> dict[str, Any]:
    """Measure (a), (b), (r), (c) for each robot count with one model and atlas."""
    unknown = set(parts) - set(PARTS)
    if unknown:
        raise ValueError(f"bench: unknown parts {sorted(unknown)} (expected "
                         f"{', '.join(PARTS)})")
    env = make_env(config)
    out: dict[str, Any] = {
        "device": jax.devices()[0].device_kind,
        "devices": len(jax.devices()),
        "backend": jax.default_backend(),
        "host": platform.node(),
        "jax": jax.__version__,
        "atlas_shape": list(env.atlas_shape),
        "solver": {
            "iterations": config.env.robot.solver_iterations,
            "ls_iterations": config.env.robot.ls_iterations,
            "timestep": config.env.robot.timestep,
            "decimation": config.env.decimation,
            "shin_collision": config.env.robot.shin_collision,
            "terrain_contacts": config.env.robot.terrain_contacts,
        },
        "network": {"conv_impl": config.network.conv_impl},
        "contacts": env.num_contacts,
        "results": [],
    }
    for n in robots:
        row: dict[str, Any] = {"robots": n}
        cfg = dataclasses.replace(config, train=dataclasses.replace(config.train, num_envs=n))
        if "physics" in parts:
            row["physics"] = bench_physics(env, n, steps, repeats)
        if "env" in parts:
            row["env"] = bench_env(env, n, steps, repeats)
        if "rollout" in parts:
            row["rollout"] = bench_rollout(cfg, env, repeats)
        if "train" in parts:
            row["train"] = bench_train(cfg, env, max(2, repeats // 2))
        if "physics" in parts and "train" in parts:
            row["train_over_physics"] = row["train"]["steps_per_s"] / row["physics"]["steps_per_s"]
        row["seconds_per_iteration"] = _split(row, n * cfg.train.unroll_length)
        row["memory_gib"] = _memory()
        out["results"].append(row)
        print(json.dumps(row), flush=True)
    return out
