"""Domain randomisation: per-robot draws at reset, the randomised model, pushes."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from mujoco import mjx

from mjx_stairs.env.config import EnvConfig, RandomizationConfig


def draw(keys: jax.Array, config: EnvConfig) -> dict[str, jnp.ndarray]:
    """This episode's draws from 6 keys (the nominal values with randomisation off): friction,
    added trunk mass, trunk CoM shift [3], motor strength [12], kp and kd scales."""
    r = config.randomization
    if not r.enabled:
        return {
            "friction": jnp.asarray(config.robot.friction),
            "added_mass": jnp.zeros(()),
            "com_shift": jnp.zeros(3),
            "motor_strength": jnp.ones(12),
            "kp_scale": jnp.ones(()),
            "kd_scale": jnp.ones(()),
        }

    def u(k, lohi, shape=()):
        return jax.random.uniform(k, shape, minval=lohi[0], maxval=lohi[1])

    return {
        "friction": u(keys[0], r.friction),
        "added_mass": u(keys[1], r.added_mass),
        "com_shift": u(keys[2], (-r.com_shift, r.com_shift), (3,)),
        "motor_strength": u(keys[3], r.motor_strength, (12,)),
        "kp_scale": u(keys[4], r.kp_scale),
        "kd_scale": u(keys[5], r.kd_scale),
    }


def robot_model(mx: mjx.Model, base_body: int, info: dict,
                config: RandomizationConfig) -> mjx.Model:
    """The MJX model with this robot's randomised friction, trunk mass and CoM."""
    if not config.enabled:
        return mx
    friction = mx.geom_friction.at[:, 0].set(info["friction"])
    return mx.replace(
        geom_friction=friction,
        body_mass=mx.body_mass.at[base_body].add(info["added_mass"]),
        body_ipos=mx.body_ipos.at[base_body].add(info["com_shift"]),
    )


def push(data: mjx.Data, info: dict, config: RandomizationConfig, every: int) -> mjx.Data:
    """Add a random planar velocity to the base every ``every`` steps."""
    v = config.push_velocity
    k = jax.random.fold_in(info["rng"], 7)
    kick = jax.random.uniform(k, (2,), minval=-v, maxval=v)
    now = (info["step"] > 0) & (info["step"] % every == 0)
    return data.replace(qvel=data.qvel.at[:2].add(jnp.where(now, kick, 0.0)))
