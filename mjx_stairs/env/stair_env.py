"""The stair-climbing env on MJX, behind brax's Env/State interface.

One robot per call (the trainer vmaps over robots). `reset` and `step` are pure and jittable. The
env auto-resets inside `step`, because the curriculum picks the next tile when an episode ends:
the returned state already holds the new episode, `state.info["final_obs"]` the observation
before the reset and `state.info["truncation"]` whether the episode ended by timeout.

Observation, both streams [49 + 441]:
  base linear velocity (3, body frame), base angular velocity (3, body frame), gravity in the body
  frame (3), joint positions minus the nominal pose (12), joint velocities (12), last action (12),
  goal (x, y, z in the body frame; yaw error) (4), then the 21 x 21 height map (row-major, rows
  along the base's y, columns along its x; value = base z - terrain z - 0.4, clipped to +-3 m).
`obs["state"]` (actor) carries uniform noise per group; `obs["privileged_state"]` (critic) is the
same without noise.

Where ours differs from the authors' Isaac Lab setup:
- The height map is sampled bilinearly from the atlas heightfield on the device instead of ray
  casting (mjx.ray does not see heightfields); for our own terrain it is exact.
- Everything is computed from qpos/qvel, so a reset needs no extra forward pass.
- The contact penalties read MJX contacts of our collision spheres: trunk corners stand for
  base/head, knee spheres for thighs, mid-shin spheres for calves.
- Regularisers are always on (the authors switch most on once the curriculum's top level is
  reached; a cross-robot gate does not fit a per-robot env).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from brax.envs.base import Env, State
from mujoco import mjx
from mujoco.mjx._src import collision_driver

from mjx_stairs.env import curriculum as cur
from mjx_stairs.env import rewards as rw
from mjx_stairs.sim import robot as rb

N_VEC = 49
"""Length of the vector part of an observation (before the height map)."""

STEP_INPUTS = ("qpos", "qvel", "qacc_warmstart", "ctrl", "time")
"""The fields of mjx.Data a physics step starts from: MJX recomputes every other field
(kinematics, contacts, constraint rows) from these (the Go2 model has no actuator activations).
The NaN guard restores these, and `pack_state` keeps these."""


@dataclasses.dataclass(frozen=True)
class NoiseConfig:
    """Uniform observation noise half-widths per group (actor stream only)."""

    enabled: bool = True
    lin_vel: float = 0.1
    ang_vel: float = 0.2
    gravity: float = 0.05
    joint_pos: float = 0.01
    joint_vel: float = 1.5
    height: float = 0.1


@dataclasses.dataclass(frozen=True)
class HeightMapConfig:
    """The local height map."""

    size: int = 21  # points per side
    spacing: float = 0.2  # m between points (21 x 0.2 -> 4 m x 4 m)
    offset: float = 0.4  # subtracted from base z - terrain z
    clip: float = 3.0  # |value| clip (m)


@dataclasses.dataclass(frozen=True)
class RandomizationConfig:
    """Domain randomisation, per robot, resampled at every reset (off in evaluation)."""

    enabled: bool = True
    friction: tuple[float, float] = (0.4, 1.2)
    added_mass: tuple[float, float] = (-1.0, 2.0)  # kg on the trunk
    com_shift: float = 0.03  # m, uniform +- on the trunk CoM in x, y, z
    motor_strength: tuple[float, float] = (0.9, 1.1)  # scales the torque per joint
    kp_scale: tuple[float, float] = (0.9, 1.1)
    kd_scale: tuple[float, float] = (0.9, 1.1)
    push_interval_s: float = 8.0  # a push every this many seconds (0: never)
    push_velocity: float = 0.5  # m/s, uniform +- added to the base xy velocity


GOAL_MODES = ("final", "waypoint")


@dataclasses.dataclass(frozen=True)
class EnvConfig:
    """The stair env."""

    robot: rb.RobotConfig = rb.RobotConfig()
    rewards: rw.RewardConfig = rw.STAGE1
    curriculum: cur.CurriculumConfig = cur.CurriculumConfig()
    noise: NoiseConfig = NoiseConfig()
    height_map: HeightMapConfig = HeightMapConfig()
    randomization: RandomizationConfig = RandomizationConfig()
    decimation: int = 4  # physics steps per policy step (0.005 s x 4 -> 50 Hz)
    episode_length_s: float = 10.0
    action_clip: float = 5.0  # |action| clip before scaling
    max_tilt: float = 1.0  # rad; tilting further ends the episode
    min_base_height: float = 0.12  # m above the terrain under the base; lower ends the episode
    terminate_on_trunk_contact: bool = True  # training only; off in evaluation
    spawn_height: float = 0.36  # base height above the spawn floor at reset (m)
    spawn_margin: float = 0.15  # m taken off each side of a tile's spawn rectangle: a Go2 turned
    # 45 deg reaches ~0.45 m from its centre, more than the terrain's 0.35 m wall clearance
    joint_noise_at_reset: float = 0.1  # rad, uniform +- around the nominal pose (0 in evaluation)
    success_distance: float = 0.5  # planar m
    success_speed: float = 0.3  # m/s
    success_hold_s: float = 0.5  # s the success condition must hold
    # What the goal observation points at. "final": the tile's goal (the paper's). "waypoint":
    # a point `waypoint_lookahead_m` further along the stair's centre-line than the robot's own
    # projection on it, with the centre-line's heading there; the final goal (and its yaw) once
    # the goal is closer along the line than the lookahead. Ours, not the paper's: a building's
    # stair centre-line is known from its map, and a goal behind the wall of a U-turn otherwise
    # pulls a stage-1 policy straight into the wall. Rewards, success and the curriculum always
    # use the final goal.
    goal_mode: str = "final"
    waypoint_lookahead_m: float = 1.0


def evaluation_config(config: EnvConfig, episode_length_s: float | None = None) -> EnvConfig:
    """The same env for evaluation: no noise, no randomisation, no trunk ending, no curriculum."""
    return dataclasses.replace(
        config,
        noise=dataclasses.replace(config.noise, enabled=False),
        randomization=dataclasses.replace(config.randomization, enabled=False),
        curriculum=dataclasses.replace(config.curriculum, enabled=False),
        terminate_on_trunk_contact=False,
        joint_noise_at_reset=0.0,
        episode_length_s=episode_length_s or config.episode_length_s,
    )


# ----------------------------------------------------------------------------- geometry helpers


def quat_to_mat(q: jnp.ndarray) -> jnp.ndarray:
    """[4] (w, x, y, z) -> [3, 3] rotation matrix (body -> world)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    return jnp.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def yaw_quat(yaw: jnp.ndarray) -> jnp.ndarray:
    """[4] quaternion of a rotation by `yaw` about z."""
    return jnp.array([jnp.cos(yaw / 2), 0.0, 0.0, jnp.sin(yaw / 2)])


