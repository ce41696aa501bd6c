"""The JSON sidecar of an exported policy: everything a robot-side program needs beside the ONNX
graph, written from the env's one observation table (mjx_stairs.env.observation) and the config
the policy was trained with.

Sections: onnx (input/output, sha256), observation (layout with units, scales, clip ranges and
training noise), normalizer, height_map (grid, frame, offset, clip, sampling), joints (our order,
the Go2 SDK's motor order and the mapping), action, pd, rates, goal (final goal or waypoint on a
route, and how the waypoint is computed), base_velocity, evaluation (the success and fall rules
and the episode starts), training (what the policy was trained to withstand: joint damping,
action delay, pushes, height-map offsets and holes, perturbed routes), versions, policy. The
robot side reads it with mjx_stairs.tools.contract, which imports nothing of the training code.
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import platform
from typing import Any

import numpy as np

from mjx_stairs.env import observation
from mjx_stairs.env.config import EnvConfig, env_config_from, leg_damping
from mjx_stairs.rl.policy import STD_EPS, Policy, normaliser_constants, saved_config
from mjx_stairs.sim import robot as rb
from mjx_stairs.sim import solref

FORMAT = "mjx_stairs policy sidecar v2"
OPSET = 17

SDK_LEGS = ("FR", "FL", "RR", "RL")
SDK_JOINT_NAMES = tuple(f"{leg}_{part}_joint" for leg in SDK_LEGS
                        for part in ("hip", "thigh", "calf"))
"""The Go2 SDK's motor order (unitree_sdk2 LowCmd/LowState motor_cmd[0..11])."""


class SidecarError(RuntimeError):
    """The policy's layout is not the stair env's."""


def _floats(values) -> list[float]:
    """float32 values as the decimals they were written as (23.7, not 23.700000762939453)."""
    return [float(str(np.float32(v))) for v in np.ravel(values)]


def _clip_ranges(cfg: EnvConfig) -> dict[str, list[float] | None]:
    """[lo, hi] each term is clipped to before it enters the graph (None: not clipped)."""
    hm = cfg.height_map
    return {"last_action": [-cfg.action_clip, cfg.action_clip],
            "action_history": [-cfg.action_clip, cfg.action_clip],
            "height_map": [-hm.clip, hm.clip]}


def _goal_description(cfg: EnvConfig, desc: str) -> str:
    if cfg.goal_mode != "waypoint":
        return desc
    yaw = {"ahead": "the centre-line's heading there",
           "here": "the centre-line's heading at the base's projection",
           "chord": "the heading from the base's projection to it"}[cfg.waypoint_heading]
    return (f"{desc}; the 'goal' is a waypoint: the point {cfg.waypoint_lookahead_m:g} m "
            "further along the stair centre-line than the base's projection on it, with "
            f"{yaw} as its yaw, and the final goal (position and yaw) once "
            f"that is nearer than {cfg.waypoint_lookahead_m:g} m along the line (see 'goal')")


def _layout(cfg: EnvConfig) -> list[dict[str, Any]]:
    hm, clips = cfg.height_map, _clip_ranges(cfg)
    entries, i, blind = [], 0, observation.critic_only(cfg)
    for term in observation.of_config(cfg):
        desc = term.description
        if term.name in blind:
            desc = f"{desc}; the critic's alone in training: the actor read 0 here (scale 0)"
        if term.name == "goal":
            desc = _goal_description(cfg, desc)
        if term.name == "height_map":
            desc = f"{desc}; index = {i} + row * {hm.size} + col"
        entries.append({
            "name": term.name, "start": i, "stop": i + term.size, "unit": term.unit,
            "scale": 0.0 if term.name in blind else term.scale, "clip": clips.get(term.name),
            "description": desc,
            "training_noise": getattr(cfg.noise, term.noise) if term.noise else 0.0})
        i += term.size
    return entries


