"""How robots fail on suite cases (the code suite's commercial and residential staircases).

Rolls a policy's first episode per robot on named cases of a suite, in the evaluation env that
`mjx-stairs eval --suite` uses (study.cases: suite_cases -> case_atlas -> evaluate.eval_env ->
case_states; mean action, evaluation physics, robot k of every case from the same key), and
logs per robot and step: progress along the route (arc), the step it stands on (terrain height
under the base over the riser), base clearance, pitch and roll, speed along the route and in
the body frame, foot contacts split into tread and riser contacts (contact normal within 60 deg
of horizontal: a foot pushed by the riser's face, a toe stub), knee, shin and trunk contacts,
torque saturation, and at the end which ending fired (tilt > env.max_tilt, base below
env.min_base_height, leaving the atlas, NaN). Prints a summary per case and one line per robot
that fell, and writes everything as JSON.

    PYTHONPATH=. JAX_PLATFORMS=cpu python experiments/diagnose_cases.py \
        --checkpoint experiments/results/generalist/policy.npz --suite code \
        --case code_commercial_straight_up --robots 16 --episode-s 30 --out /tmp/diag.json
"""

from __future__ import annotations

import argparse
import json
import time

import jax
import jax.numpy as jnp
import numpy as np
from diagnose_episodes import first_episodes  # experiments/, the script's folder

from mjx_stairs.env import rewards as rw
from mjx_stairs.env.geometry import base_kinematics, wrap_angle
from mjx_stairs.rl.policy import load_policy
from mjx_stairs.sim import robot as rb
from mjx_stairs.study import evaluate
from mjx_stairs.study.cases import case_atlas, case_states, suite_cases
from mjx_stairs.study.specs import EvalSpec

RISER_NZ = 0.5  # a contact whose normal's |z| is under this pushes sideways: a face (60 deg)
WALL_FACE = 0.3  # m: a face taller than this across the contact is a wall's, not a riser's
LAST_S = 1.0  # the window before a fall that the per-robot lines describe
ENDINGS = ("tilt_termination", "low_termination", "outside_termination", "nan_reset",
           "trunk_termination")


def pitch_roll(g_body):
    """(pitch, roll) in rad from the unit gravity in the body frame: pitch > 0 nose up, roll > 0
    left side down."""
    return jnp.arcsin(jnp.clip(-g_body[..., 0], -1, 1)), jnp.arcsin(jnp.clip(g_body[..., 1], -1, 1))


