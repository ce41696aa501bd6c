"""The stair-climbing env on MJX, behind brax's Env/State interface.

One robot per call (the trainer vmaps over robots). `reset` and `step` are pure and jittable. The
env auto-resets inside `step`, because the curriculum picks the next tile when an episode ends:
the returned state already holds the new episode, `state.info["final_obs"]` the observation
before the reset and `state.info["truncation"]` whether the episode ended by timeout.

`step` runs its phases in order: actuate (env.actuation: PD over `decimation` physics steps,
with the NaN guard) -> quantities (base kinematics once, goal, centre-line, contacts) -> rewards
(named terms, env.rewards) -> endings (success, falls, timeout) -> observation -> auto-reset
(curriculum) -> metrics. The observation layout is env.observation's table.

Where ours differs from the authors' Isaac Lab setup:
- The height map is sampled bilinearly from the atlas heightfield on the device instead of ray
  casting (mjx.ray does not see heightfields); for our own terrain it is exact.
- Everything is computed from qpos/qvel, so a reset needs no extra forward pass.
- The contact penalties read MJX contacts of our collision spheres: trunk corners stand for
  base/head, knee spheres (+ thigh chain or capsule) thighs, mid-shin spheres (+ calf's) calves.
- Regularisers are always on (the authors switch most on once the curriculum's top level is
  reached; a cross-robot gate does not fit a per-robot env).
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from brax.envs.base import Env, State
from mujoco import mjx

from mjx_stairs.env import curriculum as cur
from mjx_stairs.env import endings, goals, observation, perception, routes, symmetry
from mjx_stairs.env import randomization as dr
from mjx_stairs.env import rewards as rw
from mjx_stairs.env.actuation import STEP_INPUTS, Actuator
from mjx_stairs.env.config import EnvConfig
from mjx_stairs.env.geometry import Kinematics, base_kinematics, wrap_angle, yaw_quat
from mjx_stairs.env.terrain import Terrain
from mjx_stairs.env.tiles import TileTables, waypoint_on
from mjx_stairs.sim import robot as rb
from mjx_stairs.sim import touch

__all__ = ["STEP_INPUTS", "StairEnv"]

class StairEnv(Env):
    """Go2 climbing the stairs of an atlas. See the module docstring for the step."""
    RESUME_INERT = cur.RESUME_INERT  # {config key: why changing it on a resume does nothing}

    def __init__(self, atlas: Any, config: EnvConfig | None = None):
        """The model with the heightfield of `atlas` (a terrains.Atlas: heights, resolution,
        rows, cols, families, per-tile tables), its tables on the device; `config`: settings."""
        config = EnvConfig() if config is None else config
        if not config.waypoint_lookahead_m > 0:
            raise ValueError(f"env.waypoint_lookahead_m: must be > 0, got "
                             f"{config.waypoint_lookahead_m}")
        self.config = config
        self.atlas_shape = tuple(int(s) for s in atlas.heights.shape)
        self.resolution = float(atlas.resolution)
        self.num_levels = int(atlas.rows)
        self.families = tuple(atlas.families)
        directions = set(np.asarray(atlas.direction).tolist())
        self.both_ways = len(directions) == 2  # the atlas is walked up and down: DOWN_METRICS
        self.robot = rb.build(atlas.heights, self.resolution, config.robot)
        self._mx = self.robot.mjx_model
        if self._mx.na:
            raise ValueError(f"the robot model has {self._mx.na} actuator activations; the NaN "
                             "guard and pack_state keep only STEP_INPUTS")
        self._ids = ids = self.robot.ids
        mj = self.robot.mj_model
        self.terrain = Terrain(self.robot, self.atlas_shape, self.resolution, config.height_map)
        self.tiles = TileTables(atlas)
        self.tile_origin = self.tiles.origin  # [n, 2] host copy
        self._table = cur.TileTable(np.asarray(atlas.family), int(atlas.cols), len(self.families))
        self.contact_rows = touch.sphere_contact_rows(mj, ids)
        self._foot_radius = jnp.asarray(mj.geom_size[ids.foot_geoms, 0])
        self.actuate = Actuator(self._mx, ids, config, self.terrain, self.tiles)
        self._nominal = jnp.asarray(rb.NOMINAL_JOINT_POS)
        lo, hi = rb.JOINT_RANGE[:, 0], rb.JOINT_RANGE[:, 1]
        mid, r = 0.5 * (lo + hi), 0.5 * (hi - lo)
        self._soft_lower = jnp.asarray(mid - 0.95 * r)
        self._soft_upper = jnp.asarray(mid + 0.95 * r)
        self._dt = config.robot.timestep * config.decimation
        self._episode_steps = int(round(config.episode_length_s / self._dt))
        self._hold_steps = max(1, int(round(config.success_hold_s / self._dt)))
        self._terms = rw.active_terms(config.rewards)
        r = config.randomization  # both drawn: the CORNERS' success metrics (env.endings)
        self._corners = bool(r.enabled and r.joint_damping and r.action_delay_s[1] > 0)

    # ------------------------------------------------------------------ properties

    @property
    def observation_size(self) -> dict[str, tuple[int, ...]]:
        n = observation.n_vec_of(self.config) + self.config.height_map.size ** 2
        return {"state": (n,), "privileged_state": (n,)}

    @property
    def map_shape(self) -> tuple[int, int]:
        return (self.config.height_map.size, self.config.height_map.size)

    @property
    def mirror(self) -> symmetry.Mirror:  # left-right, for the trainer's ppo.mirror_loss_coef
        return symmetry.of_config(self.config)

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
        return self.tiles.goal

    @property
    def num_contacts(self) -> int:
        """Rows of MJX's contact array that belong to the robot's collision spheres."""
        return int(sum(r.size for r in self.contact_rows.values() if r is not None))

    # ------------------------------------------------------------------ terrain

    def terrain_height(self, x: jnp.ndarray, y: jnp.ndarray) -> jnp.ndarray:
        """[...] terrain height (m) at world (x, y), on the device (env.terrain.Terrain)."""
        return self.terrain.height(x, y)

    def height_map(self, pos: jnp.ndarray, yaw: jnp.ndarray, tile: jnp.ndarray) -> jnp.ndarray:
        """[size * size] the height map around `pos` [3], read on `tile` alone: points past its
        edge read the edge, its outer wall or floor (env.terrain.Terrain.height_map)."""
        return self.terrain.height_map(pos, yaw, self.tiles.lo[tile], self.tiles.hi[tile])

    # ------------------------------------------------------------------ reset

    def reset(self, rng: jax.Array) -> State:
        """A robot at a random family, at a level in [0, initial_max_level], on its tile's spawn."""
        k_level, k_family, k_rest = jax.random.split(rng, 3)
        top = min(self.config.curriculum.initial_max_level, self.num_levels - 1)
        level = jax.random.randint(k_level, (), 0, top + 1)
        family = cur.pick_family(k_family, len(self.families), self.config.curriculum)
        return self.reset_at(k_rest, level, family)

    def reset_at(self, rng: jax.Array, level: jnp.ndarray, family: jnp.ndarray) -> State:
        """A robot of `family` (index) on a random tile of `level` (0-based)."""
        k_tile, k_robot, k_next = jax.random.split(rng, 3)
        tile = cur.pick_tile(
            jnp.asarray(level, jnp.int32), jnp.asarray(family, jnp.int32), self._table, k_tile
        )
        qpos, draws = self._spawn_robot(k_robot, tile)
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
            "success": jnp.zeros((), jnp.float32),
            "truncation": jnp.zeros((), jnp.float32),
            **draws,
            **observation.history_start(self.config.obs_history,
                                        qpos[self._ids.qpos_joints] - self._nominal),
        }
        k_noise, info["rng"] = jax.random.split(info["rng"])
        obs = self.observe(qpos, data.qvel, info, k_noise)
        info["final_obs"] = obs
        zero = jnp.zeros((), jnp.float32)  # float32 also when the physics runs in float64
        return State(data, obs, zero, zero, {k: zero for k in self.metric_names()}, info)

    def _spawn_robot(self, rng: jax.Array, tile: jnp.ndarray) -> tuple[jnp.ndarray, dict]:
        """qpos [19] on the tile's spawn area and this episode's randomisation draws."""
        c = self.config
        ks = jax.random.split(rng, 10)
        sp = self.tiles.spawn[tile]
        hx = jnp.maximum(sp[3] - c.spawn_margin, 0.0)
        hy = jnp.maximum(sp[4] - c.spawn_margin, 0.0)
        x = sp[0] + jax.random.uniform(ks[0], (), minval=-1.0, maxval=1.0) * hx
        y = sp[1] + jax.random.uniform(ks[1], (), minval=-1.0, maxval=1.0) * hy
        half = sp[6] if c.spawn_yaw_half_range < 0 else c.spawn_yaw_half_range
        yaw = sp[5] + jax.random.uniform(ks[2], (), minval=-1.0, maxval=1.0) * half
        joints = self._nominal + jax.random.uniform(
            ks[3], (12,), minval=-c.joint_noise_at_reset, maxval=c.joint_noise_at_reset
        )
        z = sp[2] + dr.release_height(jax.random.fold_in(ks[3], 1), c)
        qpos = jnp.concatenate([jnp.stack([x, y, z]), yaw_quat(yaw), joints])
        draws = {**dr.draw(ks[4:], c), **perception.draw(rng, c)}
        draws.update(goals.draw(rng, self.tiles, tile, jnp.stack([x, y]), yaw, c))
        return qpos, {**draws, **routes.draw(rng, self.tiles, tile, c)}

    # ------------------------------------------------------------------ step

    def step(self, state: State, action: jnp.ndarray) -> State:
        """One policy step, as the phases of the module docstring."""
        c = self.config
        info = dict(state.info)
        action = jnp.clip(action, -c.action_clip, c.action_clip)
        data, finite = self.actuate(state.pipeline_state, action, info)
        kin = base_kinematics(data.qpos, data.qvel)
        q, arc, foot = self._quantities(data, kin, action, info)
        with jax.named_scope("rewards"):
            reward, terms = rw.compute(q, c.rewards, self._dt)
        ends = self._endings(kin, q, info, finite)
        reward = jnp.where(finite, reward, 0.0)
        vj = self._ids.qvel_joints
        if c.obs_history:  # the joint positions the last observation saw, the action before it
            seen = state.pipeline_state.qpos[self._ids.qpos_joints] - self._nominal
            info["joint_pos_history"] = observation.shift_in(info["joint_pos_history"], seen)
            info["action_history"] = observation.shift_in(info["action_history"],
                                                          info["last_action"])
        info.update(step=info["step"] + 1, last_action=action, last_joint_vel=data.qvel[vj],
                    air_time=jnp.where(foot, 0.0, q.air_time), last_foot_contact=foot,
                    success_count=ends.success_count, success=ends.success)
        k_noise, k_reset, info["rng"] = jax.random.split(info["rng"], 3)
        with jax.named_scope("observe"):  # a reset's observation counts as auto_reset
            final_obs = self.observe(data.qpos, data.qvel, info, k_noise, arc=arc, kin=kin)
        level, tile = info["level"], info["tile"]
        drawn = endings.corner_draws(info, c.robot.timestep) if self._corners else None
        moved_up = cur.reached(q.planar_goal_distance, q.yaw_error, c.curriculum)
        data, obs, info = self._auto_reset(data, info, final_obs, ends, moved_up, k_reset)
        metrics = endings.metrics(terms, ends, finite, level, self.num_levels - 1,
                                  q.planar_goal_distance, moved_up)
        if self.both_ways:
            metrics.update(endings.down_metrics(ends, self.tiles.down[tile]))
        metrics.update(endings.family_metrics(self.families, info["family"], level,
                                              self.num_levels - 1, ends, drawn))
        f32 = lambda x: x.astype(jnp.float32)  # noqa: E731  (also when the physics is float64)
        return State(data, obs, f32(reward), f32(ends.done), jax.tree.map(f32, metrics), info)

    def _quantities(self, data: mjx.Data, kin: Kinematics, action: jnp.ndarray,
                    info: dict) -> tuple[rw.Quantities, jnp.ndarray, jnp.ndarray]:
        """What the rewards and endings read, after the step -> (quantities, arc length along
        the centre-line, [4] foot contacts)."""
        c = self.config
        qpos, qvel = data.qpos, data.qvel
        qj, vj = self._ids.qpos_joints, self._ids.qvel_joints
        tile = info["tile"]
        goal = goals.goal_of(info, self.tiles)  # the tile's, or the episode's (env.goals)
        to_goal = goal[:3] - kin.pos
        planar_goal_distance = jnp.linalg.norm(to_goal[:2])
        dc, arc = rw.centreline_geometry(kin.pos[:2], self.tiles.line[tile],
                                         self.tiles.line_cum[tile])
        path = dc + goals.along_line(info, self.tiles, arc)
        path = jnp.where(
            planar_goal_distance < c.rewards.straight_within, jnp.linalg.norm(to_goal), path
        )
        with jax.named_scope("contacts"):
            touching = touch.sphere_contacts(data, self.contact_rows)
        foot = touching["foot"]
        q = rw.Quantities(
            time=(info["step"] + 1) * self._dt,
            goal_distance=jnp.linalg.norm(to_goal),
            planar_goal_distance=planar_goal_distance,
            yaw_error=wrap_angle(goal[3] - kin.yaw),
            centreline_distance=dc,
            path_to_goal=path,
            lin_vel_body=kin.lin_vel_body,
            ang_vel_body=qvel[3:6],  # a free joint's angular velocity is in the body frame
            gravity_body=kin.gravity_body,
            planar_speed=jnp.linalg.norm(qvel[:2]),
            torque=data.ctrl,  # the last substep's torques (before the step's, if it blew up)
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
            first_contact=foot & ~info["last_foot_contact"],
            air_time=info["air_time"] + self._dt,
            **rw.feet_quantities(self.terrain_height, data.geom_xpos[self._ids.foot_geoms],
                                 self._foot_radius, kin.yaw, foot, c.rewards),
        )
        return q, arc, foot

    def _endings(self, kin: Kinematics, q: rw.Quantities, info: dict,
                 finite: jnp.ndarray) -> endings.Endings:
        x, y, c = kin.pos[0], kin.pos[1], self.config
        clearance = kin.pos[2] - endings.ground_under(self.terrain_height, x, y, kin.yaw,
                                                      c.low_line_m)
        slope = endings.slope_along(self.terrain_height, x, y, kin.yaw, c.tilt_slope_m)
        return endings.endings(c, kin, q, info, finite, clearance, self.terrain.size,
                               self._hold_steps, self._episode_steps, slope)

    def _auto_reset(self, data: mjx.Data, info: dict, final_obs: dict, ends: endings.Endings,
                    moved_up: jnp.ndarray, key: jax.Array) -> tuple[mjx.Data, dict, dict]:
        """The curriculum's next level, then a fresh episode where this one ended."""
        c, level = self.config, info["level"]
        if c.curriculum.enabled:
            k_level, key = jax.random.split(key)
            next_level = cur.next_level(level, moved_up, self.num_levels, k_level, c.curriculum)
        else:
            next_level = level
        with jax.named_scope("auto_reset"):
            fresh = self.reset_at(key, next_level, info["family"])
        pick = lambda new, old: jnp.where(ends.done, new, old)
        data = data.replace(**{f: pick(getattr(fresh.pipeline_state, f), getattr(data, f))
                               for f in ("qpos", "qvel", "qacc_warmstart", "ctrl")})
        info = {k: (v if k == "rng" else jax.tree_util.tree_map(pick, fresh.info[k], v))
                for k, v in info.items()}
        obs = jax.tree_util.tree_map(pick, fresh.obs, final_obs)
        info.update(final_obs=final_obs, truncation=ends.truncated.astype(jnp.float32))
        return data, obs, info

    def metric_names(self) -> tuple[str, ...]:
        """The keys of `state.metrics` (env.endings.metric_names)."""
        return endings.metric_names(self._terms, self.both_ways, self.families, self._corners)

    # ------------------------------------------------------------------ observation

    def goal_target(self, pos: jnp.ndarray, tile: jnp.ndarray, arc: jnp.ndarray | None = None,
                    info: dict | None = None) -> jnp.ndarray:
        """The (x, y, z, yaw) the goal observation points at, per `config.goal_mode` (see
        env.tiles.TileTables.waypoint), on the episode's route when info has one (env.routes;
        `arc` is along the tile's centre-line)."""
        if self.config.goal_mode == "final":
            return self.tiles.goal[tile] if info is None else goals.goal_of(info, self.tiles)
        heading = self.config.waypoint_heading
        if info is not None and "route" in info:
            return waypoint_on(pos, info["route"], info["route_cum"], self.tiles.goal[tile],
                               self.config.waypoint_lookahead_m, heading=heading)
        return self.tiles.waypoint(pos, tile, self.config.waypoint_lookahead_m, arc, heading)

    def observe(self, qpos: jnp.ndarray, qvel: jnp.ndarray, info: dict,
                rng: jax.Array | None = None, arc: jnp.ndarray | None = None,
                kin: Kinematics | None = None) -> dict[str, jnp.ndarray]:
        """Actor (noisy) and critic (clean) observations (env.observation) from qpos/qvel and
        info's tile and last action; with `rng` None both are clean. `arc`: see goal_target;
        `kin`: base_kinematics(qpos, qvel) when the caller has it."""
        kin = base_kinematics(qpos, qvel) if kin is None else kin
        goal = self.goal_target(kin.pos, info["tile"], arc, info)
        values = {
            "base_lin_vel": kin.lin_vel_body,
            "base_ang_vel": qvel[3:6],
            "projected_gravity": kin.gravity_body,
            "joint_pos": qpos[self._ids.qpos_joints] - self._nominal,
            "joint_vel": qvel[self._ids.qvel_joints],
            "last_action": info["last_action"],
            "goal": jnp.concatenate([kin.rot.T @ (goal[:3] - kin.pos),
                                     wrap_angle(goal[3] - kin.yaw)[None]]),
            "height_map": self.height_map(kin.pos, kin.yaw, info["tile"]),
        }
        c = self.config
        if c.obs_history:
            values.update(joint_pos_history=info["joint_pos_history"].reshape(-1),
                          action_history=info["action_history"].reshape(-1))
        values.update(observation.robot_values(c, info))
        obs = observation.assemble(values, observation.of_config(c), c.noise, rng,
                                   observation.critic_only(c))
        return perception.corrupt(obs, info, rng, self.config)

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
        clean = self.observe(data.qpos, data.qvel, info)["privileged_state"]
        obs = {"state": packed["obs"], "privileged_state": clean}
        info["final_obs"] = obs
        return State(data, obs, packed["reward"], packed["done"], dict(packed["metrics"]), info)
