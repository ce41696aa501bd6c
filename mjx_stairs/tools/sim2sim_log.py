"""A recorded sim2sim episode as an mp4 (tracking camera on the base) and as an MCAP for Foxglove.

Frames are the runner's (mjx_stairs.tools.sim2sim.episode with record=True), one per control
step. The MCAP reuses mjx_stairs.tools.mcap_log's messages for one robot, "robot0":

  /tf                    foxglove.FrameTransforms  world -> robot0/base, robot0/heading, legs
  /terrain               foxglove.SceneUpdate      once: the staircase grid (vertical risers)
  /robot_model           foxglove.SceneUpdate      once: the robot's visual geoms
  /robot0/goal           foxglove.PoseInFrame      the goal the policy is given (waypoint)
  /robot0/joint_states   mjx_stairs.JointState     position, velocity, effort (sidecar order)
  /robot0/height_map     foxglove.Grid             the ray-cast map the policy sees
  /robot0/action         mjx_stairs.Action         action [12], q_target [12]
"""

from __future__ import annotations

import json
import os
from typing import Any

import mujoco
import numpy as np

from mjx_stairs.atomic import atomic_path
from mjx_stairs.tools.sim2sim_world import TERRAIN_GROUP

NS = 1_000_000_000


def render(world, frames: list[dict[str, Any]], width: int = 640, height: int = 480,
           stride: int = 1) -> np.ndarray:
    """[N, height, width, 3] uint8: every `stride`-th frame, a camera tracking the base."""
    from mjx_stairs.tools import play

    play.ensure_gl()
    model = play._with_offscreen(world.model, width, height)
    data = mujoco.MjData(model)
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_TRACKING
    cam.trackbodyid = world.base_body
    cam.distance, cam.azimuth, cam.elevation = 3.0, 225.0, -65.0  # above the stair walls
    shown = mujoco.MjvOption()  # visual groups 1 and 2 and the stairs, no collision geoms
    shown.geomgroup[:] = 0
    shown.geomgroup[[1, 2, TERRAIN_GROUP]] = 1
    picked = frames[::stride]
    out = np.empty((len(picked), height, width, 3), np.uint8)
    with mujoco.Renderer(model, height, width) as renderer:
        for i, f in enumerate(picked):
            data.qpos[:] = f["qpos"]
            mujoco.mj_forward(model, data)
            renderer.update_scene(data, camera=cam, scene_option=shown)
            play._add_marker(renderer.scene, np.asarray(f["target"][:3]) + [0.0, 0.0, 0.05])
            out[i] = renderer.render()
    return out


def write_video(world, frames: list[dict[str, Any]], path: str | os.PathLike,
                control_dt: float, fps: float = 25.0) -> int:
    """Render the frames to an mp4 playing in real time; returns the frames written."""
    from mjx_stairs.tools import play

    stride = max(1, int(round(1.0 / (control_dt * fps))))
    images = render(world, frames, stride=stride)
    play.write_video(images, path, 1.0 / (control_dt * stride))
    return len(images)


def write_mcap(world, course, contract, frames: list[dict[str, Any]],
               path: str | os.PathLike) -> dict[str, int]:
    """Write the recorded episode to `path` (atomically); returns {topic: messages}."""
    from mcap.writer import CompressionType, Writer

    from mjx_stairs.tools import mcap_log as ml
    from mjx_stairs.tools.mcap_schema import SCHEMAS

    topics = {"/tf": "foxglove.FrameTransforms", "/terrain": "foxglove.SceneUpdate",
              "/robot_model": "foxglove.SceneUpdate", "/robot0/goal": "foxglove.PoseInFrame",
              "/robot0/joint_states": "mjx_stairs.JointState",
              "/robot0/height_map": "foxglove.Grid", "/robot0/action": "mjx_stairs.Action"}
    counts = dict.fromkeys(topics, 0)
    data = mujoco.MjData(world.model)
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start(profile="", library="mjx_stairs sim2sim")
        schema = {k: w.register_schema(k, "jsonschema", json.dumps(SCHEMAS[k]).encode())
                  for k in set(topics.values())}
        chan = {t: w.register_channel(t, "json", schema[k]) for t, k in topics.items()}

        def put(topic: str, t_ns: int, msg: dict[str, Any]) -> None:
            w.add_message(chan[topic], log_time=t_ns, publish_time=t_ns, sequence=0,
                          data=json.dumps(msg, separators=(",", ":")).encode())
            counts[topic] += 1

        w.add_metadata("mjx_stairs", {"course": course.name, "frames": str(len(frames)),
                                      "joint_names": ",".join(contract.joint_names)})
        put("/terrain", 0, {"deletions": [], "entities": [
            ml.terrain_entity(course.heights, course.resolution)]})
        put("/robot_model", 0, {"deletions": [],
                                "entities": ml.robot_entities(world.model, "robot0")})
        for fr in frames:
            t_ns = int(round(fr["t"] * NS))
            ts = ml.stamp(t_ns)
            for topic, msg in _messages(world, contract, data, fr, t_ns, ts).items():
                put(topic, t_ns, msg)
        w.finish()
    return counts


def _messages(world, contract, data, fr: dict[str, Any], t_ns: int,
              ts: dict[str, int]) -> dict[str, dict[str, Any]]:
    from mjx_stairs.tools import mcap_log as ml

    goal = np.asarray(fr["target"], np.float64)
    half_yaw = 0.5 * goal[3]
    f = lambda v: [float(x) for x in v]
    return {
        "/tf": {"transforms": ml._transforms(world.model, data, fr["qpos"][None], ts)},
        "/robot0/goal": {"timestamp": ts, "frame_id": "world", "pose": ml._pose_msg(
            goal[:3], (np.cos(half_yaw), 0.0, 0.0, np.sin(half_yaw)))},
        "/robot0/joint_states": {"timestamp": ts, "name": list(contract.joint_names),
                                 "position": f(fr["joint_pos"]), "velocity": f(fr["joint_vel"]),
                                 "effort": f(fr["torque"])},
        "/robot0/height_map": ml.height_grid(fr["height_map"], t_ns, "robot0/heading",
                                             contract.hm_size,
                                             float(contract.raw["height_map"]["spacing_m"]),
                                             -0.3),
        "/robot0/action": {"timestamp": ts, "action": f(fr["action"]),
                           "q_target": f(fr["q_target"])},
    }
