"""Sim-to-sim: an exported policy (ONNX + sidecar) on a Go2 in MuJoCo itself.

The loop is a robot-side program's (docs/deploy.md): every control period it measures what a
Go2 measures (joint encoders, IMU angular velocity and attitude, the base velocity, stated as the
true base-frame velocity a state estimator would give, the base position for the goal, and a
height map of vertical ray casts against the stair geometry, as an elevation map gives it),
builds the observation from the sidecar alone (mjx_stairs.tools.contract), runs the ONNX graph in
onnxruntime, and holds the PD target it gives for the control period, the PD law running at every
physics step (`mujoco.mj_step`). Nothing of the training env computes anything here.

Options: action latency (the target takes effect `latency_ms` later, at the physics rate),
observation noise (uniform, the training half-widths of the sidecar), pushes (a planar base
velocity kick every `push_every_s`), a stiffer contact (`contact_timeconst`, every geom's solref
time constant in place of the MJCF's 0.02 s). Per episode: success and falls by the sidecar's
evaluation rules, and the number of times the trunk, hips, thighs and calves start touching a
step edge.
"""

from __future__ import annotations

import collections
import dataclasses
import json
import os
import time
from typing import Any, NamedTuple

import mujoco
import numpy as np

from mjx_stairs import atomic
from mjx_stairs.tools import contract as ct
from mjx_stairs.tools import sim2sim_world as sw


class Course(NamedTuple):
    """A staircase to walk: heights [ny, nx] at world (ix * res, iy * res), the spawn [7] (x, y,
    floor z, half x, half y, yaw, yaw half-range), the final goal [4] and the route [K, 3]."""

    name: str
    heights: np.ndarray
    resolution: float
    spawn: np.ndarray
    goal: np.ndarray
    route: np.ndarray


def tile_course(tile, name: str) -> Course:
    """A terrains.Tile as a course (the tile frame is the world frame)."""
    return Course(name, np.asarray(tile.heights, np.float64), float(tile.resolution),
                  np.asarray(tile.spawn, np.float64), np.asarray(tile.goal, np.float64),
                  np.asarray(tile.centreline, np.float64))


def family_course(family: str, level: int, schedule: str = "test", direction: str = "up",
                  variant: str | None = None, resolution: float = 0.025,
                  tile_size: float = 10.0) -> Course:
    """Level `level` (1-based) of a stair family's schedule, walked `direction`."""
    import terrains

    n = len(terrains.levels(family, schedule))
    if not 1 <= level <= n:
        raise ValueError(f"level {level} out of range: {family} has {n} {schedule} levels")
    tile = terrains.make_tile(family, level - 1, variant, schedule, resolution, tile_size,
                              direction=direction)
    return tile_course(tile, f"{family}_{schedule}_{level}_{direction}")


def mesh_course(path: str | os.PathLike, start: tuple[float, float], goal: tuple[float, float],
                route: np.ndarray | None = None, resolution: float = 0.025) -> Course:
    """A staircase mesh, ray-cast into a height grid (terrains.mesh_import; MuJoCo collides a
    mesh geom as its convex hull, so the stairs are the grid's boxes). `route` [K, 2] mesh-frame
    xy replaces the importer's route (its z read from the grid)."""
    from terrains.mesh_import import import_mesh

    tile = import_mesh(path, start, goal, resolution)
    c = tile_course(tile, os.path.splitext(os.path.basename(os.fspath(path)))[0])
    if route is None:
        return c
    xy = np.asarray(route, np.float64).reshape(-1, 2) - np.asarray(tile.spec["origin"])
    if len(xy) < 2:
        raise ValueError("a route needs at least two points")
    z = tile.height_at(xy[:, 0], xy[:, 1])
    return c._replace(route=np.concatenate([xy, np.asarray(z)[:, None]], 1))


@dataclasses.dataclass(frozen=True)
class Options:
    episodes: int = 1
    seed: int = 0
    episode_s: float = 20.0  # the evaluation episode of `mjx-stairs eval`
    latency_ms: float = 0.0
    noise: bool = False
    push: bool = False
    push_speed: float = 0.5  # m/s, planar, random direction
    push_every_s: float = 4.0
    contact_timeconst: float = 0.0  # > 0: every geom's solref time constant (sim2sim_world)