def _height_map(cfg: EnvConfig) -> dict[str, Any]:
    hm = cfg.height_map
    half = 0.5 * (hm.size - 1) * hm.spacing
    axis = [round(-half + k * hm.spacing, 9) for k in range(hm.size)]
    return {
        "size": [hm.size, hm.size], "spacing_m": hm.spacing, "offset_m": hm.offset,
        "clip_m": hm.clip,
        "frame": "centred on the base position, rotated by the base yaw only (gravity aligned, "
                 "no pitch/roll)",
        "rows": f"y in the yaw frame (left +), from {-half:g} m (row 0) to {half:g} m",
        "cols": f"x in the yaw frame (forward +), from {-half:g} m (col 0) to {half:g} m",
        "x_m": axis, "y_m": axis,
        "point": "world xy of (row, col) = base_xy + Rz(base_yaw) @ (x_m[col], y_m[row])",
        "value": f"base_z - terrain_z - {hm.offset}, clipped to +-{hm.clip} m",
        "sampling": "terrain_z = the highest terrain surface at the point (a vertical ray cast "
                    "down from above everything; the robot itself is not terrain)",
        "missing_value_m": hm.clip,
        "occlusion": None if not hm.occlusion_samples else {
            "samples": hm.occlusion_samples, "sensor_height_m": hm.sensor_height,
            "rule": "a point's terrain_z is raised to the highest terrain z among the samples "
                    "base_xy + (k / samples) * (point_xy - base_xy), k = 1 .. samples - 1, that "
                    "stand above base_z + sensor_height_m (a wall hides what lies behind it); "
                    "the samples are read from the elevation map, bilinear between its cells",
        },
        "missing": "a point without data (no terrain, or the elevation map has no cell there: "
                   "terrain_z NaN) reads missing_value_m (+clip_m)",
    }


def _training(cfg: EnvConfig) -> dict[str, Any]:
    """What the policy was trained to withstand (issue 24), for a runner to compare its robot
    with; none of it changes what the runner computes."""
    r, n, route = cfg.randomization, cfg.noise, cfg.route
    damping = leg_damping(cfg.robot)
    return {
        "joint_damping_nms_rad": list(r.joint_damping) if r.enabled and r.joint_damping
        else [damping, damping],
        "joint_damping_draw": r.joint_damping_draw if r.enabled and r.joint_damping else "fixed",
        "joint_damping_integration": "implicit" if cfg.robot.implicit_damping else "explicit",
        "head_collision": cfg.robot.head_collision,
        "calf_collision": cfg.robot.calf_collision,
        "thigh_collision": cfg.robot.thigh_collision,
        "limb_capsules": cfg.robot.limb_capsules,
        # every contact's solref time constant (robot and stairs); the MJCF's is MuJoCo's default
        "contact_timeconst_s": cfg.robot.contact_timeconst or solref.MJCF_TIMECONST_S,
        "action_delay_s": _delay_range(cfg),
        "pushes": None if not (r.enabled and r.push_interval_s > 0) else {
            "interval_s": r.push_interval_s, "velocity_m_s": r.push_velocity,
            "on_stairs_only": r.push_on_stairs},
        "height_map": None if not n.enabled else {
            "offset_m": n.height_offset, "missing": n.height_missing,
            "missing_under_body": n.height_missing_body, "missing_at_edges": n.height_missing_edge,
            "missing_scaled_per_episode": n.height_missing_per_episode},
        "route": None if route.perturb_prob <= 0 else {
            "perturb_prob": route.perturb_prob, "lateral_fraction_of_width": route.lateral,
            "corner_cut_m": route.corner_cut_m, "coarse_points": list(route.coarse_points)},
    }


def _joints() -> dict[str, Any]:
    ours = list(rb.JOINT_NAMES)
    return {
        "names": ours,
        "nominal_pos_rad": _floats(rb.NOMINAL_JOINT_POS),
        "pos_limits_rad": [_floats(r) for r in rb.JOINT_RANGE],
        "velocity_limit_rad_s": rb.VELOCITY_LIMIT,
        "sdk_names": list(SDK_JOINT_NAMES),
        "sdk_index": [SDK_JOINT_NAMES.index(n) for n in ours],
        "mapping": "policy joint i is Go2 SDK motor sdk_index[i]: joint_pos[i] = "
                   "motor_state[sdk_index[i]].q - nominal_pos_rad[i]; "
                   "motor_cmd[sdk_index[i]].q = q_target[i]",
    }