def wrap_angle(a: jnp.ndarray) -> jnp.ndarray:
    """Wrap to [-pi, pi)."""
    return (a + jnp.pi) % (2 * jnp.pi) - jnp.pi


def sample_heights(
    grid: jnp.ndarray, shape: tuple[int, int], resolution: float, x: jnp.ndarray, y: jnp.ndarray
) -> jnp.ndarray:
    """Bilinear terrain height at world (x, y), clamped to the grid's edge.

    Args:
      grid: [ny * nx] heights, row-major: grid[iy * nx + ix] at world (ix * res, iy * res).
      shape: (ny, nx), static.
      x, y: [...] world coordinates.
    Returns: [...] heights.
    """
    ny, nx = shape
    fx = jnp.clip(x / resolution, 0.0, nx - 1.0)
    fy = jnp.clip(y / resolution, 0.0, ny - 1.0)
    ix = jnp.clip(jnp.floor(fx).astype(jnp.int32), 0, nx - 2)
    iy = jnp.clip(jnp.floor(fy).astype(jnp.int32), 0, ny - 2)
    tx, ty = fx - ix, fy - iy
    i00 = iy * nx + ix
    h00, h01 = grid[i00], grid[i00 + 1]
    h10, h11 = grid[i00 + nx], grid[i00 + nx + 1]
    return (h00 * (1 - tx) + h01 * tx) * (1 - ty) + (h10 * (1 - tx) + h11 * tx) * ty


# ----------------------------------------------------------------------------- the env


