"""Domain randomisation: per-robot draws at reset, the randomised model, pushes.

The draws of issue 24 (joint damping, action delay) come from keys folded out of the first key,
and only when configured, so the other draws and every config without them stay as they were.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from mujoco import mjx

from mjx_stairs.env.config import EnvConfig, RandomizationConfig
from mjx_stairs.sim import robot as rb


def draw(keys: jax.Array, config: EnvConfig) -> dict[str, jnp.ndarray]:
    """This episode's draws from 6 keys (the nominal values with randomisation off): friction,
    added trunk mass, trunk CoM shift [3], motor strength [12], kp and kd scales; when
    configured, the joints' passive damping and the action delay in physics steps (drawn, or
    the robot's fixed `robot.action_delay_s`)."""
    r = config.randomization
    if not r.enabled:
        out = {
            "friction": jnp.asarray(config.robot.friction),
            "added_mass": jnp.zeros(()),
            "com_shift": jnp.zeros(3),
            "motor_strength": jnp.ones(12),
            "kp_scale": jnp.ones(()),
            "kd_scale": jnp.ones(()),
        }
    else:
        def u(k, lohi, shape=()):
            return jax.random.uniform(k, shape, minval=lohi[0], maxval=lohi[1])

        out = {
            "friction": u(keys[0], r.friction),
            "added_mass": u(keys[1], r.added_mass),
            "com_shift": u(keys[2], (-r.com_shift, r.com_shift), (3,)),
            "motor_strength": u(keys[3], r.motor_strength, (12,)),
            "kp_scale": u(keys[4], r.kp_scale),
            "kd_scale": u(keys[5], r.kd_scale),
        }
        if r.joint_damping:
            k = jax.random.fold_in(keys[0], 1)
            out["joint_damping"] = (u(k, r.joint_damping) if r.joint_damping_draw == "uniform"
                                    else jnp.exp(u(k, jnp.log(jnp.asarray(r.joint_damping)))))
        lo, hi = (int(round(s / config.robot.timestep)) for s in r.action_delay_s)
        if hi > 0:
            out["delay_steps"] = jax.random.randint(jax.random.fold_in(keys[0], 2), (), lo,
                                                    hi + 1)
    if "delay_steps" not in out and config.robot.action_delay_steps > 0:
        out["delay_steps"] = jnp.asarray(config.robot.action_delay_steps, jnp.int32)
    return out


def release_height(key: jax.Array, config: EnvConfig) -> jnp.ndarray:
    """The base's height above the spawn floor at reset (m): drawn from
    `randomization.spawn_height` when it is set and randomisation is on, else `spawn_height`."""
    r = config.randomization
    if r.enabled and r.spawn_height:
        return jax.random.uniform(key, (), minval=r.spawn_height[0], maxval=r.spawn_height[1])
    return jnp.asarray(config.spawn_height, jnp.float32)


def robot_model(mx: mjx.Model, ids: rb.RobotIds, info: dict,
                config: RandomizationConfig) -> mjx.Model:
    """The MJX model with this robot's randomised friction, trunk mass and CoM (and the joints'
    passive damping, when drawn)."""
    if not config.enabled:
        return mx
    friction = mx.geom_friction.at[:, 0].set(info["friction"])
    model = mx.replace(
        geom_friction=friction,
        body_mass=mx.body_mass.at[ids.base_body].add(info["added_mass"]),
        body_ipos=mx.body_ipos.at[ids.base_body].add(info["com_shift"]),
    )
    if "joint_damping" in info:
        damping = mx.dof_damping.at[ids.qvel_joints].set(info["joint_damping"])
        model = model.replace(dof_damping=damping)
    return model


def push(data: mjx.Data, info: dict, config: RandomizationConfig, every: int) -> mjx.Data:
    """Add a random planar velocity to the base every ``every`` steps."""
    v = config.push_velocity
    k = jax.random.fold_in(info["rng"], 7)
    kick = jax.random.uniform(k, (2,), minval=-v, maxval=v)
    now = (info["step"] > 0) & (info["step"] % every == 0)
    return data.replace(qvel=data.qvel.at[:2].add(jnp.where(now, kick, 0.0)))


def push_on_stairs(data: mjx.Data, info: dict, config: RandomizationConfig, every: int,
                   on_stairs: jnp.ndarray) -> mjx.Data:
    """Add a random planar velocity to the base at random steps while `on_stairs` ([] bool),
    each step with chance 1 / ``every``."""
    v = config.push_velocity
    k_when, k_kick = jax.random.split(jax.random.fold_in(info["rng"], 7))
    kick = jax.random.uniform(k_kick, (2,), minval=-v, maxval=v)
    now = on_stairs & (jax.random.uniform(k_when) < 1.0 / every)
    return data.replace(qvel=data.qvel.at[:2].add(jnp.where(now, kick, 0.0)))
