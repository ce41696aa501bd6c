"""Where robots end and how they get there (issue 24: the generalist's low success going up).

Rolls a policy's first episode per robot on one family's levels, in the evaluation env (the
same as `mjx_stairs eval`: mean action, evaluation physics, same resets for the same seed), and
logs per robot: progress along the tile's centre-line over time, the final planar distance to
the goal, where the robot ends (spawn landing / on the flights / goal landing), base height
above the terrain, heading error to the waypoint's heading, forward speed and the time spent
standing still. Prints a summary per level and writes the per-robot table as JSON.

    PYTHONPATH=. JAX_PLATFORMS=cpu python experiments/diagnose_episodes.py \
        --checkpoint experiments/results/generalist/policy.npz --family straight \
        --levels 1,3 --robots 16 --episode-s 30 --out /tmp/diag.json
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time

import jax
import jax.numpy as jnp
import numpy as np

import terrains
from mjx_stairs.env import rewards as rw
from mjx_stairs.env.geometry import base_kinematics, wrap_angle
from mjx_stairs.env.stair_env import StairEnv
from mjx_stairs.rl.policy import load_policy, policy_action
from mjx_stairs.study.evaluate import env_config_of, make_eval_env, physics_overrides
from mjx_stairs.study.specs import EvalSpec

STILL_SPEED = 0.1  # m/s: planar speed under which a robot counts as standing still
MARKS_S = (5.0, 10.0, 15.0, 20.0, 25.0, 30.0)  # progress reported at these times


def rollout(env, policy, state):
    """Per step [T, B] records of each robot's first episode (frozen once it ended)."""
    tiles = env.tiles

    def measure(st):
        d = st.pipeline_state
        kin = base_kinematics(d.qpos, d.qvel)
        tile = st.info["tile"]
        goal = tiles.goal[tile]
        dc, arc = rw.centreline_geometry(kin.pos[:2], tiles.line[tile], tiles.line_cum[tile])
        target = env.goal_target(kin.pos, tile, arc, st.info)
        return {
            "arc": arc,
            "centreline_distance": dc,
            "goal_distance": jnp.linalg.norm(goal[:2] - kin.pos[:2]),
            "z": kin.pos[2],
            "clearance": kin.pos[2] - env.terrain_height(kin.pos[0], kin.pos[1]),
            "heading_error": wrap_angle(target[3] - kin.yaw),
            "goal_yaw_error": wrap_angle(goal[3] - kin.yaw),
            "forward_speed": kin.lin_vel_body[0],
            "planar_speed": jnp.linalg.norm(d.qvel[:2]),
            "success": st.info["success"],
        }

    def at_end(st):
        return {"success": st.metrics["episode_success"], "fell": st.metrics["terminated"]}

    return first_episodes(env, policy, state, measure, at_end)


def first_episodes(env, policy, state, measure, at_end):
    """Per step [T, B, ...] records of each robot's first episode: ``measure(state)`` (one
    robot) frozen at its last values once the episode ended (a done step's state is already
    the next episode's), ``at_end(states)`` ([B] values, e.g. the metrics that hold the
    endings) taken on the ending step and kept, and "running" (bool)."""

    def body(carry, _):
        st, finished, last = carry
        st = jax.vmap(env.step)(st, policy_action(policy, st.obs["state"]))
        now = jax.vmap(measure)(st)
        done = st.done > 0
        first, ended = done & ~finished, done | finished
        rec = {k: jnp.where(ended.reshape(ended.shape + (1,) * (v.ndim - 1)), last[k], v)
               for k, v in now.items()}
        for k, v in at_end(st).items():
            rec[k] = jnp.where(first, v, rec.get(k, last[k]))
        rec["running"] = ~ended
        return (st, ended, rec), rec

    init = jax.vmap(measure)(state)
    ends = jax.eval_shape(at_end, state)
    init.update({k: jnp.zeros(v.shape, v.dtype) for k, v in ends.items() if k not in init})
    init["running"] = jnp.ones(state.done.shape, bool)
    zeros = jnp.zeros(state.done.shape, bool)
    return jax.lax.scan(body, (state, zeros, init), None, length=env.episode_steps)[1]


