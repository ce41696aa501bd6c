"""A play rollout as an MCAP file for Foxglove: JSON messages with JSON schemas.

Foxglove's well-known types (recognised by schema name) carry what its 3D panel draws; plain JSON
objects carry what its Plot and Raw Message panels show. Log time = sim time in nanoseconds:
frame k (the state after policy step k + 1) at (k + 1) * dt; the static topics at 0.

Topics (i = robot index; every per-step topic has exactly one message per frame):

  /tf                     foxglove.FrameTransforms  per step: world -> robot{i}/base (the qpos
                          base pose), world -> robot{i}/heading (base position, yaw only), and
                          parent -> child for every leg body (hip, thigh, calf) from MuJoCo's
                          kinematics
  /terrain                foxglove.SceneUpdate      once: the atlas as a triangle mesh (flat
                          faces merged, vertical risers), world frame, coloured by height
  /robot_model            foxglove.SceneUpdate      once: the Go2's visual geoms and feet, locked
                          to the body frames (they move with /tf)
  /robot{i}/goal          foxglove.PoseInFrame      per step: the episode's goal, world frame
  /robot{i}/path          foxglove.PosesInFrame     per step: base poses of the running episode
                          every 0.1 s, and the current one
  /robot{i}/joint_states  mjx_stairs.JointState     per step: name, position, velocity, effort
  /robot{i}/foot_contacts mjx_stairs.FootContacts   per step: FL, FR, RL, RR (bool)
  /robot{i}/height_map    foxglove.Grid             per step: the 21 x 21 map the policy sees
                          (float32 "value" = base z - terrain z - 0.4, m) in robot{i}/heading
  /robot{i}/reward        mjx_stairs.Reward         per step: total and one field per term
  /robot{i}/action        mjx_stairs.Action         per step: action [12], q_target [12] (rad)
  /robot{i}/status        mjx_stairs.Status         per step: done, terminated, success, goal
                          distance, episode step, tile

Written through a temporary file and os.replace; chunks compressed with zstd.
"""

from __future__ import annotations

import base64
import json
import os
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from mjx_stairs.atomic import atomic_path
from mjx_stairs.env import observation
from mjx_stairs.env.geometry import quat_yaw, yaw_quat
from mjx_stairs.sim import robot as rb
from mjx_stairs.tools.mcap_schema import SCHEMAS, reward_schema

NS = 1_000_000_000

# ----------------------------------------------------------------------------- message parts