class StairEnv(Env):
    """Go2 climbing the stairs of an atlas. See the module docstring for the observation."""

    def __init__(self, atlas: Any, config: EnvConfig = EnvConfig()):
        """Build the model with the atlas heightfield and the per-tile tables on the device.

        Args:
          atlas: a terrains.Atlas (heights, resolution, rows, cols, families and per-tile tables).
          config: env settings.
        """
        if config.goal_mode not in GOAL_MODES:
            raise ValueError(
                f"env.goal_mode: unknown mode {config.goal_mode!r} (known: {list(GOAL_MODES)})"
            )
        if not config.waypoint_lookahead_m > 0:
            raise ValueError(
                f"env.waypoint_lookahead_m: must be > 0, got {config.waypoint_lookahead_m}"
            )
        self.config = config
        self.atlas_shape = tuple(int(s) for s in atlas.heights.shape)
        self.resolution = float(atlas.resolution)
        self.num_levels = int(atlas.rows)
        self.families = tuple(atlas.families)
        self.robot = rb.build(atlas.heights, self.resolution, config.robot)
        self._mx = self.robot.mjx_model
        if self._mx.na:
            raise ValueError(f"the robot model has {self._mx.na} actuator activations; the NaN "
                             "guard and pack_state keep only STEP_INPUTS")
        ids = self.robot.ids
        self._ids = ids
        mj = self.robot.mj_model
        # Terrain height = lo + span * hfield_data (the data MuJoCo keeps is normalised).
        self._h_lo = float(mj.geom_pos[ids.hfield_geom][2])
        self._h_span = float(mj.hfield_size[0][2])
        self._world_size = (
            (self.atlas_shape[1] - 1) * self.resolution,
            (self.atlas_shape[0] - 1) * self.resolution,
        )

        # Per-tile tables.
        self._spawn = jnp.asarray(atlas.spawn, jnp.float32)  # [n, 7]
        self._goal = jnp.asarray(atlas.goal, jnp.float32)  # [n, 4]
        line3 = np.asarray(atlas.centreline, np.float32)  # [n, K, 3]
        seg = np.linalg.norm(np.diff(line3[..., :2], axis=1), axis=-1)
        cumulative = np.concatenate([np.zeros_like(seg[:, :1]), np.cumsum(seg, axis=1)], axis=1)
        self._line3 = jnp.asarray(line3)  # waypoints take their z from it
        self._line = self._line3[..., :2]
        self._line_cum = jnp.asarray(cumulative, jnp.float32)  # [n, K]
        self._line_len = jnp.asarray(cumulative[:, -1], jnp.float32)  # [n]
        self.tile_origin = np.asarray(atlas.origin, np.float32)  # [n, 2] host copy
        # The height map reads only the robot's own tile: [n, 2] the world xy of its first and
        # last grid point. What lies past a tile's edge in an atlas (a neighbour's floor behind
        # a thin wall, a border) is no part of that staircase.
        extent = (int(round(atlas.tile_size / self.resolution)) - 1) * self.resolution
        self._tile_lo = jnp.asarray(self.tile_origin)
        self._tile_hi = jnp.asarray(self.tile_origin + np.float32(extent))
        self._tile_level = jnp.asarray(atlas.level, jnp.int32)
        self._tile_family = jnp.asarray(atlas.family, jnp.int32)
        self._table = cur.TileTable(np.asarray(atlas.family), int(atlas.cols), len(self.families))

        # Contacts: which rows of MJX's contact array belong to which robot sphere.
        self._contact_rows = _sphere_contact_rows(mj, ids)

        # Constants.
        hm = config.height_map
        half = 0.5 * (hm.size - 1) * hm.spacing
        gx, gy = np.meshgrid(
            np.linspace(-half, half, hm.size), np.linspace(-half, half, hm.size), indexing="xy"
        )
        self._map_xy = jnp.asarray(np.stack([gx.ravel(), gy.ravel()], -1), jnp.float32)  # [441, 2]
        self._nominal = jnp.asarray(rb.NOMINAL_JOINT_POS)
        lo, hi = rb.JOINT_RANGE[:, 0], rb.JOINT_RANGE[:, 1]
        mid, r = 0.5 * (lo + hi), 0.5 * (hi - lo)
        self._soft_lower = jnp.asarray(mid - 0.95 * r)
        self._soft_upper = jnp.asarray(mid + 0.95 * r)
        self._torque_limit = jnp.asarray(rb.TORQUE_LIMIT * config.robot.torque_scale)
        self._dt = config.robot.timestep * config.decimation
        self._episode_steps = int(round(config.episode_length_s / self._dt))
        self._hold_steps = max(1, int(round(config.success_hold_s / self._dt)))
        push = config.randomization.push_interval_s
        self._push_steps = int(round(push / self._dt)) if push > 0 else 0
        self._terms = rw.active_terms(config.rewards)

    # ------------------------------------------------------------------ brax Env properties

    @property
    def observation_size(self) -> dict[str, tuple[int, ...]]:
        n = N_VEC + self.config.height_map.size**2
        return {"state": (n,), "privileged_state": (n,)}

    @property
    def map_shape(self) -> tuple[int, int]:
        return (self.config.height_map.size, self.config.height_map.size)

    @property
    def action_size(self) -> int:
        return 12

    @property
    def backend(self) -> str:
        return "mjx"

    @property
    def dt(self) -> float:
        return self._dt

    @property
    def episode_steps(self) -> int:
        return self._episode_steps

    @property
    def reward_terms(self) -> tuple[str, ...]:
        return self._terms

    @property
    def goals(self) -> jnp.ndarray:
        """[n_tiles, 4] each tile's goal (x, y, z, yaw), world frame."""
        return self._goal

    def observe(self, qpos: jnp.ndarray, qvel: jnp.ndarray, info: dict) -> jnp.ndarray:
        """The clean actor observation [49 + size**2] of one robot (evaluation settings)."""
        return self._observe(qpos, qvel, info, None)["state"]

    # ------------------------------------------------------------------ terrain

    def terrain_height(self, x: jnp.ndarray, y: jnp.ndarray) -> jnp.ndarray:
        """[...] terrain height (m) at world (x, y), from the model's heightfield on the device."""
        data = self._mx.hfield_data
        return self._h_lo + self._h_span * sample_heights(
            data, self.atlas_shape, self.resolution, x, y
        )

    def height_map(self, pos: jnp.ndarray, yaw: jnp.ndarray, tile: jnp.ndarray) -> jnp.ndarray:
        """[size * size] map values (base z - terrain z - offset, clipped) around `pos` [3],
        read on `tile` alone: points past its edge read the edge (its outer wall or floor)."""
        hm = self.config.height_map
        c, s = jnp.cos(yaw), jnp.sin(yaw)
        px = pos[0] + c * self._map_xy[:, 0] - s * self._map_xy[:, 1]
        py = pos[1] + s * self._map_xy[:, 0] + c * self._map_xy[:, 1]
        lo, hi = self._tile_lo[tile], self._tile_hi[tile]
        px, py = jnp.clip(px, lo[0], hi[0]), jnp.clip(py, lo[1], hi[1])
        h = self.terrain_height(px, py)
        return jnp.clip(pos[2] - h - hm.offset, -hm.clip, hm.clip)

    # ------------------------------------------------------------------ reset

    def reset(self, rng: jax.Array) -> State:
        """A robot at a random family, at a level in [0, initial_max_level], on its tile's spawn."""
        k_level, k_family, k_rest = jax.random.split(rng, 3)
        top = min(self.config.curriculum.initial_max_level, self.num_levels - 1)
        level = jax.random.randint(k_level, (), 0, top + 1)
        family = jax.random.randint(k_family, (), 0, len(self.families))
        return self.reset_at(k_rest, level, family)

    def reset_at(self, rng: jax.Array, level: jnp.ndarray, family: jnp.ndarray) -> State:
        """A robot of `family` (index) on a random tile of `level` (0-based)."""
        k_tile, k_robot, k_next = jax.random.split(rng, 3)
        tile = cur.pick_tile(
            jnp.asarray(level, jnp.int32), jnp.asarray(family, jnp.int32), self._table, k_tile
        )
        qpos, dr = self._spawn_robot(k_robot, tile)
        data = mjx.make_data(self._mx).replace(qpos=qpos)
        info = {
            "rng": k_next,
            "step": jnp.zeros((), jnp.int32),
            "tile": tile,
            "level": jnp.asarray(level, jnp.int32),
            "family": jnp.asarray(family, jnp.int32),
            "last_action": jnp.zeros(12),
            "last_joint_vel": jnp.zeros(12),
            "air_time": jnp.zeros(4),
            "last_foot_contact": jnp.zeros(4, bool),
            "success_count": jnp.zeros((), jnp.int32),
            "success": jnp.zeros(()),
            "truncation": jnp.zeros(()),
            **dr,
        }
        k_noise, info["rng"] = jax.random.split(info["rng"])
        obs = self._observe(qpos, data.qvel, info, k_noise)
        info["final_obs"] = obs
        metrics = self._zero_metrics()
        return State(data, obs, jnp.zeros(()), jnp.zeros(()), metrics, info)

    def _spawn_robot(self, rng: jax.Array, tile: jnp.ndarray) -> tuple[jnp.ndarray, dict]:
        """qpos [19] on the tile's spawn area and this episode's randomisation draws."""
        c = self.config
        ks = jax.random.split(rng, 10)
        sp = self._spawn[tile]
        hx = jnp.maximum(sp[3] - c.spawn_margin, 0.0)
        hy = jnp.maximum(sp[4] - c.spawn_margin, 0.0)
        x = sp[0] + jax.random.uniform(ks[0], (), minval=-1.0, maxval=1.0) * hx
        y = sp[1] + jax.random.uniform(ks[1], (), minval=-1.0, maxval=1.0) * hy
        yaw = sp[5] + jax.random.uniform(ks[2], (), minval=-1.0, maxval=1.0) * sp[6]
        joints = self._nominal + jax.random.uniform(
            ks[3], (12,), minval=-c.joint_noise_at_reset, maxval=c.joint_noise_at_reset
        )
        qpos = jnp.concatenate([jnp.array([x, y, sp[2] + c.spawn_height]), yaw_quat(yaw), joints])
        r = c.randomization
        if not r.enabled:
            dr = {
                "friction": jnp.asarray(c.robot.friction),
                "added_mass": jnp.zeros(()),
                "com_shift": jnp.zeros(3),
                "motor_strength": jnp.ones(12),
                "kp_scale": jnp.ones(()),
                "kd_scale": jnp.ones(()),
            }
            return qpos, dr

        def u(k, lohi, shape=()):
            return jax.random.uniform(k, shape, minval=lohi[0], maxval=lohi[1])

        dr = {
            "friction": u(ks[4], r.friction),
            "added_mass": u(ks[5], r.added_mass),
            "com_shift": u(ks[6], (-r.com_shift, r.com_shift), (3,)),
            "motor_strength": u(ks[7], r.motor_strength, (12,)),
            "kp_scale": u(ks[8], r.kp_scale),
            "kd_scale": u(ks[9], r.kd_scale),
        }
        return qpos, dr

    # ------------------------------------------------------------------ step

    def step(self, state: State, action: jnp.ndarray) -> State:
        """One policy step: PD over `decimation` physics steps, rewards, endings, auto-reset."""
        c = self.config
        info = dict(state.info)
        action = jnp.clip(action, -c.action_clip, c.action_clip)
        model = self._robot_model(info)
        q_target = self._nominal + c.robot.action_scale * action
        kp = c.robot.kp * info["kp_scale"]
        kd = c.robot.kd * info["kd_scale"]
        limit = self._torque_limit * info["motor_strength"]
        qj, vj = self._ids.qpos_joints, self._ids.qvel_joints

        def physics(data, _):
            tau = rb.pd_torque(q_target, data.qpos[qj], data.qvel[vj], kp, kd, limit)
            return mjx.step(model, data.replace(ctrl=tau)), None

        data0 = state.pipeline_state
        if self._push_steps:
            data0 = self._push(data0, info)
        with jax.named_scope("physics"):  # scopes name the pieces in a profiler trace
            data = jax.lax.scan(physics, data0, None, length=c.decimation)[0]
        finite = jnp.all(jnp.isfinite(data.qpos)) & jnp.all(jnp.isfinite(data.qvel))
        with jax.named_scope("nan_guard"):
            # Only the fields a step starts from (STEP_INPUTS) go back to their values before
            # the step; the derived ones, recomputed by the next step, stay as they came out.
            data = data.replace(**{f: jnp.where(finite, getattr(data, f), getattr(data0, f))
                                   for f in STEP_INPUTS})
        torque = data.ctrl  # the last substep's torques (before the step's, if it blew up)

        # Quantities of the robot after the step.
        qpos, qvel = data.qpos, data.qvel
        pos, rot = qpos[:3], quat_to_mat(qpos[3:7])
        yaw = jnp.arctan2(rot[1, 0], rot[0, 0])
        lin_vel_body = rot.T @ qvel[:3]
        gravity_body = rot.T @ jnp.array([0.0, 0.0, -1.0])
        tile = info["tile"]
        goal = self._goal[tile]
        to_goal = goal[:3] - pos
        planar_goal_distance = jnp.linalg.norm(to_goal[:2])
        yaw_error = wrap_angle(goal[3] - yaw)
        dc, arc = rw.centreline_geometry(pos[:2], self._line[tile], self._line_cum[tile])
        path = dc + jnp.maximum(self._line_len[tile] - arc, 0.0)
        path = jnp.where(
            planar_goal_distance < c.rewards.straight_within, jnp.linalg.norm(to_goal), path
        )
        with jax.named_scope("contacts"):
            touching = self._sphere_contacts(data)
        foot = touching["foot"]
        air_time = info["air_time"] + self._dt
        first_contact = foot & ~info["last_foot_contact"]
        planar_speed = jnp.linalg.norm(qvel[:2])
        step_count = info["step"] + 1
        q = rw.Quantities(
            time=step_count * self._dt,
            goal_distance=jnp.linalg.norm(to_goal),
            planar_goal_distance=planar_goal_distance,
            yaw_error=yaw_error,
            centreline_distance=dc,
            path_to_goal=path,
            lin_vel_body=lin_vel_body,
            planar_speed=planar_speed,
            torque=torque,
            joint_pos=qpos[qj],
            joint_vel=qvel[vj],
            joint_acc=(qvel[vj] - info["last_joint_vel"]) / self._dt,
            action=action,
            last_action=info["last_action"],
            joint_lower=self._soft_lower,
            joint_upper=self._soft_upper,
            joint_vel_limit=jnp.asarray(0.9 * rb.VELOCITY_LIMIT),
            trunk_contacts=touching["trunk"],
            knee_contacts=touching["knee"],
            shin_contacts=touching["shin"],
            first_contact=first_contact,
            air_time=air_time,
        )
        with jax.named_scope("rewards"):
            reward, terms = rw.compute(q, c.rewards, self._dt)

        # Success: close and slow, held for success_hold_s.
        close = (planar_goal_distance < c.success_distance) & (planar_speed < c.success_speed)
        success_count = jnp.where(close, info["success_count"] + 1, 0)
        success = jnp.maximum(
            info["success"], (success_count >= self._hold_steps).astype(jnp.float32)
        )

        # Terminations and truncation.
        base_clearance = pos[2] - self.terrain_height(pos[0], pos[1])
        tilted = gravity_body[2] > -jnp.cos(c.max_tilt)
        too_low = base_clearance < c.min_base_height
        fell = tilted | too_low
        outside = (
            (pos[0] < 0)
            | (pos[1] < 0)
            | (pos[0] > self._world_size[0])
            | (pos[1] > self._world_size[1])
        )
        trunk_hit = jnp.any(touching["trunk"]) & c.terminate_on_trunk_contact
        terminated = fell | outside | trunk_hit | ~finite
        truncated = (step_count >= self._episode_steps) & ~terminated
        done = terminated | truncated
        reward = jnp.where(finite, reward, 0.0)

        info.update(
            step=step_count,
            last_action=action,
            last_joint_vel=qvel[vj],
            air_time=jnp.where(foot, 0.0, air_time),
            last_foot_contact=foot,
            success_count=success_count,
            success=success,
        )
        k_noise, k_reset, info["rng"] = jax.random.split(info["rng"], 3)
        with jax.named_scope("observe"):  # a reset's observation counts as auto_reset
            final_obs = self._observe(qpos, qvel, info, k_noise, arc=arc)

        # Curriculum, then auto-reset of the robots whose episode ended.
        level = info["level"]
        moved_up = cur.reached(planar_goal_distance, yaw_error, c.curriculum)
        if c.curriculum.enabled:
            k_level, k_reset = jax.random.split(k_reset)
            next_level = cur.next_level(level, moved_up, self.num_levels, k_level, c.curriculum)
        else:
            next_level = level
        with jax.named_scope("auto_reset"):
            fresh = self.reset_at(k_reset, next_level, info["family"])
        pick = lambda new, old: jnp.where(done, new, old)
        data = data.replace(
            qpos=pick(fresh.pipeline_state.qpos, data.qpos),
            qvel=pick(fresh.pipeline_state.qvel, data.qvel),
            qacc_warmstart=pick(fresh.pipeline_state.qacc_warmstart, data.qacc_warmstart),
            ctrl=pick(fresh.pipeline_state.ctrl, data.ctrl),
        )
        keep = ("rng",)
        info = {
            k: (v if k in keep else jax.tree_util.tree_map(pick, fresh.info[k], v))
            for k, v in info.items()
        }
        obs = jax.tree_util.tree_map(pick, fresh.obs, final_obs)
        info["final_obs"] = final_obs
        info["truncation"] = truncated.astype(jnp.float32)

        metrics = {f"reward/{k}": v for k, v in terms.items()}
        done_f = done.astype(jnp.float32)
        metrics.update(
            done=done_f,
            episode_success=success * done_f,
            terminated=terminated.astype(jnp.float32),
            truncated=truncated.astype(jnp.float32),
            nan_reset=(~finite).astype(jnp.float32),
            trunk_termination=(trunk_hit & ~fell).astype(jnp.float32),
            tilt_termination=tilted.astype(jnp.float32),
            low_termination=(too_low & ~tilted).astype(jnp.float32),
            outside_termination=(outside & ~fell).astype(jnp.float32),
            level=level.astype(jnp.float32),
            at_top=(level == self.num_levels - 1).astype(jnp.float32),
            goal_distance=planar_goal_distance,
            moved_up=(moved_up & done).astype(jnp.float32),
        )
        return State(data, obs, reward, done_f, metrics, info)

    # ------------------------------------------------------------------ compact state

    def pack_state(self, state: State) -> dict[str, Any]:
        """The part of a State that a resume needs (~2.4 kB per robot instead of ~53 kB).

        MJX recomputes every derived field of mjx.Data (kinematics, contacts, constraint rows)
        from qpos, qvel, ctrl and the solver's warm start at the next step, and the critic's
        observation is a function of qpos, qvel and info; only the actor's noisy observation and
        the counters must be kept. `unpack_state` rebuilds the rest.
        """
        d = state.pipeline_state
        info = {k: v for k, v in state.info.items() if k != "final_obs"}
        return {
            **{f: getattr(d, f) for f in STEP_INPUTS},
            "obs": state.obs["state"],
            "reward": state.reward,
            "done": state.done,
            "metrics": state.metrics,
            "info": info,
        }

    def unpack_state(self, packed: dict[str, Any]) -> State:
        """A State from `pack_state`'s output; stepping it matches stepping the original up to
        float rounding of the recomputed critic observation."""
        data = mjx.make_data(self._mx).replace(**{f: packed[f] for f in STEP_INPUTS})
        info = dict(packed["info"])
        clean = self._observe(data.qpos, data.qvel, info, None)["privileged_state"]
        obs = {"state": packed["obs"], "privileged_state": clean}
        info["final_obs"] = obs
        return State(data, obs, packed["reward"], packed["done"], dict(packed["metrics"]), info)

    # ------------------------------------------------------------------ pieces

    def _robot_model(self, info: dict) -> mjx.Model:
        """The MJX model with this robot's randomised friction, trunk mass and CoM."""
        if not self.config.randomization.enabled:
            return self._mx
        mx = self._mx
        b = self._ids.base_body
        friction = mx.geom_friction.at[:, 0].set(info["friction"])
        return mx.replace(
            geom_friction=friction,
            body_mass=mx.body_mass.at[b].add(info["added_mass"]),
            body_ipos=mx.body_ipos.at[b].add(info["com_shift"]),
        )

    def _push(self, data: mjx.Data, info: dict) -> mjx.Data:
        """Add a random planar velocity to the base every push interval."""
        v = self.config.randomization.push_velocity
        k = jax.random.fold_in(info["rng"], 7)
        kick = jax.random.uniform(k, (2,), minval=-v, maxval=v)
        now = (info["step"] > 0) & (info["step"] % self._push_steps == 0)
        return data.replace(qvel=data.qvel.at[:2].add(jnp.where(now, kick, 0.0)))

    def _sphere_contacts(self, data: mjx.Data) -> dict[str, jnp.ndarray]:
        """{group: [4] bool} which collision spheres touch the terrain."""
        dist = data._impl.contact.dist
        return {
            g: jnp.zeros(4, bool) if rows is None else jnp.any(dist[rows] < 1e-3, axis=-1)
            for g, rows in self._contact_rows.items()
        }

    def goal_target(
        self, pos: jnp.ndarray, tile: jnp.ndarray, arc: jnp.ndarray | None = None
    ) -> jnp.ndarray:
        """The (x, y, z, yaw) the goal observation points at, per `config.goal_mode`. `arc`: the
        arc length of pos's projection on the tile's centre-line, when the caller has it."""
        goal = self._goal[tile]
        if self.config.goal_mode == "final":
            return goal
        line, cum, total = self._line3[tile], self._line_cum[tile], self._line_len[tile]
        if arc is None:
            _, arc = rw.centreline_geometry(pos[:2], self._line[tile], cum)
        s = arc + self.config.waypoint_lookahead_m
        i = jnp.clip(jnp.searchsorted(cum, s, side="right") - 1, 0, cum.shape[0] - 2)
        seg = line[i + 1] - line[i]
        seg_len = cum[i + 1] - cum[i]
        t = jnp.clip((s - cum[i]) / jnp.maximum(seg_len, 1e-6), 0.0, 1.0)
        point = line[i] + t * seg
        yaw = jnp.arctan2(seg[1], seg[0])
        waypoint = jnp.concatenate([point, yaw[None]])
        return jnp.where(s >= total, goal, waypoint)

    def _observe(
        self,
        qpos: jnp.ndarray,
        qvel: jnp.ndarray,
        info: dict,
        rng: jax.Array | None,
        arc: jnp.ndarray | None = None,
    ) -> dict[str, jnp.ndarray]:
        """Actor (noisy) and critic (clean) observations [49 + 441] from qpos/qvel alone; with
        `rng` None both are clean. `arc` (optional): see `goal_target`."""
        pos, rot = qpos[:3], quat_to_mat(qpos[3:7])
        yaw = jnp.arctan2(rot[1, 0], rot[0, 0])
        goal = self.goal_target(pos, info["tile"], arc)
        parts = {
            "lin_vel": rot.T @ qvel[:3],
            "ang_vel": qvel[3:6],
            "gravity": rot.T @ jnp.array([0.0, 0.0, -1.0]),
            "joint_pos": qpos[self._ids.qpos_joints] - self._nominal,
            "joint_vel": qvel[self._ids.qvel_joints],
            "last_action": info["last_action"],
            "goal": jnp.concatenate([rot.T @ (goal[:3] - pos), wrap_angle(goal[3] - yaw)[None]]),
            "height": self.height_map(pos, yaw, info["tile"]),
        }
        clean = jnp.concatenate(list(parts.values()))
        n = self.config.noise
        if not n.enabled or rng is None:
            return {"state": clean, "privileged_state": clean}
        scale = {
            "lin_vel": n.lin_vel,
            "ang_vel": n.ang_vel,
            "gravity": n.gravity,
            "joint_pos": n.joint_pos,
            "joint_vel": n.joint_vel,
            "last_action": 0.0,
            "goal": 0.0,
            "height": n.height,
        }
        widths = jnp.concatenate([jnp.full(v.shape, scale[k]) for k, v in parts.items()])
        noisy = clean + widths * jax.random.uniform(rng, clean.shape, minval=-1.0, maxval=1.0)
        return {"state": noisy, "privileged_state": clean}

    def _zero_metrics(self) -> dict[str, jnp.ndarray]:
        names = [f"reward/{k}" for k in self._terms] + [
            "done",
            "episode_success",
            "terminated",
            "truncated",
            "nan_reset",
            "trunk_termination",
            "tilt_termination",
            "low_termination",
            "outside_termination",
            "level",
            "at_top",
            "goal_distance",
            "moved_up",
        ]
        return {k: jnp.zeros(()) for k in names}


