# ruff: noqa: E501, E702, E401, E402, I001
"""generalist_noent on one paper test cell (200 robots, seed 0, damping DAMP implicit) in the evaluation physics with its sunk-centre rule replaced by RULE for the process (contact.set_exit_study): python experiments/gt_spiral/face.py RULE FAMILY LEVEL DAMP."""
import json, sys, time
from mjx_stairs.sim import contact
rule = sys.argv[1]
contact.set_exit_study(rule)
from mjx_stairs.rl.policy import load_policy
from mjx_stairs.study.evaluate import CellSpec, success_by_cell
fam, lv, damp = sys.argv[2], int(sys.argv[3]), sys.argv[4]
ov = (f"robot.joint_damping={damp}", "robot.implicit_damping=true")
policy = load_policy("experiments/results/generalist_noent/policy.npz")
spec = CellSpec(cells=((fam, "test", lv - 1),), robots_per_cell=200, seed=0, env_overrides=ov)
t0 = time.time()
r = success_by_cell({"p": policy}, spec)["p"]
print(json.dumps({"rule": rule, "cell": [fam, lv], "damping": damp, "success": r["success"], "fell": r["fell"], "outcomes": r.get("outcomes"), "wall": time.time() - t0}))