def rollout(env, policy, state):
    """Per step [T, B, ...] records of each robot's first episode (frozen once it ended)."""
    tiles = env.tiles
    rows = env.contact_rows
    foot_geoms = jnp.asarray(env.robot.ids.foot_geoms)
    torque_limit = jnp.asarray(rb.TORQUE_LIMIT)

    def group(d, name):
        """([4] touching, [4] touching a riser's face, [4] touching a wall's face) of a sphere
        group: a face is a contact whose normal is within 60 deg of horizontal; a wall's face
        rises more than WALL_FACE m across it (a riser one riser)."""
        r = rows[name]
        if r is None:
            return (jnp.zeros(4, bool),) * 3
        c = d._impl.contact
        on = c.dist[r] < 1e-3
        n = c.frame[r][..., 0, :]  # [4, ncon, 3] normal, out of the terrain
        side = on & (jnp.abs(n[..., 2]) < RISER_NZ)
        p = c.pos[r]
        across = (env.terrain_height(p[..., 0] - 0.03 * n[..., 0], p[..., 1] - 0.03 * n[..., 1])
                  - env.terrain_height(p[..., 0] + 0.03 * n[..., 0],
                                       p[..., 1] + 0.03 * n[..., 1]))
        wall = side & (across > WALL_FACE)
        return on.any(-1), (side & ~wall).any(-1), wall.any(-1)

    def measure(st):
        d = st.pipeline_state
        kin = base_kinematics(d.qpos, d.qvel)
        tile = st.info["tile"]
        dc, arc = rw.centreline_geometry(kin.pos[:2], tiles.line[tile], tiles.line_cum[tile])
        target = env.goal_target(kin.pos, tile, arc, st.info)
        ground = env.terrain_height(kin.pos[0], kin.pos[1])
        pitch, roll = pitch_roll(kin.gravity_body)
        foot, foot_riser, foot_wall = group(d, "foot")
        knee, _, knee_wall = group(d, "knee")
        shin, _, shin_wall = group(d, "shin")
        trunk, _, trunk_wall = group(d, "trunk")
        return {
            "arc": arc,
            "centreline_distance": dc,
            "goal_distance": jnp.linalg.norm(tiles.goal[tile][:2] - kin.pos[:2]),
            "ground": ground,
            "clearance": kin.pos[2] - ground,
            "pitch": pitch, "roll": roll,
            "heading_error": wrap_angle(target[3] - kin.yaw),
            "forward_speed": kin.lin_vel_body[0],
            "lateral_speed": kin.lin_vel_body[1],
            "planar_speed": jnp.linalg.norm(d.qvel[:2]),
            "foot": foot, "foot_riser": foot_riser, "foot_wall": foot_wall, "knee": knee,
            "shin": shin, "trunk": trunk,
            # per robot (the trunk group has a row per body, the head among them since
            # robot.head_collision, so it is not the legs' 4)
            "wall": (foot_wall.any() | knee_wall.any() | shin_wall.any() | trunk_wall.any())[None],
            "x": kin.pos[0], "y": kin.pos[1], "yaw": kin.yaw,
            "yaw_to_route": wrap_angle(target[3] - kin.yaw),
            "saturated": jnp.abs(d.ctrl) > 0.99 * torque_limit,
            "foot_z": d.geom_xpos[foot_geoms, 2],
            "success": st.info["success"],
        }

    def at_end(st):
        """The ending step's success, endings and attitude (its state is the next episode's)."""
        pitch, roll = pitch_roll(st.info["final_obs"]["privileged_state"][:, 6:9])
        return {"success": st.metrics["episode_success"],
                **{k: st.metrics[k] for k in ENDINGS + ("terminated",)},
                "end_pitch": pitch, "end_roll": roll}

    return first_episodes(env, policy, state, measure, at_end)


def swing_rises(z, touching):
    """Per foot (FL, FR, RL, RR), how high each swing lifted it: the highest foot centre of a
    run of steps off the terrain less its height at the lift-off (a swing still open at the end
    counts). z, touching: [T, 4]. -> 4 lists, m."""
    out = []
    for k in range(z.shape[1]):
        edges = np.diff(np.concatenate([[0], (~touching[:, k]).astype(int), [0]]))
        runs = zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True)
        out.append([float(z[s:e, k].max() - z[max(s - 1, 0), k]) for s, e in runs])
    return out


def swing_summary(rises, riser):
    """Per foot: its swings (lift-off to touch-down), how high they rose (median, max; m) and the
    share of them that rose more than a riser (a step up needs the foot that high)."""
    return {
        "swings": [len(r) for r in rises],
        "swing_rise_m": [[round(float(np.median(r)), 3), round(float(np.max(r)), 3)] if r
                         else None for r in rises],
        "swings_over_riser": [round(float(np.mean(np.asarray(r) > riser)), 3) if r else None
                              for r in rises],
    }


