"""Issue 24: where a robot that reached the goal ends its episode (the curriculum's view).

    JAX_PLATFORMS=cpu python experiments/heading_at_goal.py OUT.json \
        --policy NAME=experiments/results/generalist_noent/policy.npz ... \
        --cell u_shaped:test:2:up --robots 16 --episode-s 30

For each policy and cell: the robots' first episodes in the evaluation physics (no noise), and
of those that succeeded (0.5 m, slower than 0.3 m/s, held 0.5 s: what every success table
counts), at the episode's last step the planar distance to the goal and the heading error, so
the share the curriculum would promote (within 0.8 m and, with its heading check, 0.4 rad), and
the largest heading error after the success. Docs: docs/results.md 8h.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from mjx_stairs.env import goals
from mjx_stairs.env.geometry import base_kinematics, wrap_angle
from mjx_stairs.rl.policy import load_policy, policy_action
from mjx_stairs.study import evaluate
from mjx_stairs.study.specs import EvalSpec


def rollout(env, policy, state):
    """Per robot of its first episode -> (finished, success, end distance, end |yaw
    error|, largest |yaw error| after the success)."""

    def where(st):
        kin = base_kinematics(st.pipeline_state.qpos, st.pipeline_state.qvel)
        goal = goals.goal_of(st.info, env.tiles)
        return jnp.linalg.norm(goal[:2] - kin.pos[:2]), jnp.abs(wrap_angle(goal[3] - kin.yaw))

    def body(carry, _):
        st, fin, succ, dist, yaw, worst = carry
        d, y = jax.vmap(where)(st)  # before the step: the last pose of an episode that ends in it
        after = ~fin & (st.info["success"] > 0)
        worst = jnp.where(after, jnp.maximum(worst, y), worst)
        st = jax.vmap(env.step)(st, policy_action(policy, st.obs["state"]))
        first = (st.done > 0) & ~fin
        succ = jnp.where(first, st.metrics["episode_success"] > 0, succ)
        dist, yaw = jnp.where(first, d, dist), jnp.where(first, y, yaw)
        return (st, fin | first, succ, dist, yaw, worst), None

    z = jnp.zeros(state.done.shape)
    init = (state, z > 0, z > 0, z, z, z)
    return jax.lax.scan(body, init, None, length=env.episode_steps)[0][1:]


def run_cell(name: str, path: str, cell: str, robots: int, episode_s: float) -> dict:
    family, schedule, level, direction = cell.split(":")
    policy = load_policy(path)
    spec = EvalSpec(family=family, schedule=schedule, levels=(int(level) - 1,), direction=direction,
                    robots_per_level=robots, episode_length_s=episode_s, resolution=0.05)
    env, levels = evaluate.make_eval_env(policy, spec)
    state = evaluate.level_states(env, len(levels), spec)
    t0 = time.time()
    fin, succ, dist, yaw, worst = (np.asarray(a) for a in jax.jit(
        lambda s: rollout(env, policy, s))(state))
    s = succ & fin
    n = max(int(s.sum()), 1)
    return {"policy": name, "cell": cell, "robots": robots, "episode_s": episode_s,
            "success": float(s.mean()),
            "of_successes_within_0.8m": float((dist[s] < 0.8).sum() / n),
            "of_successes_promoted_with_heading_check": float(
                ((dist[s] < 0.8) & (yaw[s] < 0.4)).sum() / n),
            "end_yaw_error_rad_median": float(np.median(yaw[s])) if s.any() else None,
            "largest_yaw_error_after_success_rad_median":
                float(np.median(worst[s])) if s.any() else None,
            "wall_s": time.time() - t0}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--policy", action="append", required=True, metavar="NAME=FILE")
    ap.add_argument("--cell", action="append", required=True,
                    metavar="FAMILY:SCHEDULE:LEVEL:DIRECTION")
    ap.add_argument("--robots", type=int, default=16)
    ap.add_argument("--episode-s", type=float, default=30.0)
    a = ap.parse_args()
    rows = []
    for cell in a.cell:
        for p in a.policy:
            name, _, path = p.partition("=")
            rows.append(run_cell(name, path, cell, a.robots, a.episode_s))
            print(json.dumps(rows[-1]), flush=True)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
