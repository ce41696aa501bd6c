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
from mjx_stairs.env.geometry import quat_yaw, yaw_quat
from mjx_stairs.sim import robot as rb

NS = 1_000_000_000

# ----------------------------------------------------------------------------- JSON schemas
# The fields of Foxglove's message schemas (github.com/foxglove/schemas, schemas/jsonschema),
# composed from small parts.


def _obj(title: str, props: dict[str, Any], description: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {"title": title, "type": "object", "properties": props}
    if description:
        out["description"] = description
    return out


def _num() -> dict[str, str]:
    return {"type": "number"}


def _time() -> dict[str, Any]:
    return {
        "type": "object",
        "title": "time",
        "properties": {
            "sec": {"type": "integer", "minimum": 0},
            "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999},
        },
    }


def _vec3() -> dict[str, Any]:
    return _obj("foxglove.Vector3", {"x": _num(), "y": _num(), "z": _num()})


def _quat() -> dict[str, Any]:
    return _obj("foxglove.Quaternion", {"x": _num(), "y": _num(), "z": _num(), "w": _num()})


def _pose() -> dict[str, Any]:
    return _obj("foxglove.Pose", {"position": _vec3(), "orientation": _quat()})


def _color() -> dict[str, Any]:
    return _obj("foxglove.Color", {"r": _num(), "g": _num(), "b": _num(), "a": _num()})


def _point3() -> dict[str, Any]:
    return _obj("foxglove.Point3", {"x": _num(), "y": _num(), "z": _num()})


def _array(items: dict[str, Any]) -> dict[str, Any]:
    return {"type": "array", "items": items}


def _frame_transform() -> dict[str, Any]:
    return _obj(
        "foxglove.FrameTransform",
        {
            "timestamp": _time(),
            "parent_frame_id": {"type": "string"},
            "child_frame_id": {"type": "string"},
            "translation": _vec3(),
            "rotation": _quat(),
        },
        "A transform between two reference frames in 3D space",
    )


def _scene_entity() -> dict[str, Any]:
    shape = lambda title: _obj(title, {"pose": _pose(), "size": _vec3(), "color": _color()})
    cylinder = _obj(
        "foxglove.CylinderPrimitive",
        {"pose": _pose(), "size": _vec3(), "bottom_scale": _num(), "top_scale": _num(),
         "color": _color()},
    )
    triangles = _obj(
        "foxglove.TriangleListPrimitive",
        {"pose": _pose(), "points": _array(_point3()), "color": _color(),
         "colors": _array(_color()), "indices": _array({"type": "integer", "minimum": 0})},
    )
    return _obj(
        "foxglove.SceneEntity",
        {
            "timestamp": _time(),
            "frame_id": {"type": "string"},
            "id": {"type": "string"},
            "lifetime": {"type": "object", "title": "duration",
                         "properties": {"sec": {"type": "integer"},
                                        "nsec": {"type": "integer", "minimum": 0,
                                                 "maximum": 999999999}}},
            "frame_locked": {"type": "boolean"},
            "metadata": _array(_obj("foxglove.KeyValuePair",
                                    {"key": {"type": "string"}, "value": {"type": "string"}})),
            "cubes": _array(shape("foxglove.CubePrimitive")),
            "spheres": _array(shape("foxglove.SpherePrimitive")),
            "cylinders": _array(cylinder),
            "triangles": _array(triangles),
        },
        "A visual element in a 3D scene",
    )


def _floats(n: int | None = None) -> dict[str, Any]:
    out: dict[str, Any] = {"type": "array", "items": {"type": "number"}}
    if n is not None:
        out.update(minItems=n, maxItems=n)
    return out


SCHEMAS: dict[str, dict[str, Any]] = {
    "foxglove.FrameTransforms": _obj(
        "foxglove.FrameTransforms", {"transforms": _array(_frame_transform())},
        "An array of FrameTransform messages",
    ),
    "foxglove.SceneUpdate": _obj(
        "foxglove.SceneUpdate",
        {
            "deletions": _array(_obj("foxglove.SceneEntityDeletion",
                                     {"timestamp": _time(), "type": {"type": "integer"},
                                      "id": {"type": "string"}})),
            "entities": _array(_scene_entity()),
        },
        "An update to the entities displayed in a 3D scene",
    ),
    "foxglove.PoseInFrame": _obj(
        "foxglove.PoseInFrame",
        {"timestamp": _time(), "frame_id": {"type": "string"}, "pose": _pose()},
        "A timestamped pose for an object or reference frame in 3D space",
    ),
    "foxglove.PosesInFrame": _obj(
        "foxglove.PosesInFrame",
        {"timestamp": _time(), "frame_id": {"type": "string"}, "poses": _array(_pose())},
        "An array of timestamped poses for an object or reference frame in 3D space",
    ),
    "foxglove.Grid": _obj(
        "foxglove.Grid",
        {
            "timestamp": _time(),
            "frame_id": {"type": "string"},
            "pose": _pose(),
            "column_count": {"type": "integer", "minimum": 0},
            "cell_size": _obj("foxglove.Vector2", {"x": _num(), "y": _num()}),
            "row_stride": {"type": "integer", "minimum": 0},
            "cell_stride": {"type": "integer", "minimum": 0},
            "fields": _array(_obj("foxglove.PackedElementField",
                                  {"name": {"type": "string"},
                                   "offset": {"type": "integer", "minimum": 0},
                                   "type": {"type": "integer"}})),
            "data": {"type": "string", "contentEncoding": "base64"},
        },
        "A 2D grid of data",
    ),
    "mjx_stairs.JointState": _obj(
        "mjx_stairs.JointState",
        {"timestamp": _time(), "name": _array({"type": "string"}), "position": _floats(12),
         "velocity": _floats(12), "effort": _floats(12)},
        "Joint positions (rad), velocities (rad/s) and torques (N m) in JOINT_NAMES order",
    ),
    "mjx_stairs.FootContacts": _obj(
        "mjx_stairs.FootContacts",
        {"timestamp": _time(), **{leg: {"type": "boolean"} for leg in rb.LEGS}},
        "Whether each foot sphere touches the terrain",
    ),
    "mjx_stairs.Action": _obj(
        "mjx_stairs.Action",
        {"timestamp": _time(), "action": _floats(12), "q_target": _floats(12)},
        "Policy action (clipped as applied) and PD target q_nominal + action_scale * action",
    ),
    "mjx_stairs.Status": _obj(
        "mjx_stairs.Status",
        {"timestamp": _time(), "done": {"type": "boolean"}, "terminated": {"type": "boolean"},
         "success": {"type": "boolean"}, "goal_distance": _num(),
         "episode_step": {"type": "integer"}, "tile": {"type": "integer"}},
        "Episode status after the step (done: the episode ended and the robot was reset)",
    ),
}


def _reward_schema(terms: list[str]) -> dict[str, Any]:
    return _obj(
        "mjx_stairs.Reward",
        {"timestamp": _time(), "total": _num(), **{t: _num() for t in terms}},
        "Reward of the step: total and each term, already weighted and times dt",
    )


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
    """Write rollout `r` (tools.play.Rollout) of `env` to `path`; returns {topic: count}."""
    from mcap.writer import CompressionType, Writer

    path = Path(path)
    model = env.robot.mj_model
    ids = env.robot.ids
    data = mujoco.MjData(model)
    hm = env.config.height_map
    n_vec = env.observation_size["state"][0] - hm.size * hm.size
    terms = sorted(r.terms)
    nominal = np.asarray(rb.NOMINAL_JOINT_POS, np.float64)
    action_scale = env.config.robot.action_scale
    path_stride = max(1, int(round(path_every_s / r.dt)))
    counts: dict[str, int] = {}
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start(profile="", library="mjx_stairs")
        schema_ids = {
            name: w.register_schema(name, "jsonschema", json.dumps(s).encode())
            for name, s in {**SCHEMAS, "mjx_stairs.Reward": _reward_schema(terms)}.items()
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
            "level": str(r.spec.level + 1), "robots": str(r.num_robots),
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
            ts = stamp(t_ns)
            transforms = []
            for i in range(r.num_robots):
                q = r.qpos[k, i]
                pre = f"robot{i}"
                yaw = quat_yaw(np.asarray(q[3:7], np.float64), np)
                transforms.append({"timestamp": ts, "parent_frame_id": "world",
                                   "child_frame_id": f"{pre}/base", "translation": _v3(q[:3]),
                                   "rotation": _q(q[3:7])})
                transforms.append({"timestamp": ts, "parent_frame_id": "world",
                                   "child_frame_id": f"{pre}/heading",
                                   "translation": _v3(q[:3]), "rotation": _q(yaw_quat(yaw, np))})
                for b, pos, quat in body_transforms(model, data, q):
                    parent = model.body(model.body_parentid[b]).name
                    transforms.append({"timestamp": ts,
                                       "parent_frame_id": f"{pre}/{parent}",
                                       "child_frame_id": f"{pre}/{model.body(b).name}",
                                       "translation": _v3(pos), "rotation": _q(quat)})
            put("/tf", t_ns, {"transforms": transforms})

            for i in range(r.num_robots):
                tp = robot_topics(i)
                q = r.qpos[k, i]
                goal = r.goal[k, i]
                put(tp[0], t_ns, {"timestamp": ts, "frame_id": "world",
                                  "pose": _pose_msg(goal[:3], yaw_quat(float(goal[3]), np))})
                if k == 0 or r.step[k, i] == 0:  # a new episode (0: fresh after a reset)
                    paths[i] = []
                pose = _pose_msg(q[:3], q[3:7])
                if r.step[k, i] % path_stride == 0 or not paths[i]:
                    paths[i].append(pose)
                shown = paths[i] if paths[i][-1] is pose else [*paths[i], pose]
                put(tp[1], t_ns, {"timestamp": ts, "frame_id": "world", "poses": shown})
                put(tp[2], t_ns, {
                    "timestamp": ts, "name": list(rb.JOINT_NAMES),
                    "position": [float(x) for x in q[ids.qpos_joints]],
                    "velocity": [float(x) for x in r.qvel[k, i][ids.qvel_joints]],
                    "effort": [float(x) for x in r.torque[k, i]],
                })
                put(tp[3], t_ns, {"timestamp": ts, **{
                    leg: bool(c) for leg, c in zip(rb.LEGS, r.foot_contact[k, i],
                                                   strict=True)}})
                put(tp[4], t_ns, height_grid(r.obs[k, i, n_vec:], t_ns, f"robot{i}/heading",
                                             hm.size, hm.spacing, -rb.NOMINAL_BASE_HEIGHT))
                put(tp[5], t_ns, {"timestamp": ts, "total": float(r.reward[k, i]),
                                  **{t: float(r.terms[t][k, i]) for t in terms}})
                a = r.action[k, i]
                put(tp[6], t_ns, {"timestamp": ts, "action": [float(x) for x in a],
                                  "q_target": [float(x) for x in
                                               nominal + action_scale * a]})
                put(tp[7], t_ns, {
                    "timestamp": ts, "done": bool(r.done[k, i] > 0),
                    "terminated": bool(r.terminated[k, i] > 0),
                    "success": bool(r.success[k, i] > 0),
                    "goal_distance": float(np.linalg.norm(goal[:2] - q[:2])),
                    "episode_step": int(r.step[k, i]), "tile": int(r.tile[k, i]),
                })
        w.finish()
    return counts


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