def robot_records(env, rec, names, specs, robots, spawn_arc, spawn_z):
    """One dict per robot: outcome, ending, where, and the last LAST_S s before it ended."""
    dt = env.dt
    n_last = max(1, int(round(LAST_S / dt)))
    out = []
    origin = env.tile_origin[rec["tile"]]
    for b in range(rec["arc"].shape[1]):
        case = b // robots
        spec = specs[case]
        run = np.asarray(rec["running"][:, b])
        end = int(run.sum())  # steps run before the ending step
        lo = max(0, end - n_last)
        win = slice(lo, end + 1)
        fell = bool(rec["terminated"][-1, b] > 0)
        arc = rec["arc"][:, b]
        step_on = np.abs(rec["ground"][:, b] - spawn_z[b]) / spec["riser"]
        ending = next((k.removesuffix("_termination") for k in ENDINGS if rec[k][-1, b] > 0),
                      "success" if rec["success"][-1, b] > 0 else "timeout")
        route_speed = np.diff(arc[:end + 1]) / dt if end > 0 else np.zeros(1)
        w = lambda k, win=win, b=b: np.asarray(rec[k][win, b])  # noqa: E731
        # the steps with the base over the flights (not on the start floor or the top landing)
        fl = np.nonzero((step_on[:end + 1] > 0.5) & (step_on[:end + 1] < spec["risers"] - 0.5))[0]
        f = lambda k, fl=fl, b=b: np.asarray(rec[k][fl, b])  # noqa: E731
        out.append({
            "case": names[case], "robot": b % robots,
            "success": bool(rec["success"][-1, b] > 0), "fell": fell, "ending": ending,
            "end_s": float((end + 1) * dt),
            "success_s": float((np.argmax(rec["success"][:, b] > 0) + 1) * dt)
            if rec["success"][-1, b] > 0 else None,
            "arc_from_spawn_m": float(arc[end] - spawn_arc[b]),
            "route_m": float(np.asarray(env.tiles.line_len)[int(rec["tile"][b])]),
            "step_on": float(step_on[end]), "risers": int(spec["risers"]),
            "centreline_distance": float(rec["centreline_distance"][end, b]),
            "goal_distance": float(rec["goal_distance"][end, b]),
            "end_pitch_deg": float(np.degrees(rec["end_pitch"][-1, b])),
            "end_roll_deg": float(np.degrees(rec["end_roll"][-1, b])),
            "end_xy_in_tile": [float(rec["x"][end, b] - origin[b][0]),
                               float(rec["y"][end, b] - origin[b][1])],
            "end_yaw_to_route_deg": float(np.degrees(rec["yaw_to_route"][end, b])),
            "last": {
                "pitch_deg": [float(np.degrees(w("pitch").min())),
                              float(np.degrees(w("pitch").max()))],
                "max_abs_roll_deg": float(np.degrees(np.abs(w("roll")).max())),
                "clearance_m": [float(w("clearance").min()), float(w("clearance").max())],
                "forward_speed": float(w("forward_speed").mean()),
                "route_speed": float(route_speed[lo:].mean()) if end > lo else 0.0,
                "heading_error_deg": float(np.degrees(np.abs(w("heading_error")).max())),
                # steps with contact per foot FL FR RL RR, and of those on a riser's face
                "foot_steps": w("foot").sum(0).astype(int).tolist(),
                "foot_riser_steps": w("foot_riser").sum(0).astype(int).tolist(),
                "foot_wall_steps": w("foot_wall").sum(0).astype(int).tolist(),
                "wall_steps": int(w("wall").any(-1).sum()),
                "knee_steps": int(w("knee").any(-1).sum()),
                "shin_steps": int(w("shin").any(-1).sum()),
                "trunk_steps": int(w("trunk").any(-1).sum()),
                "saturated_steps": int(w("saturated").any(-1).sum()),
                # fraction of the steps each joint's torque is at its limit (joint_names order)
                "saturated_by_joint": np.round(w("saturated").mean(0), 3).tolist(),
            },
            "flight": {} if fl.size == 0 else {
                "s": float(fl.size * dt),
                "foot_riser_fraction": float(f("foot_riser").sum() / max(1, f("foot").sum())),
                "max_pitch_deg": float(np.degrees(f("pitch").max())),
                "max_abs_roll_deg": float(np.degrees(np.abs(f("roll")).max())),
                "min_clearance_m": float(f("clearance").min()),
                "clearance_p05_m": float(np.percentile(f("clearance"), 5)),
                "pitch_p95_deg": float(np.degrees(np.percentile(f("pitch"), 95))),
                "saturated_by_joint": np.round(f("saturated").mean(0), 3).tolist(),
            },
            "whole": {
                "route_speed": float(route_speed.mean()),
                "forward_speed": float(np.asarray(rec["forward_speed"][:end + 1, b]).mean()),
                "foot_riser_fraction": float(np.asarray(rec["foot_riser"][:end + 1, b]).sum()
                                             / max(1, np.asarray(rec["foot"][:end + 1, b]).sum())),
                "shin_steps": int(np.asarray(rec["shin"][:end + 1, b]).any(-1).sum()),
                "knee_steps": int(np.asarray(rec["knee"][:end + 1, b]).any(-1).sum()),
                "trunk_steps": int(np.asarray(rec["trunk"][:end + 1, b]).any(-1).sum()),
                "wall_steps": int(np.asarray(rec["wall"][:end + 1, b]).any(-1).sum()),
                "saturated_by_joint": np.round(
                    np.asarray(rec["saturated"][:end + 1, b]).mean(0), 3).tolist(),
                "min_clearance_m": float(np.asarray(rec["clearance"][:end + 1, b]).min()),
                "min_pitch_deg": float(np.degrees(np.asarray(rec["pitch"][:end + 1, b]).min())),
                **swing_summary(swing_rises(np.asarray(rec["foot_z"][:end + 1, b]),
                                            np.asarray(rec["foot"][:end + 1, b])),
                                spec["riser"]),
                "max_pitch_deg": float(np.degrees(np.asarray(rec["pitch"][:end + 1, b]).max())),
            },
        })
    return out