def _goal(cfg: EnvConfig) -> dict[str, Any]:
    return {
        "mode": cfg.goal_mode,
        "lookahead_m": cfg.waypoint_lookahead_m if cfg.goal_mode == "waypoint" else None,
        "heading": cfg.waypoint_heading,
        "final_goal": "(x, y, z, yaw), world frame: the goal point on the top (or bottom) "
                      "landing and the heading to arrive with",
        "route": "a polyline [K, 3] (x, y, z) in the world frame from the start to the final "
                 "goal (the stair's centre-line; repeated end points allowed)",
        "waypoint": "segments a_i -> b_i of the route's xy; cum = arc length at each point; "
                    "project the base xy on every segment (t clipped to [0, 1]), take the "
                    "nearest (first on ties): arc = cum[i] + t |b_i - a_i|; s = arc + "
                    "lookahead_m; if s >= the route's length the target is the final goal; "
                    "else i = clip(last index with cum[i] <= s, 0, K - 2), the point "
                    "route[i] + clip((s - cum[i]) / (cum[i+1] - cum[i]), 0, 1) (route[i+1] - "
                    "route[i]) (x, y, z), and as its yaw the heading atan2(dy, dx) of segment "
                    "i ('heading' = 'ahead', or absent), of segment k = clip(last index with "
                    "cum[k] <= arc, 0, K - 2), where the base's projection is ('heading' = "
                    "'here'), or of the point minus the projection route[k] + clip((arc - "
                    "cum[k]) / (cum[k+1] - cum[k]), 0, 1) (route[k+1] - route[k]) ('heading' = "
                    "'chord')",
        "used_as": "'final': the observation's goal is the final goal; 'waypoint': it is the "
                   "waypoint, recomputed every control step",
    }


def _evaluation(cfg: EnvConfig) -> dict[str, Any]:
    return {
        "success": "planar distance to the final goal < success_distance_m and planar base "
                   "speed < success_speed_m_s for success_hold_s",
        "success_distance_m": cfg.success_distance, "success_speed_m_s": cfg.success_speed,
        "success_hold_s": cfg.success_hold_s,
        "fall": "the base's z axis tilts more than max_tilt_rad from the world's vertical (with "
                "tilt_slope_m > 0: from the normal of the terrain's slope along the base's "
                "heading, the least-squares line through the terrain height at 9 points spaced "
                "evenly on a tilt_slope_m segment centred under the base), or the base is "
                "lower than min_base_height_m above the terrain under it: the terrain height at "
                "the base's (x, y) when low_line_m is 0, else the mean terrain height at 5 "
                "points spaced evenly on a low_line_m segment centred there along the base's "
                "heading (its x axis projected on the ground)",
        "max_tilt_rad": cfg.max_tilt, "min_base_height_m": cfg.min_base_height,
        "low_line_m": cfg.low_line_m, "tilt_slope_m": cfg.tilt_slope_m,
        "episode_length_s": cfg.episode_length_s,
        "spawn_height_m": cfg.spawn_height, "spawn_margin_m": cfg.spawn_margin,
        "starts": "base at spawn_height_m above the spawn floor, upright, joints at the nominal "
                  "pose, at rest; spawn rectangle shrunk by spawn_margin_m on each side",
    }


def versions() -> dict[str, str | None]:
    """The versions of what made the policy file and its export."""
    out: dict[str, str | None] = {"python": platform.python_version()}
    for pkg in ("mjx_stairs", "jax", "mujoco", "mujoco-mjx", "numpy", "onnx"):
        try:
            out[pkg] = importlib.metadata.version(pkg)
        except importlib.metadata.PackageNotFoundError:
            out[pkg] = None
    return out


def pd_gains(robot: rb.RobotConfig) -> dict[str, float]:
    """The PD gains a robot config trains or runs with, as the sidecar's `pd` names them."""
    return {"kp": robot.kp, "kd": robot.kd, "kd_per_delay_s": robot.kd_per_delay}


def _delay_range(cfg: EnvConfig) -> list[float]:
    r = cfg.randomization
    return (list(r.action_delay_s) if r.enabled and r.action_delay_s[1] > 0
            else [cfg.robot.action_delay_s] * 2)


