"""Issue 19, the U-turn: why ground-truth robots stall on the second flight of U-shaped
extended L3 where MJX's evaluation physics lets them climb (docs/results.md section 5b).

Subcommands (CPU: JAX_PLATFORMS=cpu, PYTHONPATH=.; cell 8 = U-shaped extended L3):
  gt OUT.npz [--robots 32] [--cell 8] [--iterations 100 --ls-iterations 50]
      the ground truth closed-loop (ground_truth.success_in_ground_truth), every policy step's
      state kept; time-outs and the step each stalls at
  replay GT.npz OUT.npz [--back 1.0] [--horizon 6]
      from each stalled GT robot's state `back` s before its stall, the policy closed-loop for
      `horizon` s in MJX (evaluation physics) and in the ground truth again
  segment GT.npz --at-step K
      every GT robot still running at step K, from its GT state there to the episode's end in
      MJX (evaluation physics): outcomes against the GT's own from the same states
  gaps GT.npz --at-step K
      per robot sphere, the nearest terrain contact distance in the GT boxes and in MJX's
      columns collider for the GT states at step K
  contacts GT.npz
      the contacts of stalled GT robots 1 s into their stall (geom, box, normal, force)
"""

from __future__ import annotations

import argparse
import sys

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from mjx_stairs.rl.policy import load_policy, policy_action
from mjx_stairs.sim import box_world as bw
from mjx_stairs.study import ground_truth as gt
from mjx_stairs.study.evaluate import CellSpec, cell_env, initial_states

sys.path.insert(0, "experiments/gpu")
from fidelity import CELLS, OPTIONS, POLICIES  # noqa: E402

STALL_SPEED = 0.05  # m/s: planar base speed (1 s average) below which a robot counts as stalled
STALL_S = 3.0  # s: that long


def spec_of(cell: int, robots: int, overrides=OPTIONS["reference"]) -> CellSpec:
    return CellSpec(cells=(CELLS[cell],), robots_per_cell=robots, env_overrides=overrides)


def normal_class(nz: float) -> str:
    """A contact normal's class: "vert" (tread-like, |n_z| > 0.9), "horiz" (riser-like,
    |n_z| < 0.1) or "edge" (between)."""
    return "vert" if abs(nz) > 0.9 else ("horiz" if abs(nz) < 0.1 else "edge")


def robot_and_box(model: mujoco.MjModel, c) -> tuple[str, int]:
    """(robot geom name, box geom id) of a ground-truth contact (boxes are named stair*)."""
    g1, g2 = model.geom(c.geom1).name, model.geom(c.geom2).name
    return (g2, c.geom1) if g1.startswith("stair") else (g1, c.geom2)


def robot_geoms(mm: mujoco.MjModel, names: list[str], pair) -> list[str]:
    """The names of an MJX contact's geoms that are not the heightfield."""
    return [names[j] for j in pair if mm.geom_type[j] != mujoco.mjtGeom.mjGEOM_HFIELD]


def ended(qpos: np.ndarray, k: int, b: int) -> bool:
    """Whether robot b's recorded episode had ended by policy step k (its state held)."""
    return k > 0 and np.allclose(qpos[k, b], qpos[k - 1, b])


def gt_run(policy, spec, start=None, steps=None, solver=bw.DEFAULT_SOLVER):
    """The ground truth closed-loop (ground_truth.success_in_ground_truth with every step's
    state kept). start: (qpos, qvel, last_action) or None (the evaluation's spawns).
    -> dict of qpos [T+1, B, 19], qvel [T+1, B, 18], action [T, B, 12], success, fell, t_goal."""
    env, state, info, tiles, models = gt._start(policy, spec, solver, "boxes")
    B = tiles.shape[0]
    if start is None:
        q0, v0, a0 = np.asarray(state.pipeline_state.qpos), None, np.zeros((B, 12), np.float32)
    else:
        q0, v0, a0 = start
    batch = bw.Batch(models, np.asarray(q0, np.float64),
                     None if v0 is None else np.asarray(v0, np.float64), nthread=1)
    goal = np.asarray(env.goals)[tiles]
    qs, vs, acts = [batch.qpos.copy()], [batch.qvel.copy()], []

    def record(b, last):
        qs.append(b.qpos.copy())
        vs.append(b.qvel.copy())
        acts.append(last.copy())

    ep = gt.closed_loop(env, policy, info, batch, goal, np.asarray(a0, np.float32),
                        steps or env.episode_steps, record)
    batch.close()
    return dict(qpos=np.array(qs), qvel=np.array(vs), action=np.array(acts), success=ep.success,
                fell=ep.fell, t_goal=ep.time_to_goal, tiles=tiles, goal=goal, dt=env.dt)