def summarise(env, levels, rec, robots, spawn_arc):
    """Per-robot and per-level dicts from the [T, B] records."""
    dt = env.dt
    t_end = rec["running"].astype(np.float32).sum(0) * dt  # episode length per robot
    tiles = np.asarray(rec["tile"])
    line_len = np.asarray(env.tiles.line_len)[tiles]
    robots_out, levels_out = [], []
    steps = rec["arc"].shape[0]
    for b in range(rec["arc"].shape[1]):
        arc = rec["arc"][:, b]
        run = rec["running"][:, b] > 0
        frac = arc[-1] / line_len[b]
        where = ("goal landing" if rec["goal_distance"][-1, b] < 1.0
                 else "spawn landing" if arc[-1] - spawn_arc[b] < 0.5 else "on the flights")
        still = (rec["planar_speed"][:, b] < STILL_SPEED) & run
        robots_out.append({
            "level": int(levels[b // robots]),
            "tile": int(tiles[b]),
            "success": bool(rec["success"][-1, b] > 0),
            "success_s": float((np.argmax(rec["success"][:, b] > 0) + 1) * dt)
            if rec["success"][-1, b] > 0 else None,
            "fell": bool(rec["fell"][-1, b] > 0),
            "episode_s": float(t_end[b]),
            "route_m": float(line_len[b]),
            "final_arc_m": float(arc[-1]),
            "final_fraction": float(frac),
            "final_goal_distance": float(rec["goal_distance"][-1, b]),
            "final_centreline_distance": float(rec["centreline_distance"][-1, b]),
            "final_clearance": float(rec["clearance"][-1, b]),
            "final_heading_error": float(rec["heading_error"][-1, b]),
            "final_goal_yaw_error": float(rec["goal_yaw_error"][-1, b]),
            "mean_forward_speed": float(rec["forward_speed"][run, b].mean()) if run.any() else 0.0,
            "mean_abs_heading_error": float(np.abs(rec["heading_error"][run, b]).mean())
            if run.any() else 0.0,
            "still_s": float(still.sum() * dt),
            "ends": where,
            "arc_at": {f"{m:g}": float(arc[min(int(m / dt), steps) - 1])
                       for m in MARKS_S if m / dt <= steps},
        })
    for i, lv in enumerate(levels):
        rs = robots_out[i * robots:(i + 1) * robots]
        mean = lambda k, rs=rs: float(np.mean([r[k] for r in rs]))  # noqa: E731
        levels_out.append({
            "level": lv,
            "success": mean("success"), "fell": mean("fell"),
            **{f"success_by_{m:g}s": float(np.mean([r["success_s"] is not None
                                                    and r["success_s"] <= m + 1e-6 for r in rs]))
               for m in MARKS_S if m <= steps * dt + 1e-6},
            "timeout": float(np.mean([not r["success"] and not r["fell"] for r in rs])),
            "final_fraction": mean("final_fraction"),
            "final_goal_distance": mean("final_goal_distance"),
            "still_s": mean("still_s"),
            "mean_forward_speed": mean("mean_forward_speed"),
            "mean_abs_heading_error": mean("mean_abs_heading_error"),
            "ends": {w: sum(r["ends"] == w for r in rs)
                     for w in ("spawn landing", "on the flights", "goal landing")},
            "arc_at": {k: float(np.mean([r["arc_at"][k] for r in rs]))
                       for k in rs[0]["arc_at"]},
            "route_m": mean("route_m"),
        })
    return robots_out, levels_out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--checkpoint", required=True)
    ap.add_argument("--family", default="straight")
    ap.add_argument("--direction", default="up", choices=("up", "down"))
    ap.add_argument("--schedule", default="test")
    ap.add_argument("--levels", default="1", help="1-based, comma separated")
    ap.add_argument("--robots", type=int, default=16)
    ap.add_argument("--episode-s", type=float, default=20.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--env", nargs="*", default=[], help="env overrides KEY=VALUE")
    ap.add_argument("--train-settings", action="store_true",
                    help="the policy's training env (noise, randomisation, perturbed routes, "
                    "trunk-contact ending) instead of the evaluation settings; curriculum off")
    ap.add_argument("--with-holes", action="store_true",
                    help="the evaluation settings plus the policy's trained missing height-map "
                    "cells (env.noise.height_missing*), every other noise off")
    ap.add_argument("--goal-shift", type=float, default=0.0,
                    help="m: move every tile's goal this far along its heading (probe: does a "
                    "robot stop a fixed distance before the goal, or at a fixed place?)")
    ap.add_argument("--out", default=None)
    ap.add_argument("--trace", type=int, default=0,
                    help="also print the first N robots' arc, goal distance, clearance, speed "
                    "every 0.5 s")
    a = ap.parse_args()
    spec = EvalSpec(family=a.family, schedule=a.schedule, direction=a.direction,
                    levels=tuple(int(v) - 1 for v in a.levels.split(",")),
                    robots_per_level=a.robots, episode_length_s=a.episode_s, seed=a.seed,
                    env_overrides=tuple(a.env))
    policy = load_policy(a.checkpoint)
    env, levels = make_eval_env(policy, spec)
    if a.train_settings:
        cfg = env_config_of(policy, physics_overrides(spec))
        cfg = dataclasses.replace(
            cfg, episode_length_s=a.episode_s,
            curriculum=dataclasses.replace(cfg.curriculum, enabled=False))
        env = StairEnv(terrains.build_atlas([a.family], a.schedule, list(levels),
                                            variants_per_family=2, direction=a.direction), cfg)
    if a.with_holes:
        cfg = env.config
        zero = dict.fromkeys(("lin_vel", "ang_vel", "gravity", "joint_pos", "joint_vel", "height",
                              "height_offset"), 0.0)
        cfg = dataclasses.replace(cfg, noise=dataclasses.replace(cfg.noise, enabled=True, **zero))
        env = StairEnv(terrains.build_atlas([a.family], a.schedule, list(levels),
                                            variants_per_family=2, direction=a.direction), cfg)
    if a.goal_shift:
        g = env.tiles.goal
        env.tiles.goal = g.at[:, 0].add(a.goal_shift * jnp.cos(g[:, 3])).at[:, 1].add(
            a.goal_shift * jnp.sin(g[:, 3]))
    B = len(levels) * a.robots
    row = jnp.repeat(jnp.arange(len(levels), dtype=jnp.int32), a.robots)
    keys = jax.random.split(jax.random.PRNGKey(a.seed), B)
    state = jax.jit(jax.vmap(env.reset_at))(keys, row, jnp.zeros(B, jnp.int32))
    t0 = time.time()
    rec = jax.device_get(jax.jit(lambda s: rollout(env, policy, s))(state))
    rec["tile"] = np.asarray(state.info["tile"])
    spawn_arc = np.asarray(jax.vmap(lambda p, t: rw.centreline_geometry(
        p[:2], env.tiles.line[t], env.tiles.line_cum[t])[1])(
        state.pipeline_state.qpos[:, :3], state.info["tile"]))
    robots, per_level = summarise(env, [lv + 1 for lv in levels], rec, a.robots, spawn_arc)
    wall = time.time() - t0
    every = max(1, int(round(0.5 / env.dt)))
    for b in range(min(a.trace, B)):
        print(f"robot {b}: t, arc, goal distance, clearance, forward speed, heading error")
        for k in range(every - 1, env.episode_steps, every):
            print(f"  {(k + 1) * env.dt:5.1f} " + " ".join(
                f"{float(rec[n][k, b]):6.3f}" for n in ("arc", "goal_distance", "clearance",
                                                      "forward_speed", "heading_error")))
    for r in per_level:
        print(json.dumps(r))
    print(f"wall {wall:.0f} s (compile included), {B} robots, {env.episode_steps} steps")
    if a.out:
        with open(a.out, "w") as f:
            json.dump({"args": vars(a), "levels": per_level, "robots": robots}, f, indent=1)


if __name__ == "__main__":
    main()
