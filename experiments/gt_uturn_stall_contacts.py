"""Issue 19, the U-turn: paired outcomes and the contacts of robots that succeed in MJX but time
out in the ground truth (docs/results.md section 5b).

Inputs: GT.npz from `gt_uturn_probe.py gt` and MJX.npz from `gt_uturn_probe.py segment GT.npz
--at-step 0 --out MJX.npz` (MJX, evaluation physics, from the same spawns). Writes OUT.json:
  - the per-robot cross-tab (GT outcome x MJX outcome, S / F / T),
  - for each MJX-success / GT-time-out robot: where its GT stall is (arc length along the
    tile's centre-line, terrain height under the base below the top, in risers) and, over its
    stall (every 10 policy steps from the stall start for 3 s), per robot sphere, the contacts
    in the GT boxes (box, its top height, normal class: vertical = tread-like |n_z| > 0.9,
    horizontal = riser-like |n_z| < 0.1, edge = between) and in MJX's columns collider for the
    same states, and in MJX's own trajectory where its base passes nearest the GT stall point.

Usage (CPU): JAX_PLATFORMS=cpu PYTHONPATH=. python experiments/gt_uturn_stall_contacts.py \
    GT.npz MJX.npz OUT.json
"""

from __future__ import annotations

import json
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
from gt_uturn_probe import normal_class as ncls  # noqa: E402
from gt_uturn_probe import robot_and_box, robot_geoms, spec_of  # noqa: E402

ACTIVE = 1e-3  # m: a contact counts when its distance is below this