def mjx_run(policy, spec, start, steps):
    """MJX closed-loop (the spec's physics) from start = (qpos, qvel, last_action) [B, ...] on
    the tiles the spec's seed gives. -> qpos [T, B, 19], done [T, B] (first episode only),
    success [B], fell [B]."""
    env = cell_env(policy, spec)
    s0 = initial_states(env, spec)
    q, v, last = (jnp.asarray(x, jnp.float32) for x in start)
    info = dict(s0.info, last_action=last, step=jnp.zeros_like(s0.info["step"]))
    obs = jax.vmap(lambda q_, v_, i: env.observe(q_, v_, i))(
        q, v, {k: val for k, val in info.items() if k != "final_obs"})
    info["final_obs"] = obs
    st = s0.replace(pipeline_state=s0.pipeline_state.replace(qpos=q, qvel=v), obs=obs, info=info)

    def body(carry, _):
        s, finished, ok, fell = carry
        s = jax.vmap(env.step)(s, policy_action(policy, s.obs["state"]))
        done = s.done > 0
        first = done & ~finished
        # success is final: held long enough now (info) or at the step that ended the episode
        ok = ok | (~finished & ~done & (s.info["success"] > 0)) | (
            first & (s.metrics["episode_success"] > 0))
        fell = fell | (first & (s.metrics["terminated"] > 0))
        return (s, finished | done, ok, fell), (s.pipeline_state.qpos, finished | done)

    z = jnp.zeros(q.shape[0], bool)
    (_, _, ok, fell), (qs, done) = jax.jit(
        lambda s: jax.lax.scan(body, (s, z, z, z), None, length=steps))(st)
    return dict(qpos=np.asarray(qs), done=np.asarray(done), success=np.asarray(ok),
                fell=np.asarray(fell))


def stall_start(qpos: np.ndarray, dt: float, alive: np.ndarray) -> np.ndarray:
    """[B] the first policy step from which the base moved less than STALL_SPEED * STALL_S
    (planar) over the next STALL_S seconds, while alive; -1 if never."""
    w = int(round(STALL_S / dt))
    xy = qpos[:, :, :2]
    moved = np.linalg.norm(xy[w:] - xy[:-w], axis=-1)  # [T+1-w, B]
    out = np.full(qpos.shape[1], -1)
    for b in range(qpos.shape[1]):
        idx = np.flatnonzero((moved[:, b] < STALL_SPEED * STALL_S) & alive[b])
        if idx.size:
            out[b] = idx[0]
    return out


def cmd_gt(a):
    policy = load_policy(POLICIES[a.policy])
    solver = bw.SolverConfig(a.iterations, a.ls_iterations, a.tolerance)
    r = gt_run(policy, spec_of(a.cell, a.robots), solver=solver)
    timeout = ~(r["success"] | r["fell"])
    st = stall_start(r["qpos"], r["dt"], timeout)
    np.savez_compressed(a.out, **r, stall=st, cell=a.cell, policy=a.policy)
    print(f"success {r['success'].mean():.3f} fell {r['fell'].mean():.3f} "
          f"timeout {timeout.mean():.3f}; stall step of time-outs: {st[timeout].tolist()}")
    for b in np.flatnonzero(timeout):
        k = max(st[b], 0)
        print(f"  robot {b}: stall at {k * r['dt']:.1f} s, pos {np.round(r['qpos'][k, b, :3], 3)}"
              f" goal {np.round(r['goal'][b], 2)}")