def sidecar(policy: Policy, onnx_bytes: bytes | None = None) -> dict[str, Any]:
    """What a runner needs beside the graph, as a JSON-serialisable dict.

    Long: one JSON document, section by section.
    """
    cfg = env_config_from(saved_config(policy, "env"))
    layout, hm = policy.layout, cfg.height_map
    n_vec = observation.n_vec_of(cfg)
    if layout.n_vec != n_vec or tuple(layout.map_shape) != (hm.size, hm.size):
        raise SidecarError(
            f"policy layout (vec {layout.n_vec}, map {tuple(layout.map_shape)}) is not the stair "
            f"env's (vec {n_vec}, map {(hm.size, hm.size)})")
    robot = cfg.robot
    dt = robot.timestep * cfg.decimation
    norm = normaliser_constants(policy)
    meta = policy.metadata
    return {
        "format": FORMAT,
        "onnx": {
            "input": {"name": "obs", "shape": ["batch", layout.obs_size], "dtype": "float32",
                      "what": "raw observation, NOT normalised (the graph normalises)"},
            "output": {"name": "action", "shape": ["batch", policy.action_size],
                       "dtype": "float32", "what": "mean action (deterministic)"},
            "opset": OPSET,
            "sha256": hashlib.sha256(onnx_bytes).hexdigest() if onnx_bytes else None,
        },
        "observation": {
            "size": layout.obs_size,
            "layout": _layout(cfg),
            "scales": "every entry is its SI value times its scale (1); the graph's normaliser "
                      "(mean/std from training) does all scaling",
            "noise": (f"the graph adds no noise; training added uniform noise of the given "
                      f"half-widths ({'on' if cfg.noise.enabled else 'off'} in training)"),
            "frames": "base (body) frame: x forward, y left, z up; world z up",
            "history_steps": cfg.obs_history,
            "history": "with history_steps > 0: after building each observation, put its "
                       "joint_pos (before nominal is subtracted: the encoder reading) and its "
                       "last_action in front of the kept histories and drop the oldest; at the "
                       "episode's start both are filled with the reset pose and zeros",
            "action_delay": ("the 'action_delay' term: the robot's own action delay (from "
                             "measuring an observation to its PD target taking effect), "
                             "measured once, times the term's scale; training drew "
                             f"{_delay_range(cfg)} s per robot"
                             + ("; the critic alone read it: its scale is 0, write 0"
                                if not cfg.obs_action_delay_actor else ""))
            if cfg.obs_action_delay else None,
        },
        "normalizer": None if norm is None else {
            "applied_in_graph": True, "clip": norm[2], "std_eps": STD_EPS,
            "formula": "clip((obs - mean) / (std + std_eps), -clip, clip)",
        },
        "height_map": _height_map(cfg),
        "joints": _joints(),
        "action": {
            "size": policy.action_size, "clip": cfg.action_clip, "scale": robot.action_scale,
            "rule": "q_target = nominal_pos + scale * clip(action, -clip, clip); feed the "
                    "clipped action back as last_action",
        },
        "pd": {
            "kp": robot.kp, "kd": robot.kd, "kd_per_delay_s": robot.kd_per_delay,
            "torque_limit_nm": _floats(rb.TORQUE_LIMIT * robot.torque_scale),
            "law": "tau = clip(kp * (q_target - q) - (kd + kd_per_delay_s * delay_s) * qd, "
                   "-torque_limit, torque_limit), evaluated every physics step; delay_s: the "
                   "robot's measured action delay, observation to PD target taking effect",
            "trained": meta.get("pd_trained") or pd_gains(robot),
        },
        "rates": {
            "control_hz": 1.0 / dt, "control_dt_s": dt,
            "physics_dt_s": robot.timestep, "physics_steps_per_action": cfg.decimation,
        },
        "goal": _goal(cfg),
        "base_velocity": "the base (trunk) frame origin's linear velocity, in the base frame "
                         "(training: exact; a robot: its state estimator's)",
        "evaluation": _evaluation(cfg),
        "training": _training(cfg),
        "versions": versions(),
        "policy": {"iteration": meta.get("iteration"), "env_steps": meta.get("env_steps"),
                   "network": meta.get("network"), "config": meta.get("config"),
                   "observation_overrides": meta.get("observation_overrides", []),
                   "pd_overrides": meta.get("pd_overrides", [])},
    }
