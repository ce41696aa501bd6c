"""Issue 19, the U-turn: does the columns collider's sunk rule make MJX optimistic? A sphere whose
centre is inside a column is pushed out through that column's top (`robot.sunk_exit = "top"`, the
evaluation physics as published: right for a foot sunk into a tread; a foot driven into a riser is
lifted onto the step above, where MuJoCo's box pushes it back out through the riser), or through
the column's nearest exposed face (`"nearest"`). MJX success of one policy on one cell under
either rule, from the same starts.

Usage: JAX_PLATFORMS=cpu PYTHONPATH=. python experiments/gt_sunk_exit.py top|nearest \
    ROBOTS CELL POLICY [SEED]  (e.g. nearest 256 8 stage2_u_lean; ~6 min on 2 CPU cores; SEED:
    the robots' starts, default 0, as `fidelity.py gt --seed`)
"""

from __future__ import annotations

import json
import sys
import time

sys.path.insert(0, "experiments/gpu")


def main(rule: str, robots: int, cell: int, pol: str, seed: int = 0) -> None:
    from fidelity import CELLS, KNOWN_POLICIES, OPTIONS

    from mjx_stairs.rl.policy import load_policy
    from mjx_stairs.study.evaluate import CellSpec, success_by_cell

    spec = CellSpec(cells=(CELLS[cell],), robots_per_cell=robots, physics="trained", seed=seed,
                    env_overrides=(*OPTIONS["evaluation"], f"robot.sunk_exit={rule}"))
    t0 = time.time()
    r = success_by_cell({pol: load_policy(KNOWN_POLICIES[pol])}, spec)[pol]
    print(json.dumps(dict(rule=rule, cell=list(CELLS[cell]), policy=pol, robots=robots, seed=seed,
                          success=r["success"], fell=r["fell"],
                          wall_s=round(time.time() - t0), outcomes=r["outcomes"])))


if __name__ == "__main__":
    if len(sys.argv) not in (5, 6):
        sys.exit(__doc__)
    main(sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4], *map(int, sys.argv[5:]))