def cmd_replay(a):
    d = np.load(a.gt)
    policy = load_policy(POLICIES[str(d["policy"])])
    dt = float(d["dt"])
    B = d["qpos"].shape[1]
    stalled = np.flatnonzero(d["stall"] >= 0)
    k = np.where(d["stall"] >= 0, np.maximum(d["stall"] - int(round(a.back / dt)), 0), 0)
    if a.at_step >= 0:
        k = np.full(B, a.at_step)
    start = (d["qpos"][k, np.arange(B)], d["qvel"][k, np.arange(B)],
             np.where((k > 0)[:, None], d["action"][np.maximum(k - 1, 0), np.arange(B)], 0.0))
    steps = int(round(a.horizon / dt))
    out = {}
    for name, ov in (("evaluation", OPTIONS["evaluation"]),):
        m = mjx_run(policy, spec_of(int(d["cell"]), B, ov), start, steps)
        out[name] = m
    g = gt_run(policy, spec_of(int(d["cell"]), B), start, steps)
    goal = d["goal"]

    def summary(qp, tag, ok, fell):
        dist = np.linalg.norm(qp[-1, :, :2] - goal[:, :2], axis=-1)
        moved = np.linalg.norm(qp[-1, :, :2] - qp[0, :, :2], axis=-1)
        print(f"{tag:11s} success {ok[stalled].astype(int).tolist()} fell "
              f"{fell[stalled].astype(int).tolist()}\n            goal dist at end "
              f"{np.round(dist[stalled], 2).tolist()}\n            moved "
              f"{np.round(moved[stalled], 2).tolist()}")

    print(f"stalled robots {stalled.tolist()}, from step {k[stalled].tolist()}")
    summary(g["qpos"], "gt", g["success"], g["fell"])
    for name, m in out.items():
        summary(m["qpos"], name, m["success"], m["fell"])
    np.savez_compressed(a.out, k=k, gt_qpos=g["qpos"], gt_success=g["success"],
                        **{f"{n}_qpos": m["qpos"] for n, m in out.items()},
                        **{f"{n}_success": m["success"] for n, m in out.items()})


def cmd_segment(a):
    """From the GT states at step k (robots still running there in the GT), MJX (evaluation
    physics) to the episode's end; outcomes against the GT's own from the same states."""
    d = np.load(a.gt)
    policy = load_policy(POLICIES[str(d["policy"])])
    B = d["qpos"].shape[1]
    T = d["action"].shape[0]
    k = a.at_step
    dt = float(d["dt"])
    t_goal = np.nan_to_num(d["t_goal"], nan=np.inf)
    fell_step = np.full(B, T + 1)
    alive = t_goal > k * dt
    # a GT robot that fell stops moving: its last change of qpos is its fall step
    for b in np.flatnonzero(d["fell"]):
        change = np.flatnonzero(np.any(d["qpos"][1:, b] != d["qpos"][:-1, b], -1))
        fell_step[b] = change[-1] + 1 if change.size else 0
    alive &= fell_step > k
    last = d["action"][k - 1] if k > 0 else np.zeros((B, 12), np.float32)
    m = mjx_run(policy, spec_of(int(d["cell"]), B, OPTIONS[a.option]),
                (d["qpos"][k], d["qvel"][k], last), T - k)
    gt_out = np.where(d["success"], "S", np.where(d["fell"], "F", "T"))
    mx_out = np.where(m["success"], "S", np.where(m["fell"], "F", "T"))
    n = alive.sum()
    for tag, o in (("gt", gt_out), (a.option, mx_out)):
        print(f"from step {k} ({n} robots alive): {tag:11s} success {np.mean(o[alive] == 'S'):.3f}"
              f" fell {np.mean(o[alive] == 'F'):.3f} timeout {np.mean(o[alive] == 'T'):.3f}")
    pairs = {}
    for g, x in zip(gt_out[alive], mx_out[alive], strict=True):
        pairs[g + x] = pairs.get(g + x, 0) + 1
    print("  pairs (gt, mjx):", dict(sorted(pairs.items())))
    if a.out:
        np.savez_compressed(a.out, alive=alive, gt=gt_out, mjx=mx_out, qpos=m["qpos"])


