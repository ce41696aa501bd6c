"""Issue 19's lead: do ground-truth feet sink into the box staircase and stay there?

Runs the ground truth closed-loop (study.ground_truth.closed_loop, the evaluation's spawns and
rules) and after every policy step checks each foot sphere's centre against the terrain top
under it (the atlas grid height of the cell it stands over, which is the box top there): a
foot is *sunk* when its centre lies more than --depth below that top. A robot *holds a sunk
foot* when some foot stays sunk for at least --min-steps consecutive policy steps before its
episode ends. Prints counts by outcome (success / fall / time-out).

    JAX_PLATFORMS=cpu PYTHONPATH=. python experiments/gt_sunk_feet.py --cell 8 --robots 32 \
        [--episode-s 20] [--supports all|thin] [--out OUT.json]

The spawns are gt_uturn_probe.py's (its spec_of). Cells index experiments/gpu/fidelity.py's
CELLS (8: U-shaped extended L3, 9: L4, 15: straight extended L4). --supports picks
terrains.boxes.grid_boxes' supports for the box world (the builder's default when left out;
"thin" is the builder before every box got a support).
"""

from __future__ import annotations

import argparse
import functools
import json
import sys
import time
from pathlib import Path

import mujoco
import numpy as np

from mjx_stairs.rl.policy import load_policy
from mjx_stairs.sim import box_world as bw
from mjx_stairs.sim import robot as rb
from mjx_stairs.study import ground_truth as gt
from mjx_stairs.study.evaluate import CellSpec
from terrains import boxes as tb

sys.path.insert(0, "experiments/gpu")
from fidelity import CELLS, OPTIONS, POLICIES  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cell", type=int, default=8)
    ap.add_argument("--robots", type=int, default=32)
    ap.add_argument("--policy", default="stage2_u")
    ap.add_argument("--episode-s", type=float, default=20.0)
    ap.add_argument("--depth", type=float, default=0.01, help="m below the top: sunk")
    ap.add_argument("--min-steps", type=int, default=3, help="policy steps in a row")
    ap.add_argument("--supports", default=None, help="grid_boxes' supports: all|thin")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args()

    if a.supports is not None:
        gt.grid_boxes = functools.partial(tb.grid_boxes, supports=a.supports)
    policy = load_policy(POLICIES[a.policy])
    spec = CellSpec(cells=(CELLS[a.cell],), robots_per_cell=a.robots,
                    episode_length_s=a.episode_s, env_overrides=OPTIONS["reference"])
    env, state, info, tiles, models = gt._start(policy, spec, bw.DEFAULT_SOLVER, "boxes")
    B = tiles.shape[0]
    batch = bw.Batch(models, np.asarray(state.pipeline_state.qpos), nthread=a.threads)
    goal = np.asarray(env.goals)[tiles]
    heights = np.asarray(env.terrain.heights(), np.float64)
    res = env.resolution
    feet = [models[0].geom(n).id for n in rb.SPHERE_GROUPS["foot"]]
    datas = {id(m): mujoco.MjData(m) for m in models}
    run = np.zeros((B, 4), np.int64)  # current sunk run per foot (policy steps)
    longest = np.zeros(B, np.int64)
    deepest = np.zeros(B)
    episodes = np.zeros(B, np.int64)  # sunk runs reaching min_steps
    where = [[] for _ in range(B)]  # (t, x, y, depth) where each such run reached min_steps
    k = [0]
    stopped = np.zeros(B, bool)

    def record(b: bw.Batch, last) -> None:
        k[0] += 1
        for i in np.flatnonzero(~stopped):
            d = datas[id(models[i])]
            d.qpos[:] = b.qpos[i]
            mujoco.mj_kinematics(models[i], d)
            p = d.geom_xpos[feet]
            ix = np.clip(np.rint(p[:, 0] / res).astype(int), 0, heights.shape[1] - 1)
            iy = np.clip(np.rint(p[:, 1] / res).astype(int), 0, heights.shape[0] - 1)
            depth = heights[iy, ix] - p[:, 2]
            sunk = depth > a.depth
            run[i] = np.where(sunk, run[i] + 1, 0)
            for f in np.flatnonzero(run[i] == a.min_steps):
                episodes[i] += 1
                where[i].append((k[0] * env.dt, *map(float, p[f, :2]), float(depth[f])))
            longest[i] = max(longest[i], run[i].max())
            if sunk.any():
                deepest[i] = max(deepest[i], depth.max())

    t0 = time.time()
    # closed_loop calls record after every step for all robots; stop counting ended ones by
    # re-reading its bookkeeping through a wrapper of _Episodes.
    orig_cls = gt._Episodes

    class Episodes(orig_cls):
        def __post_init__(self):
            super().__post_init__()
            holder.append(self)

    holder: list = []
    gt._Episodes = Episodes

    def record_active(b, last):
        record(b, last)
        stopped[:] = ~holder[0].active

    ep = gt.closed_loop(env, policy, info, batch, goal, np.zeros((B, 12), np.float32),
                        env.episode_steps, record_active)
    gt._Episodes = orig_cls
    batch.close()
    timeout = ~(ep.success | ep.fell)
    held = episodes > 0
    out = {"cell": list(CELLS[a.cell]), "policy": a.policy, "robots": B,
           "supports": a.supports or "default", "episode_s": a.episode_s, "depth_m": a.depth,
           "min_steps": a.min_steps, "wall_s": time.time() - t0,
           "success": float(ep.success.mean()), "fell": float(ep.fell.mean()),
           "timeout": float(timeout.mean())}
    for name, m in (("success", ep.success), ("fell", ep.fell), ("timeout", timeout)):
        out[f"{name}_robots"] = int(m.sum())
        out[f"{name}_with_sunk_foot"] = int((held & m).sum())
        out[f"{name}_sunk_runs"] = int(episodes[m].sum())
    out["longest_run_steps_max"] = int(longest.max())
    out["deepest_m_max"] = float(deepest.max())
    out["per_robot"] = [
        {"robot": int(i), "outcome": "success" if ep.success[i] else
         "fell" if ep.fell[i] else "timeout", "runs": int(episodes[i]),
         "longest": int(longest[i]), "deepest_m": round(float(deepest[i]), 4),
         "where": [[round(v, 3) for v in w] for w in where[i][:5]]}
        for i in np.flatnonzero(held)]
    print(json.dumps({k_: v for k_, v in out.items() if k_ != "per_robot"}, indent=1))
    for r in out["per_robot"][:40]:
        print(r)
    if a.out:
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
