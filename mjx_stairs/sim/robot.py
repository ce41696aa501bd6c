"""The Unitree Go2 on MJX: build the MuJoCo model with a terrain heightfield, put it on the device.

The MJCF (assets/go2.xml) is our own, written from shared/reference/go2.md. This module attaches
the atlas heightfield, applies the solver and collision settings of a `RobotConfig`, and exposes
the ids and constants the env needs (joint order, collision geoms, nominal pose, limits).

Frames: x forward, y left, z up. The heightfield grid `heights[iy, ix]` is the terrain height at
world (ix * res, iy * res): the atlas corner point is the world origin.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, Literal

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx

from mjx_stairs.config import ConfigError
from mjx_stairs.sim import capsule, contact, solref  # they register our colliders
from mjx_stairs.sim.geoms import HEAD, add_capsules, add_chains, add_head, chain_ids

ASSET = Path(__file__).parent / "assets" / "go2.xml"

LEGS = ("FL", "FR", "RL", "RR")
JOINT_NAMES = tuple(f"{leg}_{part}_joint" for leg in LEGS for part in ("hip", "thigh", "calf"))
"""Joint order of actions, observations and actuators: FL, FR, RL, RR x (hip, thigh, calf)."""

NOMINAL_JOINT_POS = np.array(
    [0.1, 0.8, -1.5, -0.1, 0.8, -1.5, 0.1, 1.0, -1.5, -0.1, 1.0, -1.5], np.float32
)
"""[12] standing pose (rad), reference table."""

_HIP = (-1.0472, 1.0472)
_FRONT_THIGH = (-1.5708, 3.4907)
_REAR_THIGH = (-0.5236, 4.5379)
_CALF = (-2.7227, -0.83776)
JOINT_RANGE = np.array([_HIP, _FRONT_THIGH, _CALF] * 2 + [_HIP, _REAR_THIGH, _CALF] * 2, np.float32)
"""[12, 2] joint position limits (rad), reference table."""

TORQUE_LIMIT = np.array([23.7, 23.7, 45.43] * 4, np.float32)
"""[12] motor torque limits (N m): hip and thigh 23.7, calf 45.43."""

VELOCITY_LIMIT = 30.0
"""Joint velocity limit (rad/s), reference table."""

JOINT_DAMPING = 0.1
"""Passive damping of every leg joint in assets/go2.xml (N m s/rad); the Go2 description has 2."""

NOMINAL_BASE_HEIGHT = 0.30
"""Approximate base height above flat ground in the nominal pose (m)."""
SPHERE_GROUPS = {
    "foot": tuple(f"{leg}_foot" for leg in LEGS),
    "knee": tuple(f"{leg}_knee" for leg in LEGS),
    "shin": tuple(f"{leg}_shin" for leg in LEGS),
    "trunk": ("trunk_fl", "trunk_fr", "trunk_rl", "trunk_rr"),
}
"""Collision sphere groups by geom name suffix."""


@dataclasses.dataclass(frozen=True)
class RobotConfig:
    """Robot, actuation and solver settings."""

    kp: float = 35.0  # PD stiffness (N m / rad), the paper's "stiff" variant
    kd: float = 1.0  # PD damping (N m s / rad)
    # N m s/rad per s of the robot's action delay: the PD's damping scheduled by the measured
    # latency, kd + kd_per_delay * delay (75: 1.0 at no delay, 2.5 at 20 ms; docs/deploy.md)
    kd_per_delay: float = 0.0
    torque_scale: float = 1.0  # multiplies the reference torque limits of the PD (only) clamp
    action_scale: float = 0.5  # q_target = q_nominal + action_scale * action
    timestep: float = 0.005  # physics step (s)
    solver_iterations: int = 1  # Newton iterations per physics step
    ls_iterations: int = 5  # line-search iterations per Newton iteration
    shin_collision: bool = True  # collide the mid-shin spheres with the terrain
    # Sphere-terrain collider: "mjx" (MJX's prism collider, 4 contacts per sphere), "nearest"
    # (sim.contact: the exact nearest surface point, 2 per sphere) or "columns" (the same, against
    # flat-topped columns with vertical risers: the CPU ground truth's terrains.boxes).
    terrain_contacts: Literal["mjx", "nearest", "columns"] = "mjx"
    # "columns" only: a sphere centre inside a column leaves through its top ("top", as published to
    # 2026-11-24) or its nearest exposed face ("nearest", as MuJoCo's boxes push it: a foot driven
    # into a riser goes back out of it; the evaluation physics since issue 19 settled it).
    sunk_exit: Literal["top", "nearest"] = "top"
    friction: float = 0.8  # foot-terrain sliding friction
    # N m s/rad on every leg joint (None: the MJCF's JOINT_DAMPING); e.g. evaluating at the Go2
    # description's 2: --env robot.joint_damping=2 (env.randomization.joint_damping draws it)
    joint_damping: float | None = None
    # Joints' passive damping integrated implicitly (MuJoCo's default `eulerdamp`; here the same
    # step as implicitfast), not explicitly (go2.xml's eulerdamp="disable"): at damping 2 the
    # explicit step damps a calf 60 % per 5 ms step where the implicit one damps 38 %.
    implicit_damping: bool = False
    # A collision sphere on the head (HEAD), a trunk sphere (trunk-contact ending, collision
    # penalty). Off: go2.xml's spheres alone, as every policy up to 2026-11-26 trained.
    head_collision: bool = False
    # Eleven spheres more along each calf (go2_full.xml's bowed calf: geoms.CALF_SHAPE), counted
    # as calf contacts. Off: go2.xml's spheres alone, as every policy up to 2026-11-29 trained.
    calf_collision: bool = False
    # Nine spheres along each thigh (go2_full.xml's thigh capsule: geoms.THIGH_SHAPE), counted as
    # knee contacts (rewards.contact_trunk_thigh). Off: as every policy up to 2026-12-01 trained.
    thigh_collision: bool = False
    # The calves and thighs those two add as go2_full.xml's capsules, collided by sim.capsule (two
    # contacts a capsule), not as sphere chains (two a sphere): the same shape, fewer solver rows.
    limb_capsules: bool = False
    # Fixed action delay (s) in whole physics steps (the previous target holds), at most one policy
    # step, as sim2sim's --latency-ms (`--env robot.action_delay_s=0.02`; or drawn per robot).
    action_delay_s: float = 0.0
    # s: every geom's contact solref time constant in MJX and the ground truth's box world (0:
    # MuJoCo's 0.02, as sim2sim keeps); the evaluation physics's 0.01 (PHYSICS).
    contact_timeconst: float = 0.0

    @property
    def action_delay_steps(self) -> int:
        """`action_delay_s` in whole physics steps."""
        return int(round(self.action_delay_s / self.timestep))

    def kd_at(self, delay_s):
        """The PD's damping at an action delay of `delay_s` s (kd_per_delay; arrays too)."""
        return self.kd + self.kd_per_delay * delay_s

    @property
    def delayed_kd(self) -> float:
        """`kd_at` the fixed `action_delay_s`, in whole physics steps."""
        return self.kd_at(self.action_delay_steps * self.timestep)

    def __post_init__(self):
        if self.sunk_exit not in ("top", "nearest"):
            raise ConfigError("config key 'env.robot.sunk_exit': must be 'top' or 'nearest', got "
                              f"{self.sunk_exit!r}")
        if self.joint_damping is not None and not self.joint_damping >= 0:
            raise ConfigError("config key 'env.robot.joint_damping': must be >= 0 or none, got "
                              f"{self.joint_damping}")
        if not (self.kd >= 0 and self.kd_per_delay >= 0):
            raise ConfigError("config keys 'env.robot.kd', 'env.robot.kd_per_delay': must be >= 0,"
                              f" got {self.kd}, {self.kd_per_delay}")
        if self.contact_timeconst and not self.contact_timeconst >= 2 * self.timestep:
            raise ConfigError("config key 'env.robot.contact_timeconst': must be 0 or at least "
                              f"twice robot.timestep, got {self.contact_timeconst}")