def sphere_gaps(a):
    """Per robot sphere, the nearest terrain contact distance (m; inf: none generated) in the
    ground truth's boxes and in MJX's evaluation collider, for the GT states at step k."""
    from mujoco import mjx

    d = np.load(a.gt)
    policy = load_policy(POLICIES[str(d["policy"])])
    B = d["qpos"].shape[1]
    k = a.at_step
    spec = spec_of(int(d["cell"]), B, OPTIONS["evaluation"])
    env = cell_env(policy, spec)
    _, _, _, tiles, models = gt._start(policy, spec_of(int(d["cell"]), B), bw.DEFAULT_SOLVER,
                                       "boxes")
    mm = env.robot.mj_model
    names = [mm.geom(i).name for i in range(mm.ngeom)]
    spheres = [i for i, n in enumerate(names) if n.endswith(("_foot", "_knee", "_shin"))
               or n.startswith("trunk_")]
    mx = env.robot.mjx_model

    def fwd(q):
        dd = mjx.forward(mx, mjx.make_data(mx).replace(qpos=q))
        c = dd._impl.contact
        return c.dist, c.geom

    dist, geom = jax.jit(jax.vmap(fwd))(jnp.asarray(d["qpos"][k], jnp.float32))
    dist, geom = np.asarray(dist), np.asarray(geom)
    gm = np.full((B, len(spheres)), np.inf)
    gg = np.full((B, len(spheres)), np.inf)
    for b in range(B):
        for j, g in enumerate(spheres):
            sel = (geom[b] == g).any(-1)
            if sel.any():
                gm[b, j] = dist[b][sel].min()
        m = models[b]
        dd = mujoco.MjData(m)
        dd.qpos[:] = d["qpos"][k, b]
        mujoco.mj_forward(m, dd)
        for i in range(dd.ncon):
            c = dd.contact[i]
            name = next(m.geom(x).name for x in (c.geom1, c.geom2)
                        if not m.geom(x).name.startswith("stair"))
            j = spheres.index(names.index(name))
            gg[b, j] = min(gg[b, j], c.dist)
    close_m, close_g = gm < 0.002, gg < 0.002
    both = np.isfinite(gm) & np.isfinite(gg) & (close_m | close_g)
    diff = np.abs(gm - gg)[both]
    print(f"step {k}: spheres in contact (<2 mm) MJX {close_m.sum()} GT {close_g.sum()}, only "
          f"MJX {(close_m & ~close_g).sum()}, only GT {(close_g & ~close_m).sum()}; |dist diff| "
          f"over {both.sum()}: mean {diff.mean() * 1e3:.2f} mm, max {diff.max() * 1e3:.2f} mm")
    bad = np.argwhere((np.abs(gm - gg) > 0.002) & (close_m | close_g))
    for b, j in bad[:12]:
        print(f"   robot {b} {names[spheres[j]]}: MJX {gm[b, j]:.4f} GT {gg[b, j]:.4f} "
              f"pos {np.round(d['qpos'][k, b, :3], 2)}")


def cmd_onestep(a):
    """One policy step (the GT's own action) from GT states at steps K in MJX (evaluation
    physics): the base's velocity error against the GT's next state, by where the robot is."""
    d = np.load(a.gt)
    policy = load_policy(POLICIES[str(d["policy"])])
    B = d["qpos"].shape[1]
    env = cell_env(policy, spec_of(int(d["cell"]), B, OPTIONS["evaluation"]))
    s0 = initial_states(env, spec_of(int(d["cell"]), B, OPTIONS["evaluation"]))
    dt = float(d["dt"])
    t_goal = np.nan_to_num(d["t_goal"], nan=np.inf)

    @jax.jit
    def step(q, v, last, act):
        info = dict(s0.info, last_action=last, step=jnp.zeros_like(s0.info["step"]))
        st = s0.replace(pipeline_state=s0.pipeline_state.replace(qpos=q, qvel=v), info=info)
        n = jax.vmap(env.step)(st, act)
        return n.pipeline_state.qpos, n.pipeline_state.qvel, n.done

    rows = []
    for k in [int(x) for x in a.steps.split(",")]:
        moving = np.any(d["qpos"][k + 1] != d["qpos"][k], -1) & (t_goal > (k + 1) * dt)
        last = d["action"][k - 1] if k > 0 else np.zeros((B, 12), np.float32)
        f32 = lambda x: jnp.asarray(x, jnp.float32)  # noqa: E731
        q, v, done = (np.asarray(x) for x in step(f32(d["qpos"][k]), f32(d["qvel"][k]),
                                                  f32(last), f32(d["action"][k])))
        ok = moving & (done == 0)
        err_v = np.linalg.norm(v[:, :3] - d["qvel"][k + 1, :, :3], axis=-1)
        err_w = np.linalg.norm(v[:, 3:6] - d["qvel"][k + 1, :, 3:6], axis=-1)
        err_p = np.linalg.norm(q[:, :3] - d["qpos"][k + 1, :, :3], axis=-1)
        for b in np.flatnonzero(ok):
            rows.append((k, b, *d["qpos"][k, b, :3], err_p[b], err_v[b], err_w[b]))
    r = np.array(rows)
    # where, by the terrain height under the base: floor, first flight, landing (half-way up),
    # second flight, top
    h = np.asarray(env.terrain_height(jnp.asarray(r[:, 2]), jnp.asarray(r[:, 3])))
    mid = 0.5 * float(np.asarray(env.goals)[:, 2].max())
    where = np.select([h < 0.01, h < mid - 0.01, h < mid + 0.01, h < 2 * mid - 0.01],
                      ["floor", "flight1", "landing", "flight2"], "top")
    print("where      n   |dv| m/s median / p90 / max   |dw| rad/s median / p90   |dp| mm median")
    for w in ("floor", "flight1", "landing", "flight2", "top"):
        m = where == w
        if m.any():
            print(f"{w:8s} {m.sum():4d}   {np.median(r[m, 6]):.4f} / "
                  f"{np.percentile(r[m, 6], 90):.4f} / {r[m, 6].max():.3f}      "
                  f"{np.median(r[m, 7]):.4f} / {np.percentile(r[m, 7], 90):.4f}     "
                  f"{1e3 * np.median(r[m, 5]):.3f}")
    if a.out:
        np.save(a.out, r)


