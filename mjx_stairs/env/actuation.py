"""One policy step of actuation: a push if one is due, PD control over `decimation` physics steps
on the robot's randomised model (the new target delayed per robot), then the NaN guard."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from mujoco import mjx

from mjx_stairs.env import randomization as dr
from mjx_stairs.env.config import EnvConfig
from mjx_stairs.env.terrain import Terrain
from mjx_stairs.env.tiles import TileTables
from mjx_stairs.sim import robot as rb

STEP_INPUTS = ("qpos", "qvel", "qacc_warmstart", "ctrl", "time")
"""The fields of mjx.Data a physics step starts from: MJX recomputes every other field
(kinematics, contacts, constraint rows) from these (the Go2 model has no actuator activations).
The NaN guard restores these, and `StairEnv.pack_state` keeps these."""

STAIR_MARGIN = 0.01
"""m: the base is over the flights when the terrain under it is this much above the tile's lower
floor and below its higher one (pushes with `push_on_stairs`)."""


class Actuator:
    """PD actuation of a robot on an atlas: `actuator(data, action, info) -> (data, finite)`."""

    def __init__(self, mx: mjx.Model, ids: rb.RobotIds, config: EnvConfig, terrain: Terrain,
                 tiles: TileTables):
        self.config = config
        self._mx, self._ids, self._terrain, self._tiles = mx, ids, terrain, tiles
        self._nominal = jnp.asarray(rb.NOMINAL_JOINT_POS)
        self._torque_limit = jnp.asarray(rb.TORQUE_LIMIT * config.robot.torque_scale)
        push = config.randomization.push_interval_s
        self._push_steps = (int(round(push / (config.robot.timestep * config.decimation)))
                            if push > 0 else 0)

    def gains(self, info: dict) -> tuple[jnp.ndarray, jnp.ndarray, jnp.ndarray]:
        """This robot's PD (kp, kd, torque limit [12]): the config's gains times its drawn
        scales, kd raised by `robot.kd_per_delay` times its action delay (the gain scheduled by
        the latency, as the sidecar's PD law tells the robot program)."""
        r = self.config.robot
        kd = r.kd_at(r.timestep * info["delay_steps"]) if "delay_steps" in info else r.kd
        return (r.kp * info["kp_scale"], kd * info["kd_scale"],
                self._torque_limit * info["motor_strength"])

    def __call__(self, data0: mjx.Data, action: jnp.ndarray,
                 info: dict) -> tuple[mjx.Data, jnp.ndarray]:
        """PD control over `decimation` physics steps (after a push, if one is due); a robot
        whose physics blew up gets the step's inputs back (the NaN guard). -> (data, finite).
        With `info["delay_steps"]` (env.randomization.action_delay_s) the first that many
        physics steps still hold the previous action's target."""
        c = self.config
        model = dr.robot_model(self._mx, self._ids, info, c.randomization)
        q_target = self._nominal + c.robot.action_scale * action
        kp, kd, limit = self.gains(info)
        qj, vj = self._ids.qpos_joints, self._ids.qvel_joints
        delayed = "delay_steps" in info
        before = self._nominal + c.robot.action_scale * info["last_action"] if delayed else None

        def physics(data, i):
            target = jnp.where(i < info["delay_steps"], before, q_target) if delayed else q_target
            tau = rb.pd_torque(target, data.qpos[qj], data.qvel[vj], kp, kd, limit)
            return mjx.step(model, data.replace(ctrl=tau)), None

        if self._push_steps:
            data0 = self._push(data0, info)
        with jax.named_scope("physics"):  # scopes name the pieces in a profiler trace
            steps = jnp.arange(c.decimation) if delayed else None
            data = jax.lax.scan(physics, data0, steps, length=c.decimation)[0]
        finite = jnp.all(jnp.isfinite(data.qpos)) & jnp.all(jnp.isfinite(data.qvel))
        with jax.named_scope("nan_guard"):
            # Only the fields a step starts from (STEP_INPUTS) go back to their values before
            # the step; the derived ones, recomputed by the next step, stay as they came out.
            data = data.replace(**{f: jnp.where(finite, getattr(data, f), getattr(data0, f))
                                   for f in STEP_INPUTS})
        return data, finite

    def _push(self, data: mjx.Data, info: dict) -> mjx.Data:
        r = self.config.randomization
        if not r.push_on_stairs:
            return dr.push(data, info, r, self._push_steps)
        return dr.push_on_stairs(data, info, r, self._push_steps,
                                 self.over_flights(data.qpos, info["tile"]))

    def over_flights(self, qpos: jnp.ndarray, tile: jnp.ndarray) -> jnp.ndarray:
        """[] bool: the terrain under the base lies between the tile's two floor heights."""
        h = self._terrain.height(qpos[0], qpos[1])
        return (h > self._tiles.floor[tile] + STAIR_MARGIN) & (
            h < self._tiles.top[tile] - STAIR_MARGIN)
