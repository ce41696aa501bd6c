# ruff: noqa: E501, E702, E401, E402, I001
"""python experiments/gt_spiral/segment.py ROBOTS OUT K,K,... OPTION [FAMILY:LEVEL [RESOLUTION]]; spiral L6 (default) up, generalist_noent, damping 2 implicit: the ground truth closed loop with every
state kept, then MJX (evaluation physics) from the GT's states at steps K to the episode's end."""
import json, os, sys, time
import numpy as np
sys.path.insert(0, "experiments"); sys.path.insert(0, "experiments/gpu")
from fidelity import OPTIONS
from gt_uturn_probe import gt_run, mjx_run
from mjx_stairs.rl.policy import load_policy
from mjx_stairs.study.evaluate import CellSpec

DAMP = (f"robot.joint_damping={os.environ.get('DAMPING', '2.0')}", "robot.implicit_damping=true")  # env DAMPING: N m s/rad
policy = load_policy("experiments/results/generalist_noent/policy.npz")
B = int(sys.argv[1]); out = sys.argv[2]
fam, lv = (sys.argv[5] if len(sys.argv) > 5 else "spiral:6").split(":")  # FAMILY:LEVEL (1-based)
cell = (fam, "test", int(lv) - 1)
RES = float(sys.argv[6]) if len(sys.argv) > 6 else 0.025  # the atlas grid (m)
gt_spec = CellSpec(cells=(cell,), robots_per_cell=B, seed=0, resolution=RES, env_overrides=DAMP)
mjx_spec = CellSpec(cells=(cell,), robots_per_cell=B, seed=0, resolution=RES,
                    env_overrides=(*OPTIONS[sys.argv[4]], *DAMP))
t0 = time.time()
kept = os.path.exists(out + "/gt.npz")  # a later call reuses the ground truth's run
r = dict(np.load(out + "/gt.npz")) if kept else gt_run(policy, gt_spec)
T = r["action"].shape[0]
print(f"gt: success {r['success'].mean():.3f} fell {r['fell'].mean():.3f} ({time.time()-t0:.0f} s, T={T})", flush=True)
if not kept:
    np.savez_compressed(out + "/gt.npz", **r)
res = {"gt_success": r["success"].tolist(), "gt_fell": r["fell"].tolist(), "segments": {}}
for k in [int(x) for x in sys.argv[3].split(",")]:
    # robots whose GT episode is still running at step k (not ended before)
    alive = np.array([not np.allclose(r["qpos"][k, b], r["qpos"][k - 1, b]) or k == 0 for b in range(B)])
    alive &= ~((~np.isnan(r["t_goal"])) & (r["t_goal"] <= k * r["dt"]))
    start = (r["qpos"][k], r["qvel"][k], r["action"][k - 1] if k > 0 else np.zeros((B, 12), np.float32))
    t1 = time.time()
    m = mjx_run(policy, mjx_spec, start, T - k)
    a = np.flatnonzero(alive)
    if k == 0:
        np.save(out + f"/mjx_{sys.argv[4]}_qpos.npy", m["qpos"])
    res["segments"][k] = {"alive": a.tolist(), "mjx_success": m["success"].tolist(), "mjx_fell": m["fell"].tolist()}
    print(f"k={k} ({k*r['dt']:.1f} s): {a.size} running in GT; their GT success {r['success'][a].mean():.3f} "
          f"fell {r['fell'][a].mean():.3f}; MJX from the same states success {m['success'][a].mean():.3f} "
          f"fell {m['fell'][a].mean():.3f} ({time.time()-t1:.0f} s)", flush=True)
json.dump(res, open(out + f"/segments_{sys.argv[4]}_{sys.argv[3]}.json", "w"))