def case_summary(name, rs):
    """Counts per ending and where the falls happened."""
    falls = [r for r in rs if r["fell"]]
    s = {
        "case": name, "robots": len(rs),
        "success": sum(r["success"] for r in rs), "fell": len(falls),
        "timeout": sum(r["ending"] == "timeout" for r in rs),
        "endings": {e: sum(r["ending"] == e for r in rs)
                    for e in sorted({r["ending"] for r in rs})},
    }
    if falls:
        f = lambda k: [round(r[k], 2) for r in falls]  # noqa: E731
        s.update(fall_s=f("end_s"), fall_step=f("step_on"), fall_arc_m=f("arc_from_spawn_m"),
                 fall_end_pitch_deg=f("end_pitch_deg"), fall_end_roll_deg=f("end_roll_deg"))
    return s


def case_arguments(ap: argparse.ArgumentParser, episode_s: float) -> None:
    """The options of a script that rolls a policy on named suite cases (this one,
    experiments/reward_terms.py)."""
    ap.add_argument("--checkpoint", required=True)
    ap.add_argument("--suite", default="code")
    ap.add_argument("--case", required=True, help="case names, comma separated")
    ap.add_argument("--robots", type=int, default=8)
    ap.add_argument("--episode-s", type=float, default=episode_s)
    ap.add_argument("--resolution", type=float, default=0.025)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--env", nargs="*", default=[], help="env overrides KEY=VALUE")