IMPLICIT_MIN_ITERATIONS = 3  # for implicit_damping: fewer run the joints away (results.md 8f)
PHYSICS = {
    "reference": {"terrain_contacts": "mjx", "shin_collision": True, "solver_iterations": 1,
                  "ls_iterations": 5},
    "lean": {"terrain_contacts": "nearest", "shin_collision": False, "solver_iterations": 1,
             "ls_iterations": 3},
    "evaluation": {"terrain_contacts": "columns", "shin_collision": True, "solver_iterations": 8,
                   "ls_iterations": 10, "sunk_exit": "nearest", "timestep": 0.005,
                   "contact_timeconst": 0.01},
    "evaluation_top": {"terrain_contacts": "columns", "shin_collision": True,
                       "solver_iterations": 8, "ls_iterations": 10, "sunk_exit": "top",
                       "timestep": 0.005},
}
"""Physics presets, named by ``robot.physics = "..."`` in a config table or an override; each
sets the collider, shin and solver fields (the evaluation presets also ``sunk_exit``), so a
preset means the same whatever came before it.
"reference": MJX's heightfield collider, shin spheres, 1 Newton iteration with 5 line-search
steps (the defaults above; what the published tables up to issue 19 were measured in);
"lean": the fast training physics of issue 7 (no mid-shin spheres, 3 line-search steps, the
nearest-point collider);
"lean_implicit": lean with 4 Newton iterations, for `implicit_damping` (IMPLICIT_MIN_ITERATIONS);
"evaluation": the physics every policy is judged in (issue 19): the grid as columns with
vertical risers (the CPU MuJoCo ground truth's geometry, `sim.contact.sphere_columns`), shin
spheres, the solver run near convergence (8 Newton iterations, 10 line-search steps), a sphere
centre sunk into a column pushed out through the column's nearest exposed face, a 5 ms physics
step (an evaluation keeps the policy's control period: `study.evaluate.eval_env`) and every
contact's solref time constant at 0.01 s (go2.xml's is MuJoCo's 0.02). Against CPU MuJoCo on box
stairs at the same contact: within 3 points on every cell of
experiments/results/ground_truth/table_stiff.md (2026-11-28);
"evaluation_soft": the same at go2.xml's 0.02 s, the evaluation physics 2026-11-25 to 11-28 (up
to 3.8 points off on the stage-2 cells, 6-31 on the generalists' spiral ones);
"evaluation_top": the evaluation physics as published to 2026-11-24, the sunk centre pushed out
through the column's top (up to 8.7 points optimistic on the U-turn at 14-16 cm risers); the
physics the committed stage2_u_paper* runs and the first generalists trained in."""
PHYSICS["lean_implicit"] = {**PHYSICS["lean"], "solver_iterations": 4}
PHYSICS["evaluation_soft"] = {**PHYSICS["evaluation"], "contact_timeconst": 0.0}


