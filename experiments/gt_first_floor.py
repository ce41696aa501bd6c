"""Issue 19: the floor under the first-second replay (docs/results.md section 5b). From the same
32 states as `fidelity.py first` (stage2_u, after 2 s in the ground truth), the same actions for
1 s in: the ground truth itself started from the float32-rounded state (the rounding any float32
simulator makes of the start: how chaotic is the ground truth?), the evaluation physics, and the
columns collider with 16 Newton iterations and 20 line-search steps (is 8 / 10 converged?).

Usage (CPU): JAX_PLATFORMS=cpu PYTHONPATH=. python experiments/gt_first_floor.py OUT_DIR 3,8,15
(CELLS indices of experiments/gpu/fidelity.py; ~3 min per cell on 2 cores).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import mujoco
import numpy as np

from mjx_stairs.rl.policy import load_policy
from mjx_stairs.sim import robot as rb
from mjx_stairs.study import ground_truth as gt
from mjx_stairs.study.evaluate import CellSpec

sys.path.insert(0, "experiments/gpu")
from fidelity import CELLS, OPTIONS, POLICIES  # noqa: E402


def gt_f32(policy, spec, start, actions):
    env, _, _, _, models = gt._start(policy, spec, gt.bw.DEFAULT_SOLVER, "boxes")
    c = env.config
    qpos, qvel, _ = start
    ds = []
    for m, q, v in zip(models, qpos, qvel, strict=True):
        d = mujoco.MjData(m)
        d.qpos[:] = q.astype(np.float32)
        d.qvel[:] = v.astype(np.float32)
        ds.append((m, d))
    pos, force = [], []
    for a in actions:
        target = rb.NOMINAL_JOINT_POS + c.robot.action_scale * np.asarray(a)
        for (m, d), t in zip(ds, target, strict=True):
            d.ctrl[:] = t
            for _ in range(c.decimation):
                mujoco.mj_step(m, d)
        pos.append(np.stack([d.qpos[:3].copy() for _, d in ds]))
        force.append([gt.bw.contact_summary(m, d)["vertical_force"] for m, d in ds])
    pos = np.array(pos)
    return pos, np.array(force), np.zeros(pos.shape[:2], bool)


def main(out: Path, cells: str) -> None:
    out.mkdir(parents=True, exist_ok=True)
    policy = load_policy(POLICIES["stage2_u"])
    opts = {"evaluation": OPTIONS["evaluation"],
            "columns_n16": ("robot.terrain_contacts=columns", "robot.shin_collision=true",
                            "robot.solver_iterations=16", "robot.ls_iterations=20")}
    for cell in [int(x) for x in cells.split(",")]:
        spec = CellSpec(cells=(CELLS[cell],), robots_per_cell=32,
                        env_overrides=OPTIONS["reference"], physics="trained")
        rec = gt.first_second(policy, spec, opts, replays={"ground_truth_from_float32": gt_f32})
        fam, sched, lv = CELLS[cell]
        (out / f"floor_stage2_u_{fam}_{sched}_{lv + 1}.json").write_text(json.dumps(rec, indent=1))
        for k, o in rec["options"].items():
            print(cell, k, f"{100 * o['pos_error_at_horizon_mean_m']:.2f} cm mean, p90 "
                  f"{100 * o['pos_error_at_horizon_p90_m']:.2f}; force "
                  f"{o['force_abs_diff_mean_n']}", flush=True)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(Path(sys.argv[1]), sys.argv[2])
