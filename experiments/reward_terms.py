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
from diagnose_cases import case_arguments, case_setup  # experiments/, the script's folder
from diagnose_episodes import first_episodes


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
    case_arguments(ap, episode_s=10.0)
    a = ap.parse_args()
    cases, policy, env, state = case_setup(a)
    names = [name for name, _ in cases]
    keys = [k for k in state.metrics if k.startswith("reward/")]
    rec = jax.device_get(jax.jit(lambda s: first_episodes(
        env, policy, s, lambda st: {k: st.metrics[k] for k in keys}, lambda st: {}))(state))
    rec = {k: np.asarray(v) for k, v in rec.items()}
    for row in per_second(rec, a.robots, env.dt, names):
        print(json.dumps(row))


if __name__ == "__main__":
    main()