class Sim:
    """One Go2 in a world, stepped as a robot-side program steps the real one."""

    def __init__(self, contract: ct.Contract, policy, world: sw.World, course: Course,
                 options: Options = Options()):
        self.c, self.policy, self.w, self.course, self.o = contract, policy, world, course, options
        self.delay = int(round(options.latency_ms * 1e-3 / world.model.opt.timestep))
        self.delay_s = self.delay * world.model.opt.timestep  # as the robot measured it
        self.rng = np.random.default_rng(options.seed)

    def reset(self, x: float, y: float, yaw: float, z: float | None = None) -> None:
        """The base upright at (x, y, z) (default: spawn height above the spawn floor) facing
        `yaw`, joints at the nominal pose, at rest; the PD holds the nominal pose."""
        m, d, w = self.w.model, self.w.data, self.w
        mujoco.mj_resetData(m, d)
        ev = self.c.evaluation
        z = self.course.spawn[2] + ev.get("spawn_height_m", 0.36) if z is None else z
        d.qpos[w.base_qpos:w.base_qpos + 7] = [x, y, z, np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)]
        d.qpos[w.qpos_adr] = self.c.nominal
        mujoco.mj_forward(m, d)
        self.last_action = np.zeros(len(self.c.joint_names))
        self.history = ct.History(self.c, d.qpos[w.qpos_adr])
        self.seen: ct.Measurement | None = None  # what the last observation measured
        self.active = self.c.nominal.copy()
        self.pending: collections.deque = collections.deque()
        self.touching = np.zeros(m.ngeom, bool)
        self.onsets = np.zeros(len(sw.PARTS), np.int64)
        self.n = 0  # physics steps

    # ------------------------------------------------------------------ sensing

    def base(self) -> tuple[np.ndarray, np.ndarray]:
        """(position [3], rotation [3, 3] base -> world) of the base."""
        q = self.w.data.qpos[self.w.base_qpos:self.w.base_qpos + 7]
        rot = np.empty(9)
        mujoco.mju_quat2Mat(rot, q[3:7])
        return q[:3].copy(), rot.reshape(3, 3)

    def measure(self) -> ct.Measurement:
        """What the Go2 measures now, with the goal it is given."""
        d, w, c = self.w.data, self.w, self.c
        pos, rot = self.base()
        v = d.qvel[w.base_dof:w.base_dof + 6]  # world linear, base-frame angular
        xy = ct.map_points(c, pos, ct.base_yaw(rot))
        terrain_z = sw.terrain_z(w, xy)
        if c.hm_occlusion:  # the sidecar's rule: nothing behind a wall
            terrain_z = ct.occlude(c, pos, terrain_z,
                                   sw.elevation_z(w, ct.occlusion_points(c, pos, xy)))
        return ct.Measurement(
            joint_pos=d.qpos[w.qpos_adr].copy(), joint_vel=d.qvel[w.dof_adr].copy(),
            ang_vel=v[3:6].copy(), base_rot=rot, base_pos=pos, lin_vel=rot.T @ v[:3],
            last_action=self.last_action,
            target=ct.goal_target(c, pos[:2], self.course.goal, self.course.route),
            terrain_z=terrain_z, joint_pos_history=self.history.joint_pos,
            action_history=self.history.actions,
            action_delay_s=self.delay_s)

    def observe(self) -> np.ndarray:
        """The observation [D] (with the training noise when `options.noise`)."""
        self.seen = self.measure()
        obs = ct.observation(self.c, self.seen)
        if self.o.noise:
            obs = obs + (self.c.noise * self.rng.uniform(-1, 1, obs.shape)).astype(np.float32)
        return obs

    # ------------------------------------------------------------------ acting

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Run the policy, send its PD target, hold it for one control period; -> action."""
        a, target = ct.action_to_target(self.c, self.policy(obs))
        self.pending.append((self.n + self.delay, target))
        if self.seen is not None:  # the observation the policy acted on joins the history
            self.history.push(self.seen)
            self.seen = None
        self.last_action = a
        if self.o.push:
            self._maybe_push()
        m, d, w = self.w.model, self.w.data, self.w
        now = np.zeros(m.ngeom, bool)
        for _ in range(w.substeps):
            while self.pending and self.pending[0][0] <= self.n:
                self.active = self.pending.popleft()[1]
            self.apply_pd()
            mujoco.mj_step(m, d)
            self.n += 1
            now |= sw.touching_edges(w)
        # a touch counts once: a geom at a step edge in this control period, not in the last
        parts = w.part[now & ~self.touching]
        np.add.at(self.onsets, parts[parts >= 0], 1)
        self.touching = now
        return a

    def apply_pd(self) -> np.ndarray:
        """Set each joint's motor (by name) to the PD torque [12] of the target in effect."""
        d, w = self.w.data, self.w
        tau = ct.pd_torque(self.c, self.active, d.qpos[w.qpos_adr], d.qvel[w.dof_adr],
                           self.delay_s)
        d.ctrl[w.actuator] = tau / w.gear
        return tau

    def _maybe_push(self) -> None:
        every = max(1, int(round(self.o.push_every_s / self.c.control_dt)))
        step = self.n // self.w.substeps
        if step > 0 and step % every == 0:
            th = self.rng.uniform(0, 2 * np.pi)
            dof = self.w.base_dof
            self.w.data.qvel[dof:dof + 2] += self.o.push_speed * np.array([np.cos(th),
                                                                           np.sin(th)])

    def fallen(self) -> bool:
        """The sidecar's fall rule (tilt, base too low), a non-finite state, or off the map."""
        d, ev = self.w.data, self.c.evaluation
        pos, rot = self.base()
        if not (np.all(np.isfinite(d.qpos)) and np.all(np.isfinite(d.qvel))):
            return True
        length = ev.get("low_line_m", 0.0)  # the sidecar's rule: 5 points along the heading
        t = np.linspace(-length / 2, length / 2, 5) if length > 0 else np.zeros(1)
        heading = rot[:2, 0] / max(np.linalg.norm(rot[:2, 0]), 1e-9)
        z = sw.terrain_z(self.w, pos[:2] + t[:, None] * heading)  # t's middle point: the base
        if not np.isfinite(z[len(t) // 2]):  # off the staircase's grid
            return True
        ground = z[np.isfinite(z)].mean()  # points off the grid left out
        return bool(self.upright(pos, rot, heading) < np.cos(ev.get("max_tilt_rad", 1.0))
                    or pos[2] - ground < ev.get("min_base_height_m", 0.12))

    def upright(self, pos: np.ndarray, rot: np.ndarray, heading: np.ndarray) -> float:
        """The sidecar's tilt rule: cos of the body's z axis against the world's vertical, or,
        with tilt_slope_m > 0, against the normal of the terrain's slope along the heading: the
        least-squares line through the height at 9 points on that segment (off the grid: the
        world's vertical)."""
        length = self.c.evaluation.get("tilt_slope_m", 0.0)
        if length <= 0:
            return float(rot[2, 2])
        t = np.linspace(-length / 2, length / 2, 9)
        z = sw.terrain_z(self.w, pos[:2] + t[:, None] * heading)
        slope = np.arctan(((z - z.mean()) * t).sum() / (t * t).sum()) if np.all(
            np.isfinite(z)) else 0.0
        normal = np.array([-np.sin(slope) * heading[0], -np.sin(slope) * heading[1],
                           np.cos(slope)])
        return float(rot[:, 2] @ normal)


# ----------------------------------------------------------------------------- episodes


def starts(course: Course, contract: ct.Contract, n: int, seed: int = 0) -> np.ndarray:
    """[n, 3] (x, y, yaw): uniform on the course's spawn rectangle shrunk by the sidecar's
    spawn margin, yaw uniform in its range."""
    rng = np.random.default_rng(seed)
    x, y, _, hx, hy, yaw, half = course.spawn
    margin = contract.evaluation.get("spawn_margin_m", 0.15)
    u = rng.uniform(-1, 1, (n, 3))
    return np.stack([x + u[:, 0] * max(hx - margin, 0.0), y + u[:, 1] * max(hy - margin, 0.0),
                     yaw + u[:, 2] * half], -1)


def episode(sim: Sim, start: np.ndarray, record: bool = False) -> dict[str, Any]:
    """One episode from `start` (x, y, yaw) by the sidecar's evaluation rules: success (close
    and slow, held) ends it first, then a fall; else it times out. With `record`, the frames
    (one per control step) are returned under "frames"."""
    c, ev = sim.c, sim.c.evaluation
    sim.reset(*start)
    steps = int(round(sim.o.episode_s / c.control_dt))
    hold = max(1, int(round(ev.get("success_hold_s", 0.5) / c.control_dt)))
    goal, dof = sim.course.goal, sim.w.base_dof
    count, outcome, k = 0, "timeout", 0
    frames: list[dict[str, Any]] = []
    for k in range(1, steps + 1):
        obs = sim.observe()
        a = sim.act(obs)
        pos, _ = sim.base()
        if record:
            frames.append(_frame(sim, k, obs, a))
        speed = np.linalg.norm(sim.w.data.qvel[dof:dof + 2])
        close = (np.linalg.norm(goal[:2] - pos[:2]) < ev.get("success_distance_m", 0.5)
                 and speed < ev.get("success_speed_m_s", 0.3))
        count = count + 1 if close else 0
        if count >= hold:
            outcome = "success"
            break
        if sim.fallen():
            outcome = "fell"
            break
    pos, _ = sim.base()
    out = {"outcome": outcome, "success": outcome == "success", "fell": outcome == "fell",
           "time_s": k * c.control_dt, "start": [float(v) for v in start],
           "goal_distance_m": float(np.linalg.norm(goal[:2] - pos[:2])),
           "edge_contacts": {p: int(n) for p, n in zip(sw.PARTS, sim.onsets, strict=True)
                             if p != "foot"}}
    if record:
        out["frames"] = frames
    return out


def _frame(sim: Sim, k: int, obs: np.ndarray, action: np.ndarray) -> dict[str, Any]:
    d, w, c = sim.w.data, sim.w, sim.c
    pos, _ = sim.base()
    return {"t": k * c.control_dt, "qpos": d.qpos.copy(), "action": action,
            "q_target": c.nominal + c.action_scale * action,
            "joint_pos": d.qpos[w.qpos_adr].copy(), "joint_vel": d.qvel[w.dof_adr].copy(),
            "torque": d.ctrl[w.actuator] * w.gear, "height_map": obs[c.slices["height_map"]],
            "target": ct.goal_target(c, pos[:2], sim.course.goal, sim.course.route)}


def summarise(records: list[dict[str, Any]]) -> dict[str, Any]:
    """Success and fall rates, mean time to the goal and mean edge contacts per episode."""
    n = len(records)
    ok = [r for r in records if r["success"]]
    parts = [p for p in sw.PARTS if p != "foot"]
    return {
        "episodes": n,
        "success": sum(r["success"] for r in records) / max(n, 1),
        "fell": sum(r["fell"] for r in records) / max(n, 1),
        "mean_time_to_goal_s": float(np.mean([r["time_s"] for r in ok])) if ok else None,
        "edge_contacts_per_episode": {
            p: float(np.mean([r["edge_contacts"][p] for r in records])) if n else 0.0
            for p in parts},
    }


def run(onnx_path: str | os.PathLike, course: Course, options: Options = Options(),
        robot: str | os.PathLike | None = None, video: str | os.PathLike | None = None,
        mcap: str | os.PathLike | None = None, out: str | os.PathLike | None = None,
        start_poses: np.ndarray | None = None) -> dict[str, Any]:
    """`options.episodes` episodes of the ONNX policy on `course` (from `start_poses` [n, 3]
    when given, else `starts`); the first is recorded when a video or an MCAP is asked for.
    Returns (and writes to `out`, atomically) the summary, the settings and every episode."""
    t0 = time.time()
    contract = ct.load_contract(onnx_path)
    policy = ct.OnnxPolicy(onnx_path, contract)
    world = sw.build_world(contract, course.heights, course.resolution, robot,
                           contact_timeconst=options.contact_timeconst)
    sim = Sim(contract, policy, world, course, options)
    poses = starts(course, contract, options.episodes, options.seed) if start_poses is None \
        else np.asarray(start_poses, np.float64)
    records = [episode(sim, s, record=i == 0 and bool(video or mcap))
               for i, s in enumerate(poses)]
    frames = records[0].pop("frames", None) if records else None
    result = {
        **summarise(records), "course": course.name, "onnx": str(onnx_path),
        "onnx_sha256": contract.raw["onnx"]["sha256"], "robot": str(robot or sw.OUR_ROBOT),
        "robot_sha256": sw.file_sha256(robot or sw.OUR_ROBOT),
        "physics_dt_s": world.model.opt.timestep, "options": dataclasses.asdict(options),
        "base_velocity": "true base-frame velocity of the base origin (a state estimator's)",
        "wall_s": time.time() - t0, "records": records,
    }
    if frames:
        from mjx_stairs.tools import sim2sim_log

        if video:
            sim2sim_log.write_video(world, frames, video, contract.control_dt)
        if mcap:
            sim2sim_log.write_mcap(world, course, contract, frames, mcap)
    if out:
        atomic.write_text(out, json.dumps(result, indent=1) + "\n")
    return result