def expand_physics_in(table: dict[str, Any], key: str = "robot") -> dict[str, Any]:
    """A copy of ``table`` in which ``table[key]["physics"]``, if present, is replaced by the
    fields its preset sets (they win over the same fields beside it)."""
    robot = table.get(key)
    if not isinstance(robot, dict) or "physics" not in robot:
        return table
    robot = dict(robot)
    name = robot.pop("physics")
    if name not in PHYSICS:
        raise ConfigError(f"config key '{key}.physics': expected one of {list(PHYSICS)}, "
                          f"got {name!r}")
    return {**table, key: {**robot, **PHYSICS[name]}}


@dataclasses.dataclass(frozen=True)
class RobotIds:
    """Indices into the MuJoCo model, looked up once at build time."""

    base_body: int
    hfield_geom: int
    foot_geoms: np.ndarray  # [4] FL, FR, RL, RR
    knee_geoms: np.ndarray  # [4]
    shin_geoms: np.ndarray  # [4]
    trunk_geoms: np.ndarray  # [4] corners (+ the head with head_collision: [5])
    calf_geoms: np.ndarray  # [4, k] each leg's calf chain (k = 11; 2 capsules), else k = 0
    thigh_geoms: np.ndarray  # [4, k] each leg's thigh chain (k = 9; 1 capsule), else k = 0
    qpos_joints: np.ndarray  # [12] qpos addresses of the joints, in JOINT_NAMES order
    qvel_joints: np.ndarray  # [12] qvel addresses of the joints


