# ruff: noqa: E501, E702, E401, E402, I001
"""Sunk sphere centres (inside a ground-truth box) along the GT and the MJX trajectories of
spiral L6 d2i from the same starts, judged against the same boxes."""
import os
import sys
import mujoco, numpy as np
from mjx_stairs.rl.policy import load_policy
from mjx_stairs.sim import box_world as bw
from mjx_stairs.study import ground_truth as gt
from mjx_stairs.study.evaluate import CellSpec
DAMP = (f"robot.joint_damping={os.environ.get('DAMPING', '2.0')}", "robot.implicit_damping=true")  # env DAMPING: N m s/rad
d = dict(np.load(sys.argv[1] + "/gt.npz"))
mq = np.load(sys.argv[1] + "/mjx_evaluation_exit_qpos.npy")  # [T, B, 19] after each step
mq = np.concatenate([d["qpos"][:1], mq], 0)
policy = load_policy("experiments/results/generalist_noent/policy.npz")
B = d["qpos"].shape[1]; fam, lv = (sys.argv[2] if len(sys.argv) > 2 else "spiral:6").split(":"); cell = (fam, "test", int(lv) - 1)
_, _, _, tiles, models = gt._start(policy, CellSpec(cells=(cell,), robots_per_cell=B, seed=0, resolution=float(sys.argv[3]) if len(sys.argv) > 3 else 0.025, env_overrides=DAMP), bw.DEFAULT_SOLVER, "boxes")
def count(Q, every=5):
    tot = 0; sunk = 0; deep = []
    for b in range(B):
        m = models[b]; dd = mujoco.MjData(m)
        box = np.array([i for i in range(m.ngeom) if m.geom(i).name.startswith("stair")])
        c = m.geom_pos[box]; h = m.geom_size[box]
        sph = [i for i in range(m.ngeom) if m.geom_type[i] == mujoco.mjtGeom.mjGEOM_SPHERE and m.geom_contype[i]]
        for k in range(0, Q.shape[0], every):
            if k > 0 and np.allclose(Q[k, b], Q[k - 1, b]):
                break  # the ground truth's episode has ended (its state held)
            if k > 0 and np.linalg.norm(Q[k, b, :2] - Q[k - every, b, :2]) > 0.5:
                break  # MJX's episode has ended: the robot is back at a spawn (auto-reset)
            if np.linalg.norm(Q[k, b, :2] - d["goal"][b, :2]) < 0.5:
                break  # at the goal: MJX's robots stand there to the episode's end, the
                # ground truth's stop once the success has held (climbing steps only)
            dd.qpos[:] = Q[k, b]; mujoco.mj_kinematics(m, dd)
            p = dd.geom_xpos[sph]
            ins = (np.abs(p[:, None, :] - c[None]) < h[None]).all(-1)
            tot += 1
            if ins.any():
                sunk += 1
                j, bi = np.argwhere(ins)[0]
                deep.append(c[bi, 2] + h[bi, 2] - p[j, 2])  # depth of the centre under that box's top
    deep = np.array(deep)
    return sunk / tot, tot, np.percentile(deep, [50, 90]) if deep.size else None
for name, Q in (("MuJoCo (GT)", d["qpos"]), ("MJX evaluation", mq)):
    f, n, dp = count(Q)
    print(f"{name}: sunk on {100*f:.1f} % of {n} sampled robot-steps; centre depth under the box top, median / p90: {np.round(dp*1e3,1)} mm", flush=True)
