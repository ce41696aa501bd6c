# ruff: noqa: E501, E702, E401, E402, I001
"""generalist_noent on spiral test level 6 going up (200 robots, seed 0, damping 2 implicit) with
a shorter physics step in both simulators: the evaluation physics in MJX and CPU MuJoCo on the
grid's boxes, each with robot.timestep=DT and decimation 0.02 / DT (the same 20 ms policy step).
python experiments/gt_spiral/dt.py DT mjx|gt"""
import json, sys, time
from mjx_stairs.rl.policy import load_policy
from mjx_stairs.study.evaluate import CellSpec, success_by_cell
from mjx_stairs.study.ground_truth import success_in_ground_truth
dt, what = float(sys.argv[1]), sys.argv[2]
ov = ("robot.joint_damping=2.0", "robot.implicit_damping=true", f"robot.timestep={dt}", f"decimation={round(0.02 / dt)}")
policy = load_policy("experiments/results/generalist_noent/policy.npz")
spec = CellSpec(cells=(("spiral", "test", 5),), robots_per_cell=200, seed=0, env_overrides=ov)
t0 = time.time()
r = success_by_cell({"p": policy}, spec)["p"] if what == "mjx" else success_in_ground_truth(policy, spec)
print(json.dumps({"what": what, "timestep": dt, "overrides": ov, "success": r["success"], "fell": r["fell"], "mean_time_to_goal_s": r.get("mean_time_to_goal_s"), "physics_settings": r.get("physics_settings"), "wall": time.time() - t0}))