@dataclasses.dataclass(frozen=True)
class Robot:
    """A built robot + terrain: the MuJoCo model, its MJX copy and the ids."""

    mj_model: mujoco.MjModel
    mjx_model: mjx.Model
    ids: RobotIds
    config: RobotConfig


def build_mj_model(heights: np.ndarray | None, resolution: float,
                   config: RobotConfig = RobotConfig()) -> mujoco.MjModel:
    """Compile the Go2 with a terrain heightfield.

    Args:
      heights: [ny, nx] terrain heights (m) at world (ix * res, iy * res); None for a 20 m x 20 m
        flat floor.
      resolution: grid spacing (m).
      config: robot and solver settings.

    Long: one MjSpec edit per setting, in the order MuJoCo needs them.
    """
    spec = mujoco.MjSpec.from_file(str(ASSET))
    spec.option.timestep = config.timestep
    spec.option.iterations = config.solver_iterations
    spec.option.ls_iterations = config.ls_iterations
    if heights is None:
        resolution = 0.5
        heights = np.zeros((41, 41), np.float32)
    heights = np.asarray(heights, np.float32)
    if heights.ndim != 2 or min(heights.shape) < 2:
        raise ValueError(f"heights must be a 2-D grid of at least 2 x 2, got shape {heights.shape}")
    if not np.all(np.isfinite(heights)):
        raise ValueError("heights contain NaN or infinite values")
    columns = config.terrain_contacts == "columns"
    name = contact.COLUMNS_EXIT_HFIELD if config.sunk_exit == "nearest" else contact.COLUMNS_HFIELD
    add_heightfield(spec, heights, resolution, config.friction,
                    hfield_name=name if columns else "terrain")
    apply_robot_settings(spec, config)
    if config.terrain_contacts in ("nearest", "columns"):
        # The same spheres as ellipsoids with equal radii: MJX then collides them with the
        # terrain through mjx_stairs.sim.contact (registered for heightfield-ellipsoid pairs;
        # the heightfield's asset name picks the surface or the columns).
        # Every sphere of the robot is a collision sphere (SPHERE_GROUPS, and the head).
        for geom in spec.geoms:
            if geom.type == mujoco.mjtGeom.mjGEOM_SPHERE:
                geom.type = mujoco.mjtGeom.mjGEOM_ELLIPSOID
                geom.size = [geom.size[0]] * 3
    elif config.terrain_contacts != "mjx":
        raise ValueError("robot.terrain_contacts must be 'mjx', 'nearest' or 'columns', got "
                         f"{config.terrain_contacts!r}")
    model = spec.compile()
    capsule.check(model)
    return model


def apply_robot_settings(spec: mujoco.MjSpec, config: RobotConfig) -> None:
    """`config`'s robot settings on go2.xml's spec, for MJX's model and the box world alike."""
    for name in SPHERE_GROUPS["foot"]:
        spec.geom(name).friction = [config.friction, 0.02, 0.01]
    set_joint_damping(spec, config)
    if config.head_collision:
        add_head(spec)
    add = add_capsules if config.limb_capsules else add_chains
    if config.calf_collision:
        add(spec, LEGS, "calf", "{leg}_shin")
    if config.thigh_collision:
        add(spec, LEGS, "thigh", "{leg}_knee")
    solref.set_timeconst(spec, config.contact_timeconst)
    for act in spec.actuators:  # the PD's clamp (pd_torque: torque_scale, motor_strength) is
        act.ctrllimited = False  # the only one; go2.xml's ctrlrange would cap it at 1x
    if not config.shin_collision:
        for name in SPHERE_GROUPS["shin"]:
            spec.geom(name).contype = 0