def stamp(t_ns: int) -> dict[str, int]:
    return {"sec": int(t_ns // NS), "nsec": int(t_ns % NS)}


def _v3(p) -> dict[str, float]:
    return {"x": float(p[0]), "y": float(p[1]), "z": float(p[2])}


def _q(q_wxyz) -> dict[str, float]:
    return {"x": float(q_wxyz[1]), "y": float(q_wxyz[2]), "z": float(q_wxyz[3]),
            "w": float(q_wxyz[0])}


def _pose_msg(pos, quat_wxyz) -> dict[str, Any]:
    return {"position": _v3(pos), "orientation": _q(quat_wxyz)}


def _rgba(c) -> dict[str, float]:
    return {"r": float(c[0]), "g": float(c[1]), "b": float(c[2]), "a": float(c[3])}


def body_transforms(model: mujoco.MjModel, data: mujoco.MjData,
                    qpos: np.ndarray) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """[(body id, position in parent, quat wxyz in parent)] for every body below the base."""
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    out = []
    for b in range(2, model.nbody):
        p = model.body_parentid[b]
        rot_p = data.xmat[p].reshape(3, 3)
        pos = rot_p.T @ (data.xpos[b] - data.xpos[p])
        q_inv = np.empty(4)
        mujoco.mju_negQuat(q_inv, data.xquat[p])
        quat = np.empty(4)
        mujoco.mju_mulQuat(quat, q_inv, data.xquat[b])
        out.append((b, pos, quat))
    return out


def terrain_entity(heights: np.ndarray, resolution: float) -> dict[str, Any]:
    """The heightfield as one TriangleListPrimitive (world frame), coloured by height.

    terrains.mesh.heights_to_mesh merges equal-height cells into rectangles and joins them with
    vertical walls, so stairs stay sharp with a few hundred triangles. Its cells are centred on
    the grid points (MuJoCo interpolates between them): the edges differ by half a cell.
    """
    from terrains.mesh import heights_to_mesh

    mesh = heights_to_mesh(heights, resolution)
    v = np.asarray(mesh.vertices, np.float64)
    f = np.asarray(mesh.faces, np.int64)
    z = v[:, 2]
    t = (z - z.min()) / max(z.max() - z.min(), 1e-6)
    lo, hi = np.array([0.30, 0.33, 0.40]), np.array([0.85, 0.80, 0.62])
    col = lo[None] + t[:, None] * (hi - lo)[None]
    return {
        "timestamp": stamp(0),
        "frame_id": "world",
        "id": "terrain",
        "lifetime": {"sec": 0, "nsec": 0},
        "frame_locked": False,
        "metadata": [{"key": "resolution_m", "value": f"{resolution:g}"}],
        "triangles": [{
            "pose": _pose_msg((0, 0, 0), (1, 0, 0, 0)),
            "points": [{"x": float(a), "y": float(b), "z": float(c)} for a, b, c in v],
            "color": _rgba((0.6, 0.6, 0.6, 1.0)),
            "colors": [_rgba((*c, 1.0)) for c in col],
            "indices": f.ravel().tolist(),
        }],
    }


def robot_entities(model: mujoco.MjModel, prefix: str) -> list[dict[str, Any]]:
    """One frame-locked entity per body with its visual geoms (boxes, cylinders, capsules) and
    the foot spheres, in the body's frame `{prefix}/{body}`."""
    entities = []
    for b in range(1, model.nbody):
        cubes, cylinders, spheres = [], [], []
        for g in np.nonzero(model.geom_bodyid == b)[0]:
            name = model.geom(g).name
            visual = model.geom_group[g] == 1
            if not visual and not name.endswith("_foot"):
                continue
            mat = model.geom_matid[g]
            rgba = model.mat_rgba[mat] if mat >= 0 else model.geom_rgba[g]
            if not visual:
                rgba = (0.1, 0.1, 0.1, 1.0)
            pose = _pose_msg(model.geom_pos[g], model.geom_quat[g])
            size = model.geom_size[g]
            kind = model.geom_type[g]
            if kind == mujoco.mjtGeom.mjGEOM_BOX:
                cubes.append({"pose": pose, "size": _v3(2 * size), "color": _rgba(rgba)})
            elif kind in (mujoco.mjtGeom.mjGEOM_CYLINDER, mujoco.mjtGeom.mjGEOM_CAPSULE):
                d, h = 2 * size[0], 2 * size[1]
                cylinders.append({"pose": pose, "size": {"x": d, "y": d, "z": h},
                                  "bottom_scale": 1.0, "top_scale": 1.0, "color": _rgba(rgba)})
                if kind == mujoco.mjtGeom.mjGEOM_CAPSULE:  # end caps
                    rot = np.empty(9)
                    mujoco.mju_quat2Mat(rot, model.geom_quat[g])
                    axis = rot.reshape(3, 3)[:, 2] * size[1]
                    for s in (-1.0, 1.0):
                        spheres.append({"pose": _pose_msg(model.geom_pos[g] + s * axis,
                                                          (1, 0, 0, 0)),
                                        "size": {"x": d, "y": d, "z": d},
                                        "color": _rgba(rgba)})
            elif kind == mujoco.mjtGeom.mjGEOM_SPHERE:
                d = 2 * size[0]
                spheres.append({"pose": pose, "size": {"x": d, "y": d, "z": d},
                                "color": _rgba(rgba)})
            elif kind == mujoco.mjtGeom.mjGEOM_ELLIPSOID:  # robot.terrain_contacts="nearest"
                spheres.append({"pose": pose, "size": _v3(2 * size), "color": _rgba(rgba)})
        if cubes or cylinders or spheres:
            body = model.body(b).name
            entities.append({
                "timestamp": stamp(0), "frame_id": f"{prefix}/{body}", "id": f"{prefix}/{body}",
                "lifetime": {"sec": 0, "nsec": 0}, "frame_locked": True, "metadata": [],
                "cubes": cubes, "cylinders": cylinders, "spheres": spheres,
            })
    return entities


def height_grid(values: np.ndarray, t_ns: int, frame: str, size: int, spacing: float,
                z: float) -> dict[str, Any]:
    """foxglove.Grid of one height map [size * size] (row-major, rows along the heading frame's
    y, columns along its x, cell centres at -half .. +half)."""
    half = 0.5 * (size - 1) * spacing
    data = np.ascontiguousarray(np.asarray(values, "<f4").reshape(size, size))
    return {
        "timestamp": stamp(t_ns),
        "frame_id": frame,
        "pose": _pose_msg((-half - 0.5 * spacing, -half - 0.5 * spacing, z), (1, 0, 0, 0)),
        "column_count": size,
        "cell_size": {"x": spacing, "y": spacing},
        "row_stride": 4 * size,
        "cell_stride": 4,
        "fields": [{"name": "value", "offset": 0, "type": 7}],  # 7 = FLOAT32
        "data": base64.b64encode(data.tobytes()).decode("ascii"),
    }


def robot_topics(i: int) -> list[str]:
    p = f"/robot{i}"
    return [f"{p}/goal", f"{p}/path", f"{p}/joint_states", f"{p}/foot_contacts",
            f"{p}/height_map", f"{p}/reward", f"{p}/action", f"{p}/status"]


# ----------------------------------------------------------------------------- the writer


def write_mcap(path: str | os.PathLike, env, r, policy_meta: dict[str, str] | None = None,
               path_every_s: float = 0.1) -> dict[str, int]:
    """Write rollout `r` (tools.play.Rollout) of `env` to `path`; returns {topic: count}.

    Long: the channels, the static topics, then the frames, in the order the file holds them.
    """
    from mcap.writer import CompressionType, Writer

    path = Path(path)
    model = env.robot.mj_model
    data = mujoco.MjData(model)
    terms = sorted(r.terms)
    path_stride = max(1, int(round(path_every_s / r.dt)))
    counts: dict[str, int] = {}
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start(profile="", library="mjx_stairs")
        schema_ids = {
            name: w.register_schema(name, "jsonschema", json.dumps(s).encode())
            for name, s in {**SCHEMAS, "mjx_stairs.Reward": reward_schema(terms)}.items()
        }
        channels: dict[str, int] = {}

        def channel(topic: str, schema: str) -> None:
            channels[topic] = w.register_channel(topic, "json", schema_ids[schema])
            counts[topic] = 0

        seq = [0]

        def put(topic: str, t_ns: int, msg: dict[str, Any]) -> None:
            w.add_message(channels[topic], log_time=t_ns, publish_time=t_ns,
                          data=json.dumps(msg, separators=(",", ":")).encode(),
                          sequence=seq[0])
            seq[0] += 1
            counts[topic] += 1

        channel("/tf", "foxglove.FrameTransforms")
        channel("/terrain", "foxglove.SceneUpdate")
        channel("/robot_model", "foxglove.SceneUpdate")
        kinds = ["foxglove.PoseInFrame", "foxglove.PosesInFrame", "mjx_stairs.JointState",
                 "mjx_stairs.FootContacts", "foxglove.Grid", "mjx_stairs.Reward",
                 "mjx_stairs.Action", "mjx_stairs.Status"]
        for i in range(r.num_robots):
            for topic, kind in zip(robot_topics(i), kinds, strict=True):
                channel(topic, kind)

        w.add_metadata("mjx_stairs", {
            "family": r.spec.family, "schedule": r.spec.schedule,
            "level": str(r.spec.level + 1), "staircase": r.terrain_name(),
            "robots": str(r.num_robots),
            "seed": str(r.spec.seed), "dt_s": repr(r.dt), "frames": str(r.num_frames),
            "reward_terms": ",".join(terms), "joint_names": ",".join(rb.JOINT_NAMES),
            **(policy_meta or {}),
        })

        heights = env.terrain.heights()
        put("/terrain", 0, {"deletions": [],
                            "entities": [terrain_entity(heights, env.resolution)]})
        put("/robot_model", 0, {"deletions": [], "entities": [
            e for i in range(r.num_robots) for e in robot_entities(model, f"robot{i}")]})

        paths: list[list[dict[str, Any]]] = [[] for _ in range(r.num_robots)]
        for k in range(r.num_frames):
            t_ns = int(round((k + 1) * r.dt * NS))
            put("/tf", t_ns, {"transforms": _transforms(model, data, r.qpos[k], stamp(t_ns))})
            for i in range(r.num_robots):
                msgs = _robot_messages(env, r, k, i, t_ns, paths[i], path_stride, terms)
                for topic, msg in zip(robot_topics(i), msgs, strict=True):
                    put(topic, t_ns, msg)
        w.finish()
    return counts


def _transforms(model: mujoco.MjModel, data: mujoco.MjData, qpos: np.ndarray,
                ts: dict[str, int]) -> list[dict[str, Any]]:
    """/tf of one frame: per robot world -> base, world -> heading, and every leg body."""
    out = []
    for i, q in enumerate(qpos):
        pre = f"robot{i}"
        yaw = quat_yaw(np.asarray(q[3:7], np.float64), np)
        out.append({"timestamp": ts, "parent_frame_id": "world", "child_frame_id": f"{pre}/base",
                    "translation": _v3(q[:3]), "rotation": _q(q[3:7])})
        out.append({"timestamp": ts, "parent_frame_id": "world",
                    "child_frame_id": f"{pre}/heading", "translation": _v3(q[:3]),
                    "rotation": _q(yaw_quat(yaw, np))})
        for b, pos, quat in body_transforms(model, data, q):
            parent = model.body(model.body_parentid[b]).name
            out.append({"timestamp": ts, "parent_frame_id": f"{pre}/{parent}",
                        "child_frame_id": f"{pre}/{model.body(b).name}",
                        "translation": _v3(pos), "rotation": _q(quat)})
    return out


def _robot_messages(env, r, k: int, i: int, t_ns: int, path: list[dict[str, Any]],
                    path_stride: int, terms: list[str]) -> list[dict[str, Any]]:
    """Robot i's messages of frame k, in robot_topics order; ``path`` (the running episode's
    poses) is updated in place."""
    ids, hm = env.robot.ids, env.config.height_map
    ts = stamp(t_ns)
    q, goal = r.qpos[k, i], r.goal[k, i]
    if k == 0 or r.step[k, i] == 0:  # a new episode (0: fresh after a reset)
        path.clear()
    pose = _pose_msg(q[:3], q[3:7])
    if r.step[k, i] % path_stride == 0 or not path:
        path.append(pose)
    shown = path if path[-1] is pose else [*path, pose]
    a = r.action[k, i]
    nominal = np.asarray(rb.NOMINAL_JOINT_POS, np.float64)
    return [
        {"timestamp": ts, "frame_id": "world",
         "pose": _pose_msg(goal[:3], yaw_quat(float(goal[3]), np))},
        {"timestamp": ts, "frame_id": "world", "poses": shown},
        {"timestamp": ts, "name": list(rb.JOINT_NAMES),
         "position": [float(x) for x in q[ids.qpos_joints]],
         "velocity": [float(x) for x in r.qvel[k, i][ids.qvel_joints]],
         "effort": [float(x) for x in r.torque[k, i]]},
        {"timestamp": ts, **{leg: bool(c) for leg, c in zip(rb.LEGS, r.foot_contact[k, i],
                                                           strict=True)}},
        height_grid(r.obs[k, i, observation.n_vec_of(env.config):], t_ns,
                    f"robot{i}/heading", hm.size,
                    hm.spacing, -rb.NOMINAL_BASE_HEIGHT),
        {"timestamp": ts, "total": float(r.reward[k, i]),
         **{t: float(r.terms[t][k, i]) for t in terms}},
        {"timestamp": ts, "action": [float(x) for x in a],
         "q_target": [float(x) for x in nominal + env.config.robot.action_scale * a]},
        {"timestamp": ts, "done": bool(r.done[k, i] > 0),
         "terminated": bool(r.terminated[k, i] > 0), "success": bool(r.success[k, i] > 0),
         "goal_distance": float(np.linalg.norm(goal[:2] - q[:2])),
         "episode_step": int(r.step[k, i]), "tile": int(r.tile[k, i])},
    ]


def read_mcap(path: str | os.PathLike) -> dict[str, list[tuple[int, dict[str, Any]]]]:
    """{topic: [(log_time_ns, decoded JSON message), ...]} of an MCAP written by write_mcap."""
    from mcap.reader import make_reader

    out: dict[str, list[tuple[int, dict[str, Any]]]] = {}
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        if summary is not None:
            for ch in summary.channels.values():
                out.setdefault(ch.topic, [])
        for _schema, channel, message in reader.iter_messages(log_time_order=True):
            out.setdefault(channel.topic, []).append((message.log_time,
                                                      json.loads(message.data)))
    return out