def _sphere_contact_rows(mj_model, ids: rb.RobotIds) -> dict[str, np.ndarray | None]:
    """{group: [4, ncon_per_sphere] rows of MJX's contact array} for each sphere group.

    MJX lays contacts out by collision-function group, each geom pair repeated ncon times; the
    layout is static, so it is read once here (tests check it against a forward pass).
    """
    rows: dict[int, list[int]] = {}
    i = 0
    for key, pairs in collision_driver._geom_groups(mj_model).items():
        ncon = collision_driver._COLLISION_FUNC[key.types].ncon
        for g1, g2, _ in pairs:
            for g in (g1, g2):
                rows.setdefault(int(g), [])
            rows[int(g2)].extend(range(i, i + ncon))
            rows[int(g1)].extend(range(i, i + ncon))
            i += ncon
    out = {}
    for group, geoms in (
        ("foot", ids.foot_geoms),
        ("knee", ids.knee_geoms),
        ("shin", ids.shin_geoms),
        ("trunk", ids.trunk_geoms),
    ):
        per = [rows.get(int(g), []) for g in geoms]
        if all(len(p) == 0 for p in per):  # a group without collision, e.g. shins switched off
            out[group] = None
        elif len({len(p) for p in per}) != 1:
            raise ValueError(f"collision spheres of group {group!r} collide unevenly: {per}")
        else:
            out[group] = np.array(per, np.int32)
    return out
