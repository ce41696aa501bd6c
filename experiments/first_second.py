"""The falls that keep the up cells under 99 %: when they happen, and how the robots set off
(issue 24; docs/results.md 8ah).

`records`: over a policy's sim2sim per-episode records (experiments/gpu/sim2sim_table.py
writes them to OUT/cells/*.json) on the paper's cells without latency, the falls within the
first `--within` seconds against the later ones, by level. `mjx`: the evaluation's robots
(`mjx-stairs eval`'s starts at `--seed`) of one family and level stepped in the evaluation env,
and the given ones' roll, pitch (deg, from the body-frame gravity), base height and largest
|action| printed every policy step.

    PYTHONPATH=. python experiments/first_second.py records \\
        experiments/results/sim2sim/mix_wall_rule_export --robot-sha aa80ba1f \\
        --policy experiments/results/generalist_from_stage1_mix/policy.npz
    PYTHONPATH=. JAX_PLATFORMS=cpu python experiments/first_second.py mjx \\
        --checkpoint experiments/results/generalist_from_stage1_mix_told_log/policy.npz \\
        --family u_shaped --level 1 --robots 1000 --show 87,229,235,420,535 \\
        --env height_map.occlusion_samples=32
    PYTHONPATH=. JAX_PLATFORMS=cpu python experiments/first_second.py starts \\
        --checkpoint experiments/results/generalist_from_stage1_mix_told_log/policy.npz \\
        --family u_shaped --level 1 --robots 4000 --seed 7 \\
        --env height_map.occlusion_samples=32 spawn_height=0.33

`starts`: of `--robots` evaluation starts at `--seed`, how many end within `--steps` policy steps
(the start's falls), by the spawn heading's offset from the tile's, with each bin's mean largest
|roll| before the end: whether the falls depend on the heading, the place or, with
`spawn_height=...`, on how far the robot drops onto the floor at reset.
"""

from __future__ import annotations

import argparse
import collections
import json

import numpy as np


def early_falls(root: str, policy: str, robot_sha: str | None, within_s: float,
                contact_timeconst: float = 0.01) -> dict:
    """{"episodes", "early", "late", "early_by_level"} over the latency-free paper cells of
    `policy` under `root`, selected as `mjx-stairs sim2sim-gaps` selects them
    (sim2sim_gaps.gather: one setting, one robot file, the longer run of a cell run twice)."""
    from mjx_stairs.tools import sim2sim_gaps

    n, early, late = 0, 0, 0
    by_level: collections.Counter = collections.Counter()
    for cell in sim2sim_gaps.gather(policy, root, [], robot_sha=robot_sha,
                                    contact_timeconst=contact_timeconst):
        if cell.mujoco is None or cell.key[2] == 0:  # not run, or a `code` case
            continue
        for r in cell.mujoco["records"]:
            n += 1
            if r["fell"] and r["time_s"] <= within_s:
                early += 1
                by_level[f"L{cell.key[2]}"] += 1
            elif r["fell"]:
                late += 1
    return {"episodes": n, "early": early, "late": late,
            "early_by_level": dict(sorted(by_level.items()))}


