"""Any committed policy in the CPU ground truth (MuJoCo itself on box stairs, issue 19): success by
level beside its MJX evaluation, from the same starts (study.ground_truth.success_in_ground_truth).

    JAX_PLATFORMS=cpu PYTHONPATH=. python experiments/gt_policy.py \
        --checkpoint experiments/results/generalist_line/policy.npz --family u_shaped \
        --schedule test --levels 1,2,3,4,5,6 --robots 200 --out OUT.json

The policy's own env config decides the endings (e.g. `low_line_m`), as in `mjx-stairs eval`;
the evaluation physics' starts; the training MJCF (shin spheres, its joint damping) on boxes
built from the tile's grid; MuJoCo's converged solver (ground_truth.DEFAULT_SOLVER). 200 robots
per level on U-shaped test levels take ~2-4 min per level on 2 CPU cores (nthread 2).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from mjx_stairs.atomic import write_text
from mjx_stairs.rl.policy import load_policy
from mjx_stairs.study.evaluate import CellSpec
from mjx_stairs.study.ground_truth import success_in_ground_truth


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--checkpoint", required=True, type=Path)
    ap.add_argument("--family", default="u_shaped")
    ap.add_argument("--schedule", default="test")
    ap.add_argument("--levels", default="1,2,3,4,5,6", help="1-based, comma-separated")
    ap.add_argument("--robots", type=int, default=200, help="robots per level")
    ap.add_argument("--episode-s", type=float, default=20.0)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--env", nargs="*", default=[], metavar="KEY=VALUE",
                    help="env overrides after the policy's config (e.g. min_base_height=0.05)")
    ap.add_argument("--out", required=True, type=Path)
    a = ap.parse_args()
    levels = [int(x) - 1 for x in a.levels.split(",")]
    spec = CellSpec(cells=tuple((a.family, a.schedule, lv) for lv in levels),
                    robots_per_cell=a.robots, env_overrides=tuple(a.env),
                    episode_length_s=a.episode_s)
    rec = success_in_ground_truth(load_policy(a.checkpoint), spec, nthread=a.threads)
    rec["checkpoint"] = str(a.checkpoint)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    write_text(a.out, json.dumps(rec, indent=1))
    print(" ".join(f"L{lv + 1} {100 * s:.1f}" for lv, s in
                   zip(levels, rec["success"], strict=True)),
          f"({a.robots} robots per level, {rec['wall_s']:.0f} s) -> {a.out}")


if __name__ == "__main__":
    main()
