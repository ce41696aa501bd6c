"""What each reward term pays a policy per second on suite cases: the scale of a new term.

Rolls a policy's first episode per robot on named cases (the evaluation env of `mjx-stairs eval
--suite`, as experiments/diagnose_cases.py: mean action, evaluation physics, no noise), with
env overrides that may weight terms the policy did not train with (e.g.
rewards.foot_clearance=-1), and prints per case each active term's sum over the episodes
divided by their total time: its mean per second, already times its weight.

    PYTHONPATH=. JAX_PLATFORMS=cpu python experiments/reward_terms.py \
        --checkpoint experiments/results/generalist_from_stage1_mix_told_log/policy.npz \
        --case code_commercial_straight_up --robots 8 --episode-s 10 \
        --env height_map.occlusion_samples=32 rewards.foot_clearance=-1.0
"""

from __future__ import annotations

import argparse
import json

import jax
import numpy as np
from diagnose_episodes import first_episodes  # experiments/, the script's folder

from mjx_stairs.rl.policy import load_policy
from mjx_stairs.study import evaluate
from mjx_stairs.study.cases import case_atlas, case_states, suite_cases
from mjx_stairs.study.specs import EvalSpec


def per_second(rec: dict, robots: int, dt: float, names: list[str]) -> list[dict]:
    """{term: mean per second} per case from [T, B] records (robots per case, in case order)."""
    out = []
    for i, name in enumerate(names):
        cols = slice(i * robots, (i + 1) * robots)
        running = rec["running"][:, cols]
        seconds = float(running.sum()) * dt
        terms = {k[len("reward/"):]: float((rec[k][:, cols] * running).sum()) / seconds
                 for k in sorted(rec) if k.startswith("reward/")}
        out.append({"case": name, "robot_seconds": round(seconds, 2), "per_second": terms})
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--checkpoint", required=True)
    ap.add_argument("--suite", default="code")
    ap.add_argument("--case", required=True, help="case names, comma separated")
    ap.add_argument("--robots", type=int, default=8)
    ap.add_argument("--episode-s", type=float, default=10.0)
    ap.add_argument("--resolution", type=float, default=0.025)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--env", nargs="*", default=[], help="env overrides KEY=VALUE")
    a = ap.parse_args()
    names = a.case.split(",")
    every = dict(suite_cases(a.suite, a.resolution))
    missing = [n for n in names if n not in every]
    if missing:
        raise SystemExit(f"unknown cases {missing}; known: {', '.join(every)}")
    spec = EvalSpec(robots_per_level=a.robots, episode_length_s=a.episode_s, seed=a.seed,
                    resolution=a.resolution, env_overrides=tuple(a.env))
    policy = load_policy(a.checkpoint)
    env = evaluate.eval_env(policy, case_atlas([(n, every[n]) for n in names]), spec)
    state = case_states(env, len(names), a.robots, a.seed)
    keys = [k for k in state.metrics if k.startswith("reward/")]
    rec = jax.device_get(jax.jit(lambda s: first_episodes(
        env, policy, s, lambda st: {k: st.metrics[k] for k in keys}, lambda st: {}))(state))
    rec = {k: np.asarray(v) for k, v in rec.items()}
    for row in per_second(rec, a.robots, env.dt, names):
        print(json.dumps(row))


if __name__ == "__main__":
    main()
