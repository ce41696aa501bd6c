"""Issue 19, the U-turn: does the ground truth's support box (terrains/boxes.py, UNDER_TOP under
each box's top and in from its sides) change the ground truth's success? It adds a second
contact where a foot is pressed deeper than UNDER_TOP into a step, where one solid staircase
(and MJX's columns collider) has one.

Usage (CPU): JAX_PLATFORMS=cpu PYTHONPATH=. python experiments/gt_support_inset.py \
    UNDER_TOP ROBOTS CELL POLICY
e.g. `0.022 1000 8 stage2_u_lean` (cell 8: U-shaped extended L3; 0.01 is today's builder).
Prints success and falls (one JSON line).
"""

from __future__ import annotations

import json
import sys
import time

import terrains.boxes as boxes

sys.path.insert(0, "experiments/gpu")


def main(under_top: float, robots: int, cell: int, policy_name: str) -> None:
    boxes.UNDER_TOP = under_top  # read by grid_boxes at call time
    from fidelity import CELLS, OPTIONS, POLICIES

    from mjx_stairs.rl.policy import load_policy
    from mjx_stairs.study import ground_truth as gt
    from mjx_stairs.study.evaluate import CellSpec

    spec = CellSpec(cells=(CELLS[cell],), robots_per_cell=robots,
                    env_overrides=OPTIONS["reference"])
    t0 = time.time()
    r = gt.success_in_ground_truth(load_policy(POLICIES[policy_name]), spec, nthread=1)
    print(json.dumps(dict(under_top=under_top, cell=list(CELLS[cell]), policy=policy_name,
                          robots=robots, success=float(r["success"][0]),
                          fell=float(r["fell"][0]), wall_s=round(time.time() - t0))))


if __name__ == "__main__":
    if len(sys.argv) != 5:
        sys.exit(__doc__)
    main(float(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), sys.argv[4])
