"""Issue 25: why a Go2 with the description's joint damping does not climb building-code risers.

    JAX_PLATFORMS=cpu PYTHONPATH=. python experiments/damping_climb_probe.py OUT \
        --onnx experiments/results/sim2sim/code_200/generalist_mix/policy.onnx \
        --case code_commercial_straight_up --dampings 0.1,2 --episodes 8

In MuJoCo itself (sim2sim's robot, `go2_full.xml`, with every joint's damping set to each value;
the same starts for each), every episode recorded, and per episode: the outcome, the height
climbed (the base's highest z over its start), the share of control steps at which the policy
stood still (base speed under 0.1 m/s), and per joint kind (hip, thigh, calf) the share of PD
torques at the motor limit, the mean |joint speed| and the mean |PD target - position|; the share
of action entries at the clip. OUT/<case>_d<damping>.json (every episode), OUT/<case>.md (the
means). Both MJX and MuJoCo itself climb none of the code cases up at a damping of 2
(docs/results.md 8j): this says whether the motors run out of torque or the policy asks too little.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

from mjx_stairs import atomic
from mjx_stairs.tools import contract as ct
from mjx_stairs.tools import sim2sim as s2s
from mjx_stairs.tools import sim2sim_world as sw

KINDS = ("hip", "thigh", "calf")


def robot_with_damping(damping: float, out: Path) -> Path:
    """A copy of sim2sim's robot in folder `out` with every joint's damping set (in the file's
    default class)."""
    text = sw.OUR_ROBOT.read_text()
    if text.count('damping="2"') != 1:
        raise SystemExit(f"{sw.OUR_ROBOT}: expected one joint default damping=\"2\"")
    path = out / f"go2_full_d{damping:g}.xml"
    path.write_text(text.replace('damping="2"', f'damping="{damping:g}"'))
    return path


def episode_facts(sim: s2s.Sim, start: np.ndarray) -> dict:
    """One recorded episode's outcome and what its joints and motors did."""
    c = sim.c
    r = s2s.episode(sim, start, record=True)
    frames = r.pop("frames")
    qpos = np.array([f["qpos"] for f in frames])
    base = qpos[:, sim.w.base_qpos:sim.w.base_qpos + 3]
    speed = np.linalg.norm(np.diff(base[:, :2], axis=0), axis=-1) / c.control_dt
    tau = np.array([f["torque"] for f in frames])
    vel = np.abs(np.array([f["joint_vel"] for f in frames]))
    err = np.abs(np.array([f["q_target"] - f["joint_pos"] for f in frames]))
    act = np.abs(np.array([f["action"] for f in frames]))
    at_limit = np.abs(tau) >= c.torque_limit - 1e-6
    kind = np.array([next(k for k in KINDS if k in n) for n in c.joint_names])
    per = {k: {"torque_at_limit": float(at_limit[:, kind == k].mean()),
               "joint_speed_rad_s": float(vel[:, kind == k].mean()),
               "tracking_error_rad": float(err[:, kind == k].mean())} for k in KINDS}
    return {**r, "climbed_m": float(base[:, 2].max() - base[0, 2]),
            "still": float((speed < 0.1).mean()),
            "action_at_clip": float((act >= c.action_clip - 1e-6).mean()), "joints": per}


def means(records: list[dict]) -> dict:
    keys = ("success", "fell", "climbed_m", "still", "action_at_clip")
    out = {k: float(np.mean([r[k] for r in records])) for k in keys}
    for k in KINDS:
        for f in records[0]["joints"][k]:
            out[f"{k}_{f}"] = float(np.mean([r["joints"][k][f] for r in records]))
    return out


def main(argv: list[str] | None = None) -> None:
    from terrains.suites import find_case

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out", type=Path)
    p.add_argument("--onnx", type=Path, required=True)
    p.add_argument("--case", default="code_commercial_straight_up")
    p.add_argument("--dampings", default="0.1,2")
    p.add_argument("--episodes", type=int, default=8)
    p.add_argument("--episode-s", type=float, default=30.0)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args(argv)
    a.out.mkdir(parents=True, exist_ok=True)
    c = ct.load_contract(a.onnx)
    policy = ct.OnnxPolicy(a.onnx, c)
    course = s2s.tile_course(find_case("code", a.case).tile(0.025), a.case)
    poses = s2s.starts(course, c, a.episodes, a.seed)
    rows, robots = {}, Path(tempfile.mkdtemp())
    for d in (float(v) for v in a.dampings.split(",")):
        world = sw.build_world(c, course.heights, course.resolution, robot_with_damping(d, robots))
        sim = s2s.Sim(c, policy, world, course, s2s.Options(episode_s=a.episode_s, seed=a.seed))
        records = [episode_facts(sim, s) for s in poses]
        rows[d] = means(records)
        atomic.write_text(a.out / f"{a.case}_d{d:g}.json", json.dumps(
            {"case": a.case, "onnx": str(a.onnx), "damping": d, "episode_s": a.episode_s,
             "means": rows[d], "records": records}, indent=1) + "\n")
        print(f"damping {d:g}: {rows[d]}", flush=True)
    cols = list(next(iter(rows.values())))
    lines = ["| damping | " + " | ".join(cols) + " |", "|---|" + "---|" * len(cols)]
    lines += [f"| {d:g} | " + " | ".join(f"{v[k]:.3f}" for k in cols) + " |"
              for d, v in rows.items()]
    atomic.write_text(a.out / f"{a.case}.md", "\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