def set_joint_damping(spec: mujoco.MjSpec, config: RobotConfig) -> None:
    """Every leg joint's passive damping to `config.joint_damping` (None: leave the MJCF's),
    integrated implicitly when `config.implicit_damping`."""
    if config.joint_damping is not None:
        for name in JOINT_NAMES:
            spec.joint(name).damping = [config.joint_damping, 0.0, 0.0]
    if config.implicit_damping:
        spec.option.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_EULERDAMP)


def add_heightfield(spec: mujoco.MjSpec, heights: np.ndarray, resolution: float,
                    friction: float, hfield_name: str = "terrain") -> None:
    """Add the terrain heightfield `heights` [ny, nx] (at world (ix * res, iy * res)) to `spec`."""
    ny, nx = heights.shape
    lo, hi = float(heights.min()), float(heights.max())
    span = hi - lo
    data = (heights - lo) / span if span > 0 else np.zeros_like(heights)
    rx, ry = 0.5 * (nx - 1) * resolution, 0.5 * (ny - 1) * resolution
    spec.add_hfield(name=hfield_name, nrow=ny, ncol=nx, size=[rx, ry, max(span, 1e-3), 0.5],
                    userdata=data.ravel().tolist())
    spec.worldbody.add_geom(name="terrain", type=mujoco.mjtGeom.mjGEOM_HFIELD,
                            hfieldname=hfield_name, pos=[rx, ry, lo], contype=0, conaffinity=1,
                            material="terrain", friction=[friction, 0.02, 0.01])


def robot_ids(model: mujoco.MjModel) -> RobotIds:
    """Look up the ids the env needs."""

    head = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, HEAD[0])

    def geoms(group: str) -> np.ndarray:
        ids = [model.geom(n).id for n in SPHERE_GROUPS[group]]
        return np.array(ids + ([head] if group == "trunk" and head >= 0 else []), np.int32)

    joints = [model.joint(n) for n in JOINT_NAMES]
    return RobotIds(
        base_body=model.body("base").id,
        hfield_geom=model.geom("terrain").id,
        foot_geoms=geoms("foot"),
        knee_geoms=geoms("knee"),
        shin_geoms=geoms("shin"),
        trunk_geoms=geoms("trunk"),
        calf_geoms=chain_ids(model, LEGS, "calf"),
        thigh_geoms=chain_ids(model, LEGS, "thigh"),
        qpos_joints=np.array([int(j.qposadr[0]) for j in joints], np.int32),
        qvel_joints=np.array([int(j.dofadr[0]) for j in joints], np.int32),
    )


def build(
    heights: np.ndarray | None, resolution: float, config: RobotConfig = RobotConfig()
) -> Robot:
    """Build the MuJoCo model with the terrain and put it on this process's first device (MJX's
    default, ``jax.devices()[0]``, is process 0's device in a multi-process run, which the
    other processes cannot address)."""
    mj_model = build_mj_model(heights, resolution, config)
    mx = mjx.put_model(mj_model, device=jax.local_devices()[0])
    return Robot(mj_model, mx, robot_ids(mj_model), config)


def pd_torque(
    q_target: jnp.ndarray,
    q: jnp.ndarray,
    qd: jnp.ndarray,
    kp: jnp.ndarray | float,
    kd: jnp.ndarray | float,
    limit: jnp.ndarray,
) -> jnp.ndarray:
    """Joint-position PD with a torque clamp: clip(kp (q* - q) - kd qd, -limit, limit). [..., 12]"""
    return jnp.clip(kp * (q_target - q) - kd * qd, -limit, limit)


def standing_qpos(xy: tuple[float, float] = (0.0, 0.0), z: float = 0.445) -> np.ndarray:
    """[19] qpos of the robot at (x, y, z), upright, facing +x, joints in the nominal pose."""
    qpos = np.zeros(19, np.float32)
    qpos[0:3] = (xy[0], xy[1], z)
    qpos[3] = 1.0
    qpos[7:] = NOMINAL_JOINT_POS
    return qpos
