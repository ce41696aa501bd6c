"""Throughput in one process, one model and atlas, one robot count and device set at a time.

(a) physics only: `decimation` MJX steps per policy step with random torques, no env logic;
(b) the env: reset/step with observations, rewards, terminations, curriculum and auto-reset,
    random actions;
(r) the trainer's rollout alone: (b) plus policy inference and the critic's values, no update;
(c) full training: rollout + PPO update, the trainer's compiled chunk.
Each is reported as env (policy) steps per second after warm-up, with compile times and the
devices' peak memory. Every part splits the robots over the same devices (rl.sharding).
``run_bench`` measures robot counts over all devices; ``run_scaling`` the first N devices for
each N, at ``per_device`` robots per device (weak scaling) and at a fixed total (strong).
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
from mjx_stairs.rl.sharding import batched, constrain, make_mesh, replicated
from mjx_stairs.rl.trainer import build_trainer
from mjx_stairs.sim import robot as rb
from mjx_stairs.study.experiment import ExperimentConfig, make_env


def _time(fn, arg, repeats: int) -> tuple[float, float, Any]:
    """(compile seconds, median run seconds, last output) of a jitted fn(arg) -> same type,
    the output placed as the input (so it feeds the next call)."""
    t0 = time.time()
    placed = jax.tree_util.tree_map(lambda x: x.sharding, arg)
    compiled = jax.jit(fn, out_shardings=placed).lower(arg).compile()
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


def _spread(tree) -> int:
    """How many devices hold the widest-spread array of ``tree`` (the robots' devices)."""
    return max(len(x.sharding.device_set) for x in jax.tree_util.tree_leaves(tree))


def _key(mesh) -> jax.Array:
    """The random actions' key, on every device of the mesh."""
    return jax.device_put(jax.random.PRNGKey(1), replicated(mesh))


def _reset(env, robots: int, mesh):
    """All robots reset, split over the mesh."""
    keys = jax.random.split(jax.random.PRNGKey(0), robots)
    return jax.jit(jax.vmap(env.reset), out_shardings=batched(mesh))(keys)


def bench_physics(env, robots: int, steps: int, repeats: int, mesh, model=None,
                  data=None) -> dict[str, Any]:
    """(a) MJX physics only, random torques within the limits, robots split over the mesh.
    `model` / `data` (batched): another MJX model and its robots' data on the env's atlas (e.g.
    MuJoCo Warp's, experiments/gpu/warp_physics.py); default the env's, reset. The last
    data is returned under "data"."""
    mx = env.robot.mjx_model if model is None else model
    limit = jnp.asarray(rb.TORQUE_LIMIT)
    dec = env.config.decimation
    data = _reset(env, robots, mesh).pipeline_state if data is None else data

    def policy_step(carry, _):
        d, k = carry
        k, sub = jax.random.split(k)
        tau = jax.random.uniform(sub, (robots, 12), minval=-1.0, maxval=1.0) * limit * 0.3
        tau, d = constrain((tau, d), mesh, 0)

        def physics(d, _):
            return jax.vmap(lambda x, t: mjx.step(mx, x.replace(ctrl=t)))(d, tau), None

        d = jax.lax.scan(physics, d, None, length=dec)[0]
        return (d, k), None

    fn = lambda c: jax.lax.scan(policy_step, c, None, length=steps)[0]
    compile_s, run_s, out = _time(fn, (data, _key(mesh)), repeats)
    return {"compile_s": compile_s, "steps_per_s": robots * steps / run_s,
            "devices_used": _spread(out), "data": out[0]}


def bench_env(env, robots: int, steps: int, repeats: int, mesh) -> dict[str, float]:
    """(b) the full env step with random actions, robots split over the mesh."""
    state = _reset(env, robots, mesh)

    def one(carry, _):
        s, k = carry
        k, sub = jax.random.split(k)
        a = jax.random.uniform(sub, (robots, env.action_size), minval=-1.0, maxval=1.0)
        a, s = constrain((a, s), mesh, 0)
        return (jax.vmap(env.step)(s, a), k), None

    fn = lambda c: jax.lax.scan(one, c, None, length=steps)[0]
    compile_s, run_s, out = _time(fn, (state, _key(mesh)), repeats)
    return {"compile_s": compile_s, "steps_per_s": robots * steps / run_s,
            "devices_used": _spread(out)}


def bench_train(config: ExperimentConfig, env, repeats: int, mesh) -> dict[str, float]:
    """(c) the trainer's compiled chunk: rollout + GAE + PPO update."""
    trainer = build_trainer(config, env, mesh)
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
    return {"compile_s": compile_s, "steps_per_s": steps / times[len(times) // 2],
            "devices_used": _spread(state.env_state)}


def bench_rollout(config: ExperimentConfig, env, repeats: int, mesh) -> dict[str, float]:
    """(r) the trainer's rollout (policy inference, env steps, critic values), no update:
    ``iterations_per_chunk`` rollouts with fixed params as one scan, like the chunk."""
    trainer = build_trainer(config, env, mesh)
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
    compile_s, run_s, out = _time(fn, state, max(2, repeats // 2))
    tc = config.train
    steps = tc.num_envs * tc.unroll_length * tc.iterations_per_chunk
    return {"compile_s": compile_s, "steps_per_s": steps / run_s,
            "devices_used": _spread(out.env_state)}


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


def _memory(mesh) -> dict[str, float]:
    """The largest peak (and the limit) over the mesh's devices, GiB."""
    out: dict[str, float] = {}
    for d in mesh.devices.flat:
        stats = d.memory_stats() or {}
        for k in ("peak_bytes_in_use", "bytes_limit"):
            if k in stats:
                out[k] = max(out.get(k, 0.0), stats[k] / 2**30)
    return out


def _check_parts(parts: tuple[str, ...]) -> None:
    unknown = set(parts) - set(PARTS)
    if unknown:
        raise ValueError(f"bench: unknown parts {sorted(unknown)} (expected "
                         f"{', '.join(PARTS)})")


def _header(config: ExperimentConfig, env) -> dict[str, Any]:
    """What a bench ran on: devices, model, solver, network."""
    return {
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
            "head_collision": config.env.robot.head_collision,
            "calf_collision": config.env.robot.calf_collision,
            "thigh_collision": config.env.robot.thigh_collision,
            "limb_capsules": config.env.robot.limb_capsules,
            "terrain_contacts": config.env.robot.terrain_contacts,
        },
        "network": {"conv_impl": config.network.conv_impl},
        "contacts": env.num_contacts,
        "results": [],
    }


def measure(config: ExperimentConfig, env, robots: int, mesh, parts: tuple[str, ...],
            steps: int = 24, repeats: int = 5) -> dict[str, Any]:
    """One row: the parts at ``robots`` robots split over ``mesh``."""
    row: dict[str, Any] = {"robots": robots, "devices": int(mesh.devices.size)}
    cfg = dataclasses.replace(config, train=dataclasses.replace(config.train, num_envs=robots))
    if "physics" in parts:
        row["physics"] = bench_physics(env, robots, steps, repeats, mesh)
        row["physics"].pop("data")
    if "env" in parts:
        row["env"] = bench_env(env, robots, steps, repeats, mesh)
    if "rollout" in parts:
        row["rollout"] = bench_rollout(cfg, env, repeats, mesh)
    if "train" in parts:
        row["train"] = bench_train(cfg, env, max(2, repeats // 2), mesh)
    if "physics" in parts and "train" in parts:
        row["train_over_physics"] = row["train"]["steps_per_s"] / row["physics"]["steps_per_s"]
    row["seconds_per_iteration"] = _split(row, robots * cfg.train.unroll_length)
    row["memory_gib"] = _memory(mesh)
    print(json.dumps(row), flush=True)
    return row


def run_bench(
    config: ExperimentConfig,
    robots: list[int],
    steps: int = 24,
    repeats: int = 5,
    parts: tuple[str, ...] = PARTS,
) -> dict[str, Any]:
    """Measure (a), (b), (r), (c) for each robot count with one model and atlas, all devices."""
    _check_parts(parts)
    env = make_env(config)
    out = _header(config, env)
    mesh = make_mesh()
    for n in robots:
        out["results"].append(measure(config, env, n, mesh, parts, steps, repeats))
    return out


SCALINGS = ("weak", "strong")


def run_scaling(
    config: ExperimentConfig,
    devices: list[int],
    per_device: int = 4096,
    total: int = 16384,
    scalings: tuple[str, ...] = SCALINGS,
    steps: int = 24,
    repeats: int = 5,
    parts: tuple[str, ...] = ("physics", "train"),
) -> dict[str, Any]:
    """Rows over the first N devices for each N in ``devices``: ``per_device`` robots on each
    (weak scaling) and ``total`` robots split over them (strong scaling); a row both kinds share
    (N x per_device == total) is measured once. ``scaling`` sums them up (``efficiency``)."""
    _check_parts(parts)
    if set(scalings) - set(SCALINGS) or not scalings:
        raise ValueError(f"bench: scalings {list(scalings)}, expected some of {list(SCALINGS)}")
    available, devices = jax.devices(), sorted(set(devices))
    if max(devices) > len(available) or min(devices) < 1:
        raise ValueError(f"bench: --devices {devices}, but {len(available)} devices are visible")
    env = make_env(config)
    out = _header(config, env)
    out.update(per_device=per_device, total=total)
    rows: dict[tuple[int, int], dict[str, Any]] = {}
    for n in devices:
        mesh = make_mesh(available[:n])
        for scaling in scalings:
            robots = per_device * n if scaling == "weak" else total
            if robots % n:
                raise ValueError(f"bench: {robots} robots do not split over {n} devices")
            if (n, robots) not in rows:
                rows[(n, robots)] = measure(config, env, robots, mesh, parts, steps, repeats)
            out["results"].append({"scaling": scaling, **rows[(n, robots)]})
    out["scaling"] = efficiency(out["results"])
    print(json.dumps(out["scaling"], indent=1), flush=True)
    return out


def efficiency(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per (scaling, devices): each part's rate over N times the one-device rate of the same
    scaling (weak: N x per-device robots; strong: the same robots), and the chunk's compile
    time. None where the one-device row is missing."""
    out = []
    for r in rows:
        base = next((b for b in rows if b["scaling"] == r["scaling"] and b["devices"] == 1), None)
        n = r["devices"]
        item: dict[str, Any] = {"scaling": r["scaling"], "devices": n, "robots": r["robots"]}
        for part in PARTS:
            if part not in r:
                continue
            rate = r[part]["steps_per_s"]
            item[f"{part}_steps_per_s"] = rate
            item[f"{part}_efficiency"] = (rate / (n * base[part]["steps_per_s"])
                                          if base is not None else None)
        if "train" in r:
            item["train_compile_s"] = r["train"]["compile_s"]
        out.append(item)
    return out
