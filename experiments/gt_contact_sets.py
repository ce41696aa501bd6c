"""Issue 19, the U-turn: on the same ground-truth states, each robot sphere's contacts in the
ground truth's boxes (CPU MuJoCo) against MJX's columns collider (the evaluation physics), by
normal class (tread-like "vert" |n_z| > 0.9, riser-like "horiz" |n_z| < 0.1, "edge" between);
penetrating contacts only (dist < 0). Prints the totals and up to MAX examples of a class where
the two differ.

Input: GT.npz from `experiments/gt_uturn_probe.py gt` (every policy step's state kept).
Usage (CPU): JAX_PLATFORMS=cpu PYTHONPATH=. python experiments/gt_contact_sets.py GT.npz \
    [--every 20] [--show horiz] [--max 25]
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx

from mjx_stairs.rl.policy import load_policy
from mjx_stairs.sim import box_world as bw
from mjx_stairs.study import ground_truth as gt
from mjx_stairs.study.evaluate import cell_env

sys.path.insert(0, "experiments")
sys.path.insert(0, "experiments/gpu")
from fidelity import OPTIONS, POLICIES  # noqa: E402
from gt_uturn_probe import ended, robot_and_box, robot_geoms, spec_of  # noqa: E402
from gt_uturn_probe import normal_class as ncls  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("gt")
    ap.add_argument("--every", type=int, default=20)
    ap.add_argument("--show", default="horiz")
    ap.add_argument("--max", type=int, default=25)
    a = ap.parse_args()
    d = np.load(a.gt)
    policy = load_policy(POLICIES[str(d["policy"])])
    cell, B = int(d["cell"]), d["qpos"].shape[1]
    env = cell_env(policy, spec_of(cell, B, OPTIONS["evaluation"]))
    _, _, _, _, models = gt._start(policy, spec_of(cell, B), bw.DEFAULT_SOLVER, "boxes")
    mm, mx = env.robot.mj_model, env.robot.mjx_model
    names = [mm.geom(i).name for i in range(mm.ngeom)]

    @jax.jit
    @jax.vmap
    def columns(q):
        c = mjx.forward(mx, mjx.make_data(mx).replace(qpos=q))._impl.contact
        return c.dist, c.geom, c.frame

    totals, shown = Counter(), 0
    for k in range(0, d["qpos"].shape[0], a.every):
        q = d["qpos"][k]
        dist, geom, frame = (np.asarray(x) for x in columns(jnp.asarray(q, jnp.float32)))
        for b in range(B):
            if ended(d["qpos"], k, b):
                continue
            model = models[b]
            dd = mujoco.MjData(model)
            dd.qpos[:] = q[b]
            mujoco.mj_forward(model, dd)
            g, x, gl, xl = Counter(), Counter(), {}, {}
            for i in range(dd.ncon):
                c = dd.contact[i]
                if c.dist >= 0:
                    continue
                robot, box = robot_and_box(model, c)
                g[robot, ncls(c.frame[2])] += 1
                gl.setdefault(robot, []).append((ncls(c.frame[2]), round(float(c.dist), 4),
                                                 model.geom(box).name))
            for i in np.flatnonzero(dist[b] < 0):
                gg = robot_geoms(mm, names, geom[b, i])
                if len(gg) != 1:
                    continue
                x[gg[0], ncls(frame[b, i][0, 2])] += 1
                xl.setdefault(gg[0], []).append((ncls(frame[b, i][0, 2]),
                                                 round(float(dist[b, i]), 4)))
            for key in set(g) | set(x):
                totals[key[1], "boxes"] += g[key]
                totals[key[1], "columns"] += x[key]
                if g[key] != x[key]:
                    totals[key[1], "states_differing"] += 1
                    if key[1] == a.show and shown < a.max:
                        shown += 1
                        print(dict(step=k, robot=b, sphere=key[0], boxes=gl.get(key[0]),
                                   columns=xl.get(key[0])))
    for key, n in sorted(totals.items()):
        print(*key, n)


if __name__ == "__main__":
    main()
