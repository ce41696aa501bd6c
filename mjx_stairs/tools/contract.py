"""The robot side of an exported policy: read the ONNX file's JSON sidecar and build the policy's
observation from what a Go2 measures, following the sidecar alone.

Nothing of the training code is imported here (numpy, json, onnxruntime): this module is what a
robot-side program would be, in Python. Measurements come in the sidecar's joint order (see
`Contract.sdk_index` for the Go2 SDK's motor order); the observation is laid out by the
sidecar's table (name -> [start, stop)), not by a layout known in advance.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

FORMAT = "mjx_stairs policy sidecar v2"
TERMS = ("base_lin_vel", "base_ang_vel", "projected_gravity", "joint_pos", "joint_vel",
         "last_action", "goal", "height_map")
"""The observation terms this reader knows how to measure."""
HISTORY_TERMS = ("joint_pos_history", "action_history")
"""The terms of a policy with history (sidecar 'observation.history_steps' > 0): both or none."""
DELAY_TERM = "action_delay"
"""The term of a policy that observes its action delay (Measurement.action_delay_s, times the
term's scale)."""
CRITIC_TERMS = ("joint_damping",)
"""Terms a policy's critic alone read in training (scale 0 in the sidecar): written as 0."""
OPTIONAL_TERMS = (*HISTORY_TERMS, DELAY_TERM, *CRITIC_TERMS)


class ContractError(ValueError):
    """The ONNX file or its sidecar is missing, or they do not fit together."""


@dataclass(frozen=True)
class Contract:
    """The sidecar, parsed. Joint arrays are in `joint_names` order (the policy's)."""

    raw: dict[str, Any]
    obs_size: int
    slices: dict[str, slice]
    noise: np.ndarray  # [obs_size] training noise half-widths
    joint_names: tuple[str, ...]
    sdk_index: np.ndarray  # [12] Go2 SDK motor index of each policy joint
    nominal: np.ndarray  # [12] rad
    kp: float
    kd: float
    kd_per_delay: float  # N m s/rad per s of the robot's action delay, added to kd (pd_torque)
    torque_limit: np.ndarray  # [12] N m
    action_scale: float
    action_clip: float
    control_dt: float
    physics_dt: float
    hm_size: int
    hm_offset: float
    hm_clip: float
    hm_xy: np.ndarray  # [S * S, 2] map points in the yaw frame, row-major (rows = y)
    goal_mode: str
    lookahead: float
    evaluation: dict[str, Any]
    history: int = 0  # policy steps of joint positions and actions the observation keeps
    hm_occlusion: int = 0  # height_map.occlusion.samples (0: none)
    hm_sensor_height: float = 0.0  # m, height_map.occlusion.sensor_height_m
    delay_scale: float | None = None  # the action_delay term's scale (None: not observed)
    heading: str = "ahead"  # the waypoint's yaw: the route's heading at it ("ahead"), at the
    # robot's projection ("here"), or from the projection to the waypoint ("chord")


def sidecar_path(onnx_path: str | os.PathLike) -> Path:
    p = Path(onnx_path)
    return p.with_name(p.name + ".json")


def _need(d: dict, key: str, where: str) -> Any:
    if not isinstance(d, dict) or key not in d:
        raise ContractError(f"{where}: the sidecar has no '{key}'")
    return d[key]


def load_contract(onnx_path: str | os.PathLike) -> Contract:
    """The sidecar of `onnx_path` (`<file>.json`), checked against the ONNX file's bytes.

    Long: one check per field a runner relies on, each a one-line error.
    """
    onnx_path = Path(onnx_path)
    side_path = sidecar_path(onnx_path)
    if not onnx_path.is_file():
        raise ContractError(f"{onnx_path}: no such ONNX file")
    if not side_path.is_file():
        raise ContractError(f"{side_path}: no sidecar beside the ONNX file (mjx-stairs export "
                            "writes it)")
    try:
        raw = json.loads(side_path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise ContractError(f"{side_path}: not JSON ({e})") from None
    w = str(side_path)
    if _need(raw, "format", w) != FORMAT:
        raise ContractError(f"{w}: format {raw['format']!r}, this runner reads {FORMAT!r} "
                            "(export the policy again)")
    sha = _need(_need(raw, "onnx", w), "sha256", w)
    if sha and hashlib.sha256(onnx_path.read_bytes()).hexdigest() != sha:
        raise ContractError(f"{w}: sidecar mismatch: its sha256 is not that of {onnx_path}")
    obs = _need(raw, "observation", w)
    size = int(_need(obs, "size", w))
    slices, noise, at, delay_scale = {}, np.zeros(size), 0, None
    for e in _need(obs, "layout", w):
        if e["name"] not in TERMS + OPTIONAL_TERMS:
            raise ContractError(f"{w}: unknown observation term {e['name']!r}")
        if e["start"] != at:
            raise ContractError(f"{w}: observation term {e['name']!r} starts at {e['start']}, "
                                f"not {at}")
        slices[e["name"]] = slice(e["start"], e["stop"])
        if e["name"] == DELAY_TERM:
            delay_scale = float(e.get("scale", 1.0))
        if e["name"] in CRITIC_TERMS and float(e.get("scale", 1.0)) != 0.0:
            raise ContractError(f"{w}: the {e['name']} term is the critic's alone (scale 0), "
                                f"not {e.get('scale', 1.0)}: this reader cannot measure it")
        noise[e["start"]:e["stop"]] = e.get("training_noise", 0.0)
        at = e["stop"]
    if at != size or set(slices) - set(OPTIONAL_TERMS) != set(TERMS):
        raise ContractError(f"{w}: the observation layout covers {at} of {size} floats with "
                            f"terms {sorted(slices)}")
    hm, joints, pd = _need(raw, "height_map", w), _need(raw, "joints", w), _need(raw, "pd", w)
    act, rates, goal = _need(raw, "action", w), _need(raw, "rates", w), _need(raw, "goal", w)
    n = int(hm["size"][0])
    occlusion = hm.get("occlusion") or {}  # the wall rule; absent or null: none
    gx, gy = np.meshgrid(np.asarray(hm["x_m"]), np.asarray(hm["y_m"]), indexing="xy")
    if slices["height_map"].stop - slices["height_map"].start != n * n:
        raise ContractError(f"{w}: height_map term of the wrong size for a {n} x {n} grid")
    names = tuple(joints["names"])
    if len(names) != slices["joint_pos"].stop - slices["joint_pos"].start:
        raise ContractError(f"{w}: {len(names)} joint names for the joint_pos term")
    sizes = [slices[t].stop - slices[t].start for t in HISTORY_TERMS if t in slices]
    history = int(obs.get("history_steps", 0))
    if sizes != [len(names) * history] * (2 if history else 0):
        raise ContractError(f"{w}: history terms of {sizes} floats for history_steps {history} "
                            f"of {len(names)} joints")
    if DELAY_TERM in slices and slices[DELAY_TERM].stop - slices[DELAY_TERM].start != 1:
        raise ContractError(f"{w}: the {DELAY_TERM} term is one float")
    return Contract(
        raw=raw, obs_size=size, slices=slices, noise=noise, joint_names=names,
        sdk_index=np.asarray(joints["sdk_index"], np.int64),
        nominal=np.asarray(joints["nominal_pos_rad"], np.float64),
        kp=float(pd["kp"]), kd=float(pd["kd"]),
        kd_per_delay=float(pd.get("kd_per_delay_s", 0.0)),  # 0 in sidecars before 2026-11-30
        torque_limit=np.asarray(pd["torque_limit_nm"], np.float64),
        action_scale=float(act["scale"]), action_clip=float(act["clip"]),
        control_dt=float(rates["control_dt_s"]), physics_dt=float(rates["physics_dt_s"]),
        hm_size=n, hm_offset=float(hm["offset_m"]), hm_clip=float(hm["clip_m"]),
        hm_xy=np.stack([gx.ravel(), gy.ravel()], -1), goal_mode=str(goal["mode"]),
        lookahead=float(goal["lookahead_m"] or 0.0), evaluation=dict(raw.get("evaluation", {})),
        history=history, heading=_heading(goal, w),
        delay_scale=delay_scale,
        hm_occlusion=int(occlusion.get("samples", 0)),
        hm_sensor_height=float(occlusion.get("sensor_height_m", 0.0)),
    )


def _heading(goal: dict, where: str) -> str:
    """The goal section's waypoint heading rule ('ahead' where a sidecar predates it)."""
    heading = str(goal.get("heading", "ahead"))
    if heading not in ("ahead", "here", "chord"):
        raise ContractError(f"{where}: goal heading must be 'ahead', 'here' or 'chord', got "
                            f"{heading!r}")
    return heading


# ----------------------------------------------------------------------------- the policy


class OnnxPolicy:
    """The ONNX graph in onnxruntime (one CPU thread): observation [D] -> action [A]."""

    def __init__(self, onnx_path: str | os.PathLike, contract: Contract, threads: int = 1):
        try:
            import onnxruntime as ort
        except ImportError:
            raise ContractError("running the ONNX policy needs onnxruntime: pip install "
                                "'mjx_stairs[export]'") from None
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = opts.inter_op_num_threads = threads
        try:
            self.session = ort.InferenceSession(str(onnx_path), opts,
                                                providers=["CPUExecutionProvider"])
        except Exception as e:  # onnxruntime raises its own kinds on a bad file
            raise ContractError(f"{onnx_path}: onnxruntime cannot load it "
                                f"({str(e).splitlines()[0]})") from None
        (inp,), outs = self.session.get_inputs(), self.session.get_outputs()
        want = contract.raw["onnx"]
        if inp.name != want["input"]["name"] or inp.shape[-1] != contract.obs_size:
            raise ContractError(f"{onnx_path}: sidecar mismatch: the graph takes {inp.name} "
                                f"{inp.shape}, the sidecar says {contract.obs_size} floats")
        self.input, self.output = inp.name, want["output"]["name"]
        if self.output not in [o.name for o in outs]:
            raise ContractError(f"{onnx_path}: sidecar mismatch: no output {self.output!r}")

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        x = np.asarray(obs, np.float32).reshape(1, -1)
        return self.session.run([self.output], {self.input: x})[0][0]


# ----------------------------------------------------------------------------- observation


class Measurement(NamedTuple):
    """What the robot knows at a control step (joint arrays in the sidecar's order)."""

    joint_pos: np.ndarray  # [12] rad, encoders
    joint_vel: np.ndarray  # [12] rad/s, encoders
    ang_vel: np.ndarray  # [3] rad/s, IMU gyro (base frame)
    base_rot: np.ndarray  # [3, 3] base -> world (IMU attitude; gravity direction and yaw)
    base_pos: np.ndarray  # [3] m, world (localisation)
    lin_vel: np.ndarray  # [3] m/s, base frame (state estimate)
    last_action: np.ndarray  # [12] the previous clipped action
    target: np.ndarray  # [4] (x, y, z, yaw) world: the goal the policy is given (goal_target)
    terrain_z: np.ndarray  # [S * S] m, terrain height at map_points
    # with history (Contract.history = H > 0; History keeps them): [H, 12] the encoder readings
    # of the H previous observations and [H, 12] the actions before last_action, newest first
    joint_pos_history: np.ndarray | None = None
    action_history: np.ndarray | None = None
    # s, the robot's measured action delay (observation to PD target taking effect), for a
    # policy that observes it (Contract.delay_scale)
    action_delay_s: float = 0.0


class History:
    """What a runner keeps for a policy with history (the sidecar's 'observation.history'):
    the joint positions and last actions of the `contract.history` previous observations."""

    def __init__(self, c: Contract, joint_pos: np.ndarray):
        """At the episode's start: the reset pose (encoder readings) and no earlier actions."""
        self.clip = c.action_clip
        self.joint_pos = np.tile(np.asarray(joint_pos, np.float64), (c.history, 1))
        self.actions = np.zeros((c.history, len(c.joint_names)))

    def push(self, m: Measurement) -> None:
        """After an observation of `m` went to the policy: its joint_pos and last_action in
        front, the oldest dropped."""
        if len(self.joint_pos):
            self.joint_pos = np.vstack([m.joint_pos, self.joint_pos[:-1]])
            a = np.clip(m.last_action, -self.clip, self.clip)
            self.actions = np.vstack([a, self.actions[:-1]])


def base_yaw(rot: np.ndarray) -> float:
    """Heading of a base -> world rotation: the yaw of its x axis."""
    return float(np.arctan2(rot[1, 0], rot[0, 0]))


def map_points(c: Contract, pos: np.ndarray, yaw: float) -> np.ndarray:
    """[S * S, 2] world xy of the height-map points around base position `pos`."""
    cs, sn = np.cos(yaw), np.sin(yaw)
    x, y = c.hm_xy[:, 0], c.hm_xy[:, 1]
    return np.stack([pos[0] + cs * x - sn * y, pos[1] + sn * x + cs * y], -1)


def occlusion_points(c: Contract, pos: np.ndarray, points: np.ndarray) -> np.ndarray:
    """[P, K - 1, 2] world xy where the sidecar's occlusion rule reads the elevation map: K - 1
    points evenly between the base `pos` and each map point of `points` [P, 2]."""
    s = np.arange(1, c.hm_occlusion, dtype=np.float64)[None, :, None] / c.hm_occlusion
    return pos[:2] + s * (np.asarray(points, np.float64)[:, None, :] - pos[:2])


def occlude(c: Contract, pos: np.ndarray, terrain_z: np.ndarray,
            sample_z: np.ndarray) -> np.ndarray:
    """[P] the map points' terrain_z as the sidecar's occlusion rule has it: raised to the
    highest of their samples' heights `sample_z` [P, K - 1] that stand above the sensor."""
    seen = np.where(sample_z > pos[2] + c.hm_sensor_height, sample_z, -np.inf).max(-1)
    return np.maximum(np.asarray(terrain_z, np.float64), seen)


def wrap(a: float) -> float:
    """An angle wrapped to [-pi, pi)."""
    return float((a + np.pi) % (2 * np.pi) - np.pi)


def goal_target(c: Contract, xy: np.ndarray, final_goal: np.ndarray,
                route: np.ndarray | None) -> np.ndarray:
    """(x, y, z, yaw) the goal input points at: the final goal, or the waypoint on `route`
    [K, 3] by the sidecar's rule (see its 'goal' section)."""
    final_goal = np.asarray(final_goal, np.float64)
    if c.goal_mode == "final" or route is None:
        return final_goal
    line = np.asarray(route, np.float64)
    a, b = line[:-1, :2], line[1:, :2]
    ab = b - a
    seg = np.linalg.norm(ab, axis=-1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    len2 = np.sum(ab * ab, -1)
    t = np.clip(np.sum((xy[:2] - a) * ab, -1) / np.maximum(len2, 1e-12), 0.0, 1.0)
    i = int(np.argmin(np.linalg.norm(xy[:2] - (a + t[:, None] * ab), axis=-1)))
    arc = cum[i] + t[i] * np.sqrt(len2[i])
    s = arc + c.lookahead
    if s >= cum[-1]:
        return final_goal
    j = int(np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(cum) - 2))
    f = np.clip((s - cum[j]) / max(cum[j + 1] - cum[j], 1e-6), 0.0, 1.0)
    d = line[j + 1] - line[j]
    point = line[j] + f * d
    heading = getattr(c, "heading", "ahead")
    if heading == "here":  # the segment the robot's projection is on (the env's index rule)
        k = int(np.clip(np.searchsorted(cum, arc, side="right") - 1, 0, len(cum) - 2))
        d = line[k + 1] - line[k]
    elif heading == "chord":  # from the projection itself to the point
        d = point[:2] - (a[i] + t[i] * ab[i])
    return np.concatenate([point, [np.arctan2(d[1], d[0])]])


def observation(c: Contract, m: Measurement) -> np.ndarray:
    """[obs_size] float32 raw observation, laid out by the sidecar."""
    rot = np.asarray(m.base_rot, np.float64)
    pos = np.asarray(m.base_pos, np.float64)
    target = np.asarray(m.target, np.float64)
    height = pos[2] - np.asarray(m.terrain_z, np.float64) - c.hm_offset
    values = {
        "base_lin_vel": m.lin_vel,
        "base_ang_vel": m.ang_vel,
        "projected_gravity": rot.T @ np.array([0.0, 0.0, -1.0]),
        "joint_pos": np.asarray(m.joint_pos) - c.nominal,
        "joint_vel": m.joint_vel,
        "last_action": np.clip(m.last_action, -c.action_clip, c.action_clip),
        "goal": np.concatenate([rot.T @ (target[:3] - pos), [wrap(target[3] - base_yaw(rot))]]),
        "height_map": np.clip(np.nan_to_num(height, nan=c.hm_clip, posinf=c.hm_clip),
                              -c.hm_clip, c.hm_clip),
    }
    if c.history:
        if m.joint_pos_history is None or m.action_history is None:
            raise ContractError(f"the policy observes {c.history} steps of history: the "
                                "measurement needs joint_pos_history and action_history (History)")
        values["joint_pos_history"] = (np.asarray(m.joint_pos_history) - c.nominal).ravel()
        values["action_history"] = np.clip(m.action_history, -c.action_clip,
                                           c.action_clip).ravel()
    if c.delay_scale is not None:
        values[DELAY_TERM] = [c.delay_scale * m.action_delay_s]
    values.update({t: [0.0] for t in CRITIC_TERMS if t in c.slices})
    out = np.zeros(c.obs_size, np.float64)
    for name, sl in c.slices.items():
        out[sl] = values[name]
    return out.astype(np.float32)


def action_to_target(c: Contract, action: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(clipped action [12], PD target [12] rad) of a policy output."""
    a = np.clip(np.asarray(action, np.float64), -c.action_clip, c.action_clip)
    return a, c.nominal + c.action_scale * a


def pd_torque(c: Contract, q_target: np.ndarray, q: np.ndarray, qd: np.ndarray,
              delay_s: float = 0.0) -> np.ndarray:
    """[12] N m: clip(kp (q* - q) - (kd + kd_per_delay delay_s) qd, -limit, limit), the
    sidecar's PD law at the robot's measured action delay `delay_s`."""
    kd = c.kd + c.kd_per_delay * delay_s
    return np.clip(c.kp * (q_target - q) - kd * qd, -c.torque_limit, c.torque_limit)


def to_sdk(c: Contract, x: np.ndarray) -> np.ndarray:
    """[12] policy-order values -> the Go2 SDK's motor order."""
    out = np.empty_like(np.asarray(x))
    out[c.sdk_index] = x
    return out


def from_sdk(c: Contract, x: np.ndarray) -> np.ndarray:
    """[12] values in the Go2 SDK's motor order -> policy order."""
    return np.asarray(x)[c.sdk_index]
