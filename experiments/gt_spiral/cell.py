# ruff: noqa: E501, E402
"""generalist_noent (or --policy) on one paper test cell going up (--robots, 200, seed 0, damping 2 implicit
unless --env says otherwise), in MJX's evaluation physics or the CPU MuJoCo ground truth (box
stairs), with the study's changes: --dt (a shorter physics step, the same 20 ms policy step, in
both), --resolution (the atlas grid: MJX's columns, the height map and the boxes alike), --exit
(MJX's sunk-centre rule for the process, contact.set_exit_study), --timeconst (every geom's
contact solref time constant, robot and stairs, in both simulators: robot.contact_timeconst;
without it the evaluation physics's 0.01 s, 0 for go2.xml's 0.02). One JSON line.
    python experiments/gt_spiral/cell.py mjx|gt [--cell spiral:6] [--dt 0.0025]
        [--resolution 0.0125] [--exit face] [--timeconst 0.01] [--env KEY=VALUE ...]
        [--policy experiments/results/generalist_noent_stiff/policy.npz]
(replaces the session's dt.py, res.py and face.py: git show d25518a:experiments/gt_spiral/)"""
import argparse
import json
import time

ap = argparse.ArgumentParser()
ap.add_argument("what", choices=("mjx", "gt"))
ap.add_argument("--cell", default="spiral:6", help="FAMILY:LEVEL (1-based, test schedule)")
ap.add_argument("--dt", type=float, default=None)
ap.add_argument("--resolution", type=float, default=0.025)
ap.add_argument("--exit", default=None, choices=("nearest", "face"))
ap.add_argument("--timeconst", type=float, default=None)
ap.add_argument("--policy", default="experiments/results/generalist_noent/policy.npz")
ap.add_argument("--robots", type=int, default=200)
ap.add_argument("--env", nargs="*", default=["robot.joint_damping=2.0", "robot.implicit_damping=true"])
a = ap.parse_args()
if a.exit:
    from mjx_stairs.sim import contact

    contact.set_exit_study(a.exit)  # before any model is put on the device
from mjx_stairs.rl.policy import load_policy
from mjx_stairs.study.evaluate import CellSpec, success_by_cell
from mjx_stairs.study.ground_truth import success_in_ground_truth

ov = tuple(a.env) + ((f"robot.timestep={a.dt}", f"decimation={round(0.02 / a.dt)}") if a.dt else ())
# no --timeconst: the evaluation preset's (0.01) on both sides; 0: go2.xml's 0.02
ov += (f"robot.contact_timeconst={a.timeconst}",) if a.timeconst is not None else ()
fam, lv = a.cell.split(":")
policy = load_policy(a.policy)
spec = CellSpec(cells=((fam, "test", int(lv) - 1),), robots_per_cell=a.robots, seed=0,
                resolution=a.resolution, env_overrides=ov)
t0 = time.time()
r = success_by_cell({"p": policy}, spec)["p"] if a.what == "mjx" else success_in_ground_truth(policy, spec)
print(json.dumps({"what": a.what, "cell": a.cell, "overrides": ov, "resolution": a.resolution,
                  "exit": a.exit, "timeconst": a.timeconst, "policy": a.policy, "robots": a.robots, "success": r["success"], "fell": r["fell"],
                  "mean_time_to_goal_s": r.get("mean_time_to_goal_s"), "wall": time.time() - t0}))