def cmd_contacts(a):
    d = np.load(a.gt)
    policy = load_policy(POLICIES[str(d["policy"])])
    B = d["qpos"].shape[1]
    env, state, info, tiles, models = gt._start(policy, spec_of(int(d["cell"]), B),
                                                bw.DEFAULT_SOLVER, "boxes")
    for b in np.flatnonzero(d["stall"] >= 0):
        m = models[b]
        dd = mujoco.MjData(m)
        k = d["stall"][b] + int(round(1.0 / float(d["dt"])))
        dd.qpos[:], dd.qvel[:] = d["qpos"][k, b], d["qvel"][k, b]
        mujoco.mj_forward(m, dd)
        rows = {}
        f6 = np.zeros(6)
        for i in range(dd.ncon):
            c = dd.contact[i]
            robot, box_id = robot_and_box(m, c)
            box = m.geom(box_id).name
            mujoco.mj_contactForce(m, dd, i, f6)
            rows.setdefault(robot, []).append((box, round(float(c.dist), 4),
                                               np.round(c.frame[:3], 2).tolist(),
                                               round(float(f6[0]), 1)))
        print(f"robot {b} step {k}: base {np.round(dd.qpos[:3], 3)}")
        for g, r in sorted(rows.items()):
            print(f"   {g}: {r}")


def main():
    ap = argparse.ArgumentParser()
    sub = ap.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("gt")
    p.add_argument("out")
    p.add_argument("--robots", type=int, default=32)
    p.add_argument("--cell", type=int, default=8)
    p.add_argument("--policy", default="stage2_u")
    p.add_argument("--iterations", type=int, default=100)
    p.add_argument("--ls-iterations", type=int, default=50)
    p.add_argument("--tolerance", type=float, default=1e-8)
    p = sub.add_parser("replay")
    p.add_argument("gt")
    p.add_argument("out")
    p.add_argument("--back", type=float, default=1.0)
    p.add_argument("--horizon", type=float, default=6.0)
    p.add_argument("--at-step", type=int, default=-1)
    p = sub.add_parser("segment")
    p.add_argument("gt")
    p.add_argument("--at-step", type=int, default=0)
    p.add_argument("--option", default="evaluation")
    p.add_argument("--out", default="")
    p = sub.add_parser("gaps")
    p.add_argument("gt")
    p.add_argument("--at-step", type=int, default=250)
    p = sub.add_parser("onestep")
    p.add_argument("gt")
    p.add_argument("--steps", default="50,100,150,200,250,300,350")
    p.add_argument("--out", default="")
    p = sub.add_parser("contacts")
    p.add_argument("gt")
    a = ap.parse_args()
    {"gt": cmd_gt, "replay": cmd_replay, "segment": cmd_segment, "gaps": sphere_gaps,
     "onestep": cmd_onestep, "contacts": cmd_contacts}[a.cmd](a)


if __name__ == "__main__":
    main()
