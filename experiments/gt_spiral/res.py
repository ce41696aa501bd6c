# ruff: noqa: E501, E702, E401, E402, I001
"""generalist_noent on spiral test level 6 going up (200 robots, seed 0, damping 2 implicit) on a
finer grid: the atlas (MJX's columns, the robots' height map, the ground truth's boxes) at
RESOLUTION m instead of 0.025, so that the spiral's diagonal step edges are notched finer.
python experiments/gt_spiral/res.py RESOLUTION mjx|gt"""
import json, sys, time
from mjx_stairs.rl.policy import load_policy
from mjx_stairs.study.evaluate import CellSpec, success_by_cell
from mjx_stairs.study.ground_truth import success_in_ground_truth
res, what = float(sys.argv[1]), sys.argv[2]
ov = ("robot.joint_damping=2.0", "robot.implicit_damping=true")
policy = load_policy("experiments/results/generalist_noent/policy.npz")
spec = CellSpec(cells=(("spiral", "test", 5),), robots_per_cell=200, seed=0, resolution=res, env_overrides=ov)
t0 = time.time()
r = success_by_cell({"p": policy}, spec)["p"] if what == "mjx" else success_in_ground_truth(policy, spec)
print(json.dumps({"what": what, "resolution": res, "success": r["success"], "fell": r["fell"], "mean_time_to_goal_s": r.get("mean_time_to_goal_s"), "wall": time.time() - t0}))