def case_setup(a: argparse.Namespace):
    """(cases [(name, tile)], policy, env, state) for case_arguments' parsed options: the
    evaluation env of `mjx-stairs eval --suite` on those cases, robot k of every case from the
    same key."""
    wanted = a.case.split(",")
    every = dict(suite_cases(a.suite, a.resolution))
    missing = [n for n in wanted if n not in every]
    if missing:
        raise SystemExit(f"unknown cases {missing}; known: {', '.join(every)}")
    cases = [(n, every[n]) for n in wanted]
    spec = EvalSpec(robots_per_level=a.robots, episode_length_s=a.episode_s, seed=a.seed,
                    resolution=a.resolution, env_overrides=tuple(a.env))
    policy = load_policy(a.checkpoint)
    env = evaluate.eval_env(policy, case_atlas(cases), spec)
    return cases, policy, env, case_states(env, len(cases), a.robots, a.seed)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    case_arguments(ap, episode_s=30.0)
    ap.add_argument("--out", default=None)
    ap.add_argument("--riser", type=float, default=0.17,
                    help="m, for a case whose tile has no spec of its own (an imported mesh)")
    ap.add_argument("--risers", type=int, default=20, help="the same, risers up to the top")
    ap.add_argument("--trace", type=int, default=0,
                    help="print the first N falling robots' last 2 s every 0.1 s")
    a = ap.parse_args()
    cases, policy, env, state = case_setup(a)
    wanted = [name for name, _ in cases]
    t0 = time.time()
    rec = jax.device_get(jax.jit(lambda s: rollout(env, policy, s))(state))
    wall = time.time() - t0
    rec = {k: np.asarray(v) for k, v in rec.items()}
    rec["tile"] = np.asarray(state.info["tile"])
    pos = np.asarray(state.pipeline_state.qpos[:, :3])
    spawn_arc = np.asarray(jax.vmap(lambda p, t: rw.centreline_geometry(
        p[:2], env.tiles.line[t], env.tiles.line_cum[t])[1])(jnp.asarray(pos), state.info["tile"]))
    spawn_z = np.asarray(env.tiles.spawn)[rec["tile"], 2]
    # a mesh case's tile carries no riser: its exported JSON's spec does (--suite FOLDER)
    specs = [{"riser": a.riser, "risers": a.risers, **t.spec} for _, t in cases]
    robots = robot_records(env, rec, wanted, specs, a.robots, spawn_arc, spawn_z)
    summaries = [case_summary(n, robots[i * a.robots:(i + 1) * a.robots])
                 for i, n in enumerate(wanted)]
    for s in summaries:
        print(json.dumps(s))
    for r in robots:
        if r["fell"]:
            L = r["last"]
            print(f"{r['case']} #{r['robot']}: {r['ending']} at {r['end_s']:.2f} s, "
                  f"{r['arc_from_spawn_m']:.2f} m, step {r['step_on']:.1f}/{r['risers']}, end "
                  f"pitch {r['end_pitch_deg']:+.0f} roll {r['end_roll_deg']:+.0f} deg, at "
                  f"({r['end_xy_in_tile'][0]:.2f}, {r['end_xy_in_tile'][1]:.2f}) m in the tile, "
                  f"yaw to route {r['end_yaw_to_route_deg']:+.0f} deg; last "
                  f"{LAST_S:g} s: pitch {L['pitch_deg'][0]:+.0f}..{L['pitch_deg'][1]:+.0f}, "
                  f"|roll| {L['max_abs_roll_deg']:.0f}, clearance {L['clearance_m'][0]:.2f}.."
                  f"{L['clearance_m'][1]:.2f}, v_route {L['route_speed']:.2f}, feet "
                  f"{L['foot_steps']} riser {L['foot_riser_steps']} wall {L['foot_wall_steps']}, "
                  f"any part on a wall {L['wall_steps']}, knee {L['knee_steps']} "
                  f"shin {L['shin_steps']} trunk {L['trunk_steps']} sat {L['saturated_steps']}")
    dt = env.dt
    shown = 0
    for b, r in enumerate(robots):
        if shown >= a.trace or not r["fell"]:
            continue
        shown += 1
        end = int(rec["running"][:, b].sum())
        print(f"trace {r['case']} #{r['robot']}: t, arc, step, clearance, pitch, roll, v_fwd, "
              "yaw to route, feet (Tread/Riser/Wall), knee, shin, trunk")
        for k in range(max(0, end - int(2 / dt)), end + 1, max(1, int(round(0.1 / dt)))):
            feet = "".join("W" if rec["foot_wall"][k, b, i] else "R" if rec["foot_riser"][k, b, i]
                           else "T" if rec["foot"][k, b, i] else "." for i in range(4))
            print(f"  {(k + 1) * dt:6.2f} {rec['arc'][k, b]:6.2f} "
                  f"{abs(rec['ground'][k, b] - spawn_z[b]) / specs[b // a.robots]['riser']:5.1f} "
                  f"{rec['clearance'][k, b]:5.2f} {np.degrees(rec['pitch'][k, b]):+5.0f} "
                  f"{np.degrees(rec['roll'][k, b]):+5.0f} {rec['forward_speed'][k, b]:+5.2f} "
                  f"{np.degrees(rec['yaw_to_route'][k, b]):+5.0f} "
                  f"{feet} {''.join('k' if v else '.' for v in rec['knee'][k, b])} "
                  f"{''.join('s' if v else '.' for v in rec['shin'][k, b])} "
                  f"{''.join('t' if v else '.' for v in rec['trunk'][k, b])}")
    print(f"wall {wall:.0f} s (compile included), {len(robots)} robots, {env.episode_steps} steps")
    if a.out:
        with open(a.out, "w") as f:
            json.dump({"args": vars(a), "cases": summaries, "robots": robots,
                       "specs": [{k: v for k, v in s.items() if isinstance(v, (int, float, str))}
                                 for s in specs]}, f, indent=1)


if __name__ == "__main__":
    main()
