"""Issue 19, the U-turn: one 5 ms physics substep from identical ground-truth states and the same
motor torques (the ground truth's PD torques for the policy's recorded action), in the ground
truth (boxes, CPU MuJoCo) and in the evaluation physics (MJX, columns collider); the base
velocity error after the substep over all sampled states, and the contacts (depth, normal,
normal force) of the states that part most. With `nearest`, the columns collider pushes a sunk
centre out through its nearest exposed face (experiments/gt_sunk_exit.py).

Input: GT.npz from `experiments/gt_uturn_probe.py gt`.
Usage (CPU): JAX_PLATFORMS=cpu PYTHONPATH=. python experiments/gt_one_substep.py GT.npz EVERY \
    [top|nearest]
"""

# ruff: noqa: E501, E702
import sys

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx

sys.path.insert(0, "experiments")
sys.path.insert(0, "experiments/gpu")
from fidelity import OPTIONS, POLICIES  # noqa: E402
from gt_uturn_probe import ended, robot_and_box, robot_geoms, spec_of  # noqa: E402

from mjx_stairs.rl.policy import load_policy  # noqa: E402
from mjx_stairs.sim import box_world as bw  # noqa: E402
from mjx_stairs.sim import robot as rb  # noqa: E402
from mjx_stairs.study import ground_truth as gt  # noqa: E402
from mjx_stairs.study.evaluate import cell_env  # noqa: E402

d = np.load(sys.argv[1]); every = int(sys.argv[2])
rule = sys.argv[3] if len(sys.argv) > 3 else "top"
policy = load_policy(POLICIES[str(d["policy"])]); cell = int(d["cell"]); B = d["qpos"].shape[1]
env = cell_env(policy, spec_of(cell, B, (*OPTIONS["evaluation"], f"robot.sunk_exit={rule}")))
_, _, _, _, models = gt._start(policy, spec_of(cell, B), bw.DEFAULT_SOLVER, "boxes")
c = env.config
mm, mx = env.robot.mj_model, env.robot.mjx_model
names = [mm.geom(i).name for i in range(mm.ngeom)]
print("sunk exit", rule, "hfield", mm.hfield(0).name)

@jax.jit
@jax.vmap
def mstep(q, v, u):
    dd = mjx.make_data(mx).replace(qpos=q, qvel=v, ctrl=u)
    d1 = mjx.forward(mx, dd)
    d2 = mjx.step(mx, dd)
    ct = d1._impl.contact
    return d2.qvel, ct.dist, ct.geom, ct.frame, ct.efc_address, d1._impl.efc_force, d1.qfrc_constraint

rows = []
for k in range(0, d["action"].shape[0], every):
    q, v = d["qpos"][k], d["qvel"][k]
    target = rb.NOMINAL_JOINT_POS + c.robot.action_scale * d["action"][k]
    tau = np.zeros((B, mm.nu)); gv = np.zeros((B, 18)); gcon = []
    for b in range(B):
        m = models[b]; dd = mujoco.MjData(m)
        dd.qpos[:], dd.qvel[:], dd.ctrl[:] = q[b], v[b], target[b]
        mujoco.mj_forward(m, dd)
        tau[b] = dd.actuator_force
        f6 = np.zeros(6); cl = []
        for i in range(dd.ncon):
            cc = dd.contact[i]
            mujoco.mj_contactForce(m, dd, i, f6)
            rob = robot_and_box(m, cc)[0]
            cl.append((rob, round(float(cc.dist), 4), np.round(cc.frame[:3], 2).tolist(), round(float(f6[0]), 1)))
        gcon.append((cl, dd.qfrc_constraint[:3].copy()))
        mujoco.mj_step(m, dd)
        gv[b] = dd.qvel
    out = mstep(jnp.asarray(q, jnp.float32), jnp.asarray(v, jnp.float32), jnp.asarray(tau, jnp.float32))
    xv, dist, geom, frame, addr, efc, qfc = (np.asarray(x) for x in out)
    for b in range(B):
        if ended(d["qpos"], k, b):
            continue
        err = float(np.linalg.norm(xv[b, :3] - gv[b, :3]))
        xl = []
        for i in np.flatnonzero(dist[b] < 0):
            gg = robot_geoms(mm, names, geom[b, i])
            fn = float(efc[b, addr[b, i]: addr[b, i] + 4].sum()) if addr[b, i] >= 0 else np.nan
            xl.append((gg[0] if gg else "?", round(float(dist[b, i]), 4), np.round(frame[b, i][0], 2).tolist(), round(fn, 1)))
        rows.append((err, k, b, gcon[b], xl, gv[b, :3], xv[b, :3], qfc[b, :3]))
errs = np.array([r[0] for r in rows])
print("states", len(rows), "base vel error after one substep: median", np.median(errs), "p90", np.percentile(errs, 90), "p99", np.percentile(errs, 99), "max", errs.max(), "share>1e-3", (errs > 1e-3).mean(), "share>1e-2", (errs > 1e-2).mean())
for r in sorted(rows, key=lambda r: -r[0])[:6]:
    print("\nerr", round(r[0], 4), "k", r[1], "b", r[2], "gt v", np.round(r[5], 4), "mjx v", np.round(r[6], 4))
    print("  GT qfrc_con[:3]", np.round(r[3][1], 1), " MJX", np.round(r[7], 1))
    print("  GT :", sorted(r[3][0]))
    print("  MJX:", sorted(r[4]))