def main(gt_path, mjx_path, out):
    d, m = np.load(gt_path), np.load(mjx_path)
    policy = load_policy(POLICIES[str(d["policy"])])
    cell = int(d["cell"])
    B = d["qpos"].shape[1]
    dt = float(d["dt"])
    g_out, x_out = m["gt"], m["mjx"]
    tab = Counter(g + x for g, x in zip(g_out, x_out, strict=True))
    env = cell_env(policy, spec_of(cell, B, OPTIONS["evaluation"]))
    _, _, _, tiles, models = gt._start(policy, spec_of(cell, B), bw.DEFAULT_SOLVER, "boxes")
    mm = env.robot.mj_model
    names = [mm.geom(i).name for i in range(mm.ngeom)]
    mx = env.robot.mjx_model

    @jax.jit
    def mjx_contacts(q):
        dd = mjx.forward(mx, mjx.make_data(mx).replace(qpos=q))
        c = dd._impl.contact
        return c.dist, c.geom, c.frame

    def mjx_rows(q):
        dist, geom, frame = (np.asarray(x) for x in mjx_contacts(jnp.asarray(q, jnp.float32)))
        rows = []
        for i in np.flatnonzero(dist < ACTIVE):
            g = robot_geoms(mm, names, geom[i])
            if len(g) != 1:
                continue
            rows.append((g[0], ncls(frame[i][0, 2]), float(dist[i])))
        return rows

    def gt_rows(model, q, v):
        dd = mujoco.MjData(model)
        dd.qpos[:], dd.qvel[:] = q, v
        mujoco.mj_forward(model, dd)
        f6 = np.zeros(6)
        rows = []
        for i in range(dd.ncon):
            c = dd.contact[i]
            if c.dist >= ACTIVE:
                continue
            robot, box = robot_and_box(model, c)
            mujoco.mj_contactForce(model, dd, i, f6)
            top = float(model.geom_pos[box][2] + model.geom_size[box][2])
            rows.append((robot, ncls(c.frame[2]), float(c.dist), model.geom(box).name,
                         round(top, 3), float(f6[0])))
        return rows

    report = dict(cell=cell, policy=str(d["policy"]), robots=B,
                  crosstab_gt_mjx={k: int(v) for k, v in sorted(tab.items())},
                  gt_rates={o: float(np.mean(g_out == o)) for o in "SFT"},
                  mjx_rates={o: float(np.mean(x_out == o)) for o in "SFT"}, robots_TS=[])
    sel = np.flatnonzero((g_out == "T") & (x_out == "S"))
    agg = {"gt": Counter(), "mjx_same_state": Counter(), "mjx_own_pass": Counter()}
    for b in sel:
        tile = int(tiles[b])
        line3 = np.asarray(env.tiles.line3[tile])
        cum = np.asarray(env.tiles.line_cum[tile])
        top = float(env.tiles.top[tile])
        model = models[b]
        # riser height: the most common step between the box tops of this staircase
        tops = np.unique(np.round(model.geom_pos[:, 2] + model.geom_size[:, 2], 3))
        steps = np.diff(tops)
        riser = float(np.median(steps[steps > 0.05])) if (steps > 0.05).any() else np.nan
        k0 = int(max(d["stall"][b], 0))

        def where(q, line3=line3, cum=cum):
            from mjx_stairs.env import rewards as rw
            off, arc = rw.centreline_geometry(jnp.asarray(q[:2]), jnp.asarray(line3[:, :2]),
                                              jnp.asarray(cum))
            h = float(env.terrain_height(jnp.asarray(q[0:1]), jnp.asarray(q[1:2]))[0])
            return float(arc), float(off), h

        arc, off, h = where(d["qpos"][k0, b])
        rec = dict(robot=int(b), stall_s=round(k0 * dt, 2), base=np.round(d["qpos"][k0, b, :3],
                   3).tolist(), arc_m=round(arc, 3), line_len_m=round(float(cum[-1]), 3),
                   offset_m=round(off, 3), terrain_below_top_m=round(top - h, 3),
                   risers_below_top=round((top - h) / riser, 2), riser_m=round(riser, 3))
        ks = list(range(k0, min(k0 + int(3.0 / dt), d["action"].shape[0]), 10))
        per = {"gt": Counter(), "mjx_same_state": Counter()}
        for k in ks:
            for r in gt_rows(model, d["qpos"][k, b], d["qvel"][k, b]):
                per["gt"][f"{r[0]}:{r[1]}"] += 1
            for r in mjx_rows(d["qpos"][k, b]):
                per["mjx_same_state"][f"{r[0]}:{r[1]}"] += 1
        rec["gt_contacts_1s"] = [list(r) for r in gt_rows(
            model, d["qpos"][min(k0 + 50, len(d["qpos"]) - 1), b],
            d["qvel"][min(k0 + 50, len(d["qpos"]) - 1), b])]
        # MJX's own run: the policy steps where its base is within 0.25 m of the GT stall point
        xq = m["qpos"][:, b]
        near = np.linalg.norm(xq[:, :2] - d["qpos"][k0, b, :2], axis=-1)
        idx = np.flatnonzero(near < 0.25)
        rec["mjx_time_near_stall_s"] = round(len(idx) * dt, 2)
        rec["mjx_nearest_m"] = round(float(near.min()), 3)
        per["mjx_own_pass"] = Counter()
        for k in idx[::5]:
            for r in mjx_rows(xq[k]):
                per["mjx_own_pass"][f"{r[0]}:{r[1]}"] += 1
        rec["samples"] = dict(gt=len(ks), mjx_own_pass=len(idx[::5]))
        for key, c in per.items():
            rec[key] = dict(sorted(c.items()))
            n = len(ks) if key != "mjx_own_pass" else max(len(idx[::5]), 1)
            for kk, v in c.items():
                agg[key][kk] += v / n
        report["robots_TS"].append(rec)
        print(json.dumps({k: v for k, v in rec.items() if not k.startswith(("gt", "mjx_s"))}))
    # mean contacts per sampled state (per sphere:normal class), over the T/S robots
    n = max(len(sel), 1)
    report["mean_contacts_per_state"] = {
        key: {kk: round(v / n, 3) for kk, v in sorted(c.items())} for key, c in agg.items()}
    with open(out, "w") as f:
        json.dump(report, f, indent=1)
    print(json.dumps(report["crosstab_gt_mjx"]), json.dumps(report["mean_contacts_per_state"],
                                                            indent=1))


if __name__ == "__main__":
    main(*sys.argv[1:4])
