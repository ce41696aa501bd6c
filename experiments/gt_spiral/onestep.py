# ruff: noqa: E501, E702, E401, E402, I001
"""Spiral L6 d2i: from GT states (robots on the flights), (a) each sphere's nearest terrain
distance in MJX's columns collider and in the GT boxes, (b) one policy step in MJX with the GT's
own action, against the GT's next state: the bias in base height and planar progress."""
import sys
import jax, jax.numpy as jnp, mujoco, numpy as np
from mujoco import mjx
sys.path.insert(0, "experiments"); sys.path.insert(0, "experiments/gpu")
from fidelity import OPTIONS
from mjx_stairs.rl.policy import load_policy
from mjx_stairs.sim import box_world as bw
from mjx_stairs.study import ground_truth as gt
from mjx_stairs.study.evaluate import CellSpec, cell_env, initial_states

DAMP = ("robot.joint_damping=2.0", "robot.implicit_damping=true")
d = dict(np.load(sys.argv[1] + "/gt.npz"))
policy = load_policy("experiments/results/generalist_noent/policy.npz")
B = d["qpos"].shape[1]; cell = ("spiral", "test", 5)
spec = CellSpec(cells=(cell,), robots_per_cell=B, seed=0, env_overrides=(*OPTIONS["evaluation_exit"], *DAMP))
env = cell_env(policy, spec); s0 = initial_states(env, spec)
_, _, _, tiles, models = gt._start(policy, CellSpec(cells=(cell,), robots_per_cell=B, seed=0, env_overrides=DAMP), bw.DEFAULT_SOLVER, "boxes")
mm = env.robot.mj_model; names = [mm.geom(i).name for i in range(mm.ngeom)]
spheres = [i for i, n in enumerate(names) if n.endswith(("_foot", "_knee", "_shin")) or n.startswith("trunk_") or n == "head"]
mx = env.robot.mjx_model
print("env damping", env.config.robot.joint_damping, env.config.robot.implicit_damping, env.config.robot.sunk_exit, "gt model damping", models[0].dof_damping[6:9], "mjx", np.asarray(mx.dof_damping[6:9]), flush=True)

@jax.jit
def step(q, v, last, act):
    info = dict(s0.info, last_action=last, step=jnp.zeros_like(s0.info["step"]))
    st = s0.replace(pipeline_state=s0.pipeline_state.replace(qpos=q, qvel=v), info=info)
    n = jax.vmap(env.step)(st, act)
    return n.pipeline_state.qpos, n.pipeline_state.qvel

@jax.jit
def contacts(q):
    def fwd(qq):
        dd = mjx.forward(mx, mjx.make_data(mx).replace(qpos=qq))
        return dd._impl.contact.dist, dd._impl.contact.geom
    return jax.vmap(fwd)(q)

z0 = d["qpos"][0, :, 2]; rise = d["goal"][:, 2] - z0
rows = []
for k in range(50, 951, 50):
    fr = (d["qpos"][k, :, 2] - z0) / rise
    moving = ~np.all(np.isclose(d["qpos"][k + 1], d["qpos"][k]), axis=1)
    sel = moving & (fr > 0.05) & (fr < 0.95)
    if not sel.any():
        continue
    q, v = d["qpos"][k], d["qvel"][k]
    last = d["action"][k - 1]; act = d["action"][k]
    nq, nv = step(jnp.asarray(q, jnp.float32), jnp.asarray(v, jnp.float32), jnp.asarray(last), jnp.asarray(act))
    nq, nv = np.asarray(nq), np.asarray(nv)
    gq, gv = d["qpos"][k + 1], d["qvel"][k + 1]
    dz = (nq[:, 2] - gq[:, 2])[sel]; dvz = (nv[:, 2] - gv[:, 2])[sel]
    dxy = np.linalg.norm(nq[:, :2] - q[:, :2], axis=1)[sel] - np.linalg.norm(gq[:, :2] - q[:, :2], axis=1)[sel]
    dist, geom = contacts(jnp.asarray(q, jnp.float32)); dist, geom = np.asarray(dist), np.asarray(geom)
    gm = np.full((B, len(spheres)), np.inf); gg = np.full((B, len(spheres)), np.inf)
    for b in np.flatnonzero(sel):
        for j, g in enumerate(spheres):
            s_ = (geom[b] == g).any(-1)
            if s_.any():
                gm[b, j] = dist[b][s_].min()
        m = models[b]; dd = mujoco.MjData(m); dd.qpos[:] = q[b]; mujoco.mj_forward(m, dd)
        for i in range(dd.ncon):
            c = dd.contact[i]
            nm = next(m.geom(x).name for x in (c.geom1, c.geom2) if not m.geom(x).name.startswith("stair"))
            if names.index(nm) in spheres:
                j = spheres.index(names.index(nm)); gg[b, j] = min(gg[b, j], c.dist)
    cm, cg = gm < 0.002, gg < 0.002
    both = np.isfinite(gm) & np.isfinite(gg) & (cm | cg)
    diff = np.abs(gm - gg)[both]
    print(f"k {k:4d} n {sel.sum():3d}: one step MJX-GT dz {dz.mean()*1e3:+.2f} mm (sd {dz.std()*1e3:.2f}), dvz {dvz.mean():+.4f} m/s, planar progress {dxy.mean()*1e3:+.2f} mm; "
          f"contacts MJX {cm.sum()} GT {cg.sum()} (only MJX {(cm & ~cg).sum()}, only GT {(cg & ~cm).sum()}), |dist diff| mean {diff.mean()*1e3 if diff.size else 0:.2f} max {diff.max()*1e3 if diff.size else 0:.2f} mm", flush=True)
    rows.append((k, sel.sum(), dz.mean(), dvz.mean(), dxy.mean()))
r = np.array(rows, float); w = r[:, 1]
print("weighted mean over states: dz %+.3f mm, dvz %+.4f m/s, planar %+.3f mm per policy step" % tuple((r[:, c] * w).sum() / w.sum() * s for c, s in ((2, 1e3), (3, 1), (4, 1e3))))