def roll_pitch_deg(gravity_body: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(roll, pitch) in degrees from unit gravity in the body frame ([..., 3]; [0, 0, -1]
    upright)."""
    g = np.clip(gravity_body, -1.0, 1.0)
    return np.degrees(np.arcsin(-g[..., 1])), np.degrees(np.arcsin(g[..., 0]))


def eval_starts(args):
    """(policy, evaluation env, its robots reset as `mjx-stairs eval` resets them) for one
    family, direction and level at `args.seed`, with `args.env` overrides."""
    from mjx_stairs.rl.policy import load_policy
    from mjx_stairs.study.evaluate import level_states, make_eval_env
    from mjx_stairs.study.specs import EvalSpec

    policy = load_policy(args.checkpoint)
    spec = EvalSpec(family=args.family, schedule="test", direction=args.direction,
                    levels=(args.level - 1,), robots_per_level=args.robots, seed=args.seed,
                    env_overrides=tuple(args.env))
    env, _ = make_eval_env(policy, spec)
    return policy, env, level_states(env, 1, spec)


def trace_mjx(args) -> None:
    import jax
    import jax.numpy as jnp

    from mjx_stairs.env.geometry import base_kinematics
    from mjx_stairs.rl.policy import policy_action

    show = jnp.asarray([int(v) for v in args.show.split(",")])
    policy, env, state = eval_starts(args)
    state = jax.tree.map(lambda x: x[show], state)
    act = jax.jit(lambda s: policy_action(policy, s.obs["state"]))
    step = jax.jit(lambda s, a: jax.vmap(env.step)(s, a))
    gravity = jax.jit(jax.vmap(lambda q, v: base_kinematics(q, v).gravity_body))
    for k in range(args.steps):
        a = act(state)
        state = step(state, a)
        g = np.asarray(gravity(state.pipeline_state.qpos, state.pipeline_state.qvel))
        z, done = np.asarray(state.pipeline_state.qpos[:, 2]), np.asarray(state.done) > 0
        amax = np.abs(np.asarray(a)).max(axis=1)
        cols = []
        for i in range(len(show)):
            r, p = roll_pitch_deg(g[i])
            end = " ended" if done[i] else ""
            cols.append(f"{r:+4.0f}/{p:+4.0f} z{z[i]:.2f} a{amax[i]:.1f}{end}")
        print(f"t {(k + 1) * env.dt:.2f}  " + " | ".join(cols))


def start_falls(args) -> None:
    import jax
    import jax.numpy as jnp

    from mjx_stairs.env.geometry import base_kinematics
    from mjx_stairs.rl.policy import policy_action

    policy, env, state = eval_starts(args)
    kin = jax.vmap(base_kinematics)

    def body(carry, _):  # worst: the body-frame gravity of the largest sideways lean so far
        s, ended, worst = carry
        s = jax.vmap(env.step)(s, policy_action(policy, s.obs["state"]))
        g = kin(s.pipeline_state.qpos, s.pipeline_state.qvel).gravity_body
        more = ~ended & (jnp.abs(g[:, 1]) > jnp.abs(worst[:, 1]))
        return (s, ended | (s.done > 0), jnp.where(more[:, None], g, worst)), None

    upright = jnp.zeros(state.done.shape + (3,)).at[:, 2].set(-1.0)
    start = (state, jnp.zeros(state.done.shape, bool), upright)
    _, ended, worst_g = jax.device_get(
        jax.jit(lambda c: jax.lax.scan(body, c, None, args.steps)[0])(start))
    worst, _ = roll_pitch_deg(worst_g)
    yaw0 = np.asarray(kin(state.pipeline_state.qpos, state.pipeline_state.qvel).yaw)
    tile_yaw = np.asarray(env.tiles.spawn[state.info["tile"]])[:, 5]
    off = np.degrees((yaw0 - tile_yaw + np.pi) % (2 * np.pi) - np.pi)
    print(f"{args.family} {args.direction} L{args.level} {args.env}: {int(ended.sum())} of "
          f"{ended.size} ended within {args.steps * env.dt:.2f} s")
    for lo in range(-45, 45, 15):
        k = (off >= lo) & (off < lo + 15)
        print(f"  heading {lo:+d} to {lo + 15:+d} deg: {int(ended[k].sum())} of {int(k.sum())}, "
              f"mean largest roll {worst[k].mean():+.1f} deg")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="what", required=True)
    r = sub.add_parser("records")
    r.add_argument("root", help="a folder of sim2sim_table.py runs (OUT/cells/*.json)")
    r.add_argument("--policy", required=True, help="the policy.npz the cells name")
    r.add_argument("--robot-sha", default=None, help="only cells run on this robot file")
    r.add_argument("--within", type=float, default=1.0, help="seconds")
    m = sub.add_parser("mjx")
    st = sub.add_parser("starts")
    for p in (m, st):
        p.add_argument("--checkpoint", required=True)
        p.add_argument("--family", default="u_shaped")
        p.add_argument("--direction", default="up", choices=("up", "down"))
        p.add_argument("--level", type=int, default=1)
        p.add_argument("--robots", type=int, default=1000, help="as the evaluation: its starts")
        p.add_argument("--seed", type=int, default=0)
        p.add_argument("--env", nargs="*", default=[])
    m.add_argument("--show", required=True, help="robot indices, comma separated")
    m.add_argument("--steps", type=int, default=25)
    st.add_argument("--steps", type=int, default=50, help="policy steps (50: 1 s)")
    a = ap.parse_args()
    if a.what == "records":
        print(json.dumps(early_falls(a.root, a.policy, a.robot_sha, a.within), indent=1))
    elif a.what == "mjx":
        trace_mjx(a)
    else:
        start_falls(a)


if __name__ == "__main__":
    main()
