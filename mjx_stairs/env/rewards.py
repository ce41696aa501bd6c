"""Reward terms as small named functions, weights in a config, stage presets.

Each term maps the `Quantities` of one robot after a policy step to a scalar; the env multiplies
it by its weight and by the policy step dt (as Isaac Lab does, so the authors' weights carry over)
and logs it as `reward/<name>`. A term with weight 0 is not computed.
"""

from __future__ import annotations

import dataclasses
from typing import Callable, NamedTuple

import jax.numpy as jnp


class Quantities(NamedTuple):
    """What the reward terms read, for one robot. Shapes in brackets."""

    time: jnp.ndarray  # [] seconds since the episode started
    goal_distance: jnp.ndarray  # [] 3-D distance base -> goal (m)
    planar_goal_distance: jnp.ndarray  # [] xy distance base -> goal (m)
    yaw_error: jnp.ndarray  # [] goal yaw - base yaw, wrapped to [-pi, pi]
    centreline_distance: jnp.ndarray  # [] xy distance to the centre-line polyline (m)
    path_to_goal: jnp.ndarray  # [] D of the centre-line reward (m)
    lin_vel_body: jnp.ndarray  # [3] base linear velocity in the body frame
    ang_vel_body: jnp.ndarray  # [3] base angular velocity in the body frame (rad/s)
    gravity_body: jnp.ndarray  # [3] unit gravity in the body frame ([0, 0, -1] upright)
    planar_speed: jnp.ndarray  # [] xy speed of the base (m/s)
    torque: jnp.ndarray  # [12] last physics step's joint torques
    joint_pos: jnp.ndarray  # [12]
    joint_vel: jnp.ndarray  # [12]
    joint_acc: jnp.ndarray  # [12] (qvel - last qvel) / dt
    action: jnp.ndarray  # [12]
    last_action: jnp.ndarray  # [12]
    joint_lower: jnp.ndarray  # [12] soft position limits
    joint_upper: jnp.ndarray  # [12]
    joint_vel_limit: jnp.ndarray  # [] soft velocity limit
    trunk_contacts: jnp.ndarray  # [4] bool, trunk-corner spheres touching the terrain (+ head: [5])
    knee_contacts: jnp.ndarray  # [4] bool, knee (thigh end) spheres
    shin_contacts: jnp.ndarray  # [4] bool, each calf (its mid-shin sphere or calf chain)
    first_contact: jnp.ndarray  # [4] bool, a foot touched down this step
    air_time: jnp.ndarray  # [4] seconds the foot was in the air before touching down
    # For foot_clearance (zeros while its weight is 0): [4] each foot's contact, its sole's
    # height, the terrain under it and the terrain clearance_ahead ahead of it along the heading
    foot_contact: jnp.ndarray
    sole_height: jnp.ndarray
    ground_under_foot: jnp.ndarray
    ground_ahead_of_foot: jnp.ndarray


@dataclasses.dataclass(frozen=True)
class RewardConfig:
    """Weights of the reward terms (0 switches a term off) and their parameters."""

    nav_coarse: float = 1.0  # 1 - tanh(d / coarse_std), d = 3-D goal distance
    nav_fine: float = 1.0  # 1 - tanh(d / fine_std)
    heading: float = -0.3  # |goal yaw - base yaw|
    centreline: float = 0.0  # stage 2 centre-line reward
    stall: float = 0.0  # 1 when slower than stall_speed outside stall_goal_radius
    # tanh((v - 0.1) / 0.2) when faster than 0.1 m/s and further than stall_goal_radius from
    # the goal, only before fine_after_s (the authors' stage-2 movement_reward, +0.2 there)
    movement: float = 0.0
    power: float = -1e-4  # sum |tau * qdot|
    torque: float = -1e-5  # sum tau^2
    action_rate: float = -1e-4  # sum (a - a_prev)^2
    joint_pos_limit: float = -0.1  # sum of soft-limit violations (rad)
    joint_vel_limit: float = -0.1  # sum of |qdot| above the soft velocity limit
    joint_vel: float = -5e-5  # sum qdot^2
    joint_acc: float = -2e-8  # sum qddot^2
    contact_trunk_thigh: float = -8.0  # number of trunk and knee spheres touching
    contact_calf: float = -0.2  # number of calves touching (mid-shin sphere or calf chain)
    overspeed: float = -1.0  # planar speed above max_speed (m/s)
    backward: float = -0.05  # backward body-frame speed (m/s)
    feet_air_time: float = 0.2  # sum over touchdowns of (min(air, air_max) - air_min)
    # The base's motion off its gait (legged_gym's and Isaac Lab's velocity tasks: -2.0, -0.05;
    # the authors' stair env has neither): off here, the paper's reward as written.
    lin_vel_z: float = 0.0  # body-frame vertical speed squared (m/s)^2
    ang_vel_xy: float = 0.0  # roll and pitch rates squared, body frame (rad/s)^2
    roll: float = 0.0  # lateral tilt: gravity's body-y component squared, sin^2(roll) upright
    # A foot in the air that would stub the step nose ahead of it (off in the paper's reward):
    # metres its sole is below clearance_target above the next tread, summed over swing feet
    # with a riser (a rise above clearance_step) within clearance_ahead ahead along the heading
    foot_clearance: float = 0.0

    coarse_std: float = 5.0
    fine_std: float = 1.0
    fine_after_s: float = 0.0  # nav_fine and heading count only after this time in the episode
    stall_speed: float = 0.3  # m/s
    stall_goal_radius: float = 0.5  # m, no stall penalty inside it
    max_speed: float = 1.5  # m/s
    air_min: float = 0.4  # s
    air_max: float = 1.0  # s
    straight_within: float = 0.8  # centre-line D is the straight distance this close to the goal
    clearance_target: float = 0.05  # m above the next tread that a swing foot's sole should be
    clearance_ahead: float = 0.1  # m ahead of the foot (along the heading) it looks for a riser
    clearance_step: float = 0.03  # m: a rise smaller than this is not a riser


STAGE1 = RewardConfig()
"""Stage 1, pyramid stairs: navigation terms and regularisers."""

STAGE2 = dataclasses.replace(
    STAGE1,
    nav_coarse=0.0,
    centreline=2.0,
    stall=-0.8,
    contact_trunk_thigh=-4.0,
    fine_after_s=6.0,
)
"""Stage 2, U-shaped stairs: coarse term off, centre-line reward, stall penalty, late fine terms."""

PRESETS = {"stage1": STAGE1, "stage2": STAGE2}


def _late(q: Quantities, c: RewardConfig) -> jnp.ndarray:
    return (q.time >= c.fine_after_s).astype(jnp.float32)


def nav_coarse(q: Quantities, c: RewardConfig) -> jnp.ndarray:
    return 1.0 - jnp.tanh(q.goal_distance / c.coarse_std)


def nav_fine(q: Quantities, c: RewardConfig) -> jnp.ndarray:
    return (1.0 - jnp.tanh(q.goal_distance / c.fine_std)) * _late(q, c)


def heading(q: Quantities, c: RewardConfig) -> jnp.ndarray:
    return jnp.abs(q.yaw_error) * _late(q, c)


def centreline(q: Quantities, c: RewardConfig) -> jnp.ndarray:
    """0.95 (1 - tanh(D / 8)) (1 - tanh(d_c / 0.6)) + 0.05 (1 - tanh(d_c / 0.4))."""
    dc = q.centreline_distance
    return 0.95 * (1 - jnp.tanh(q.path_to_goal / 8.0)) * (1 - jnp.tanh(dc / 0.6)) + 0.05 * (
        1 - jnp.tanh(dc / 0.4)
    )


def stall(q: Quantities, c: RewardConfig) -> jnp.ndarray:
    slow = q.planar_speed < c.stall_speed
    away = q.planar_goal_distance > c.stall_goal_radius
    return (slow & away).astype(jnp.float32)


def movement(q: Quantities, c: RewardConfig) -> jnp.ndarray:
    moving = (q.planar_speed > 0.1) & (q.goal_distance > c.stall_goal_radius)
    early = (q.time < c.fine_after_s).astype(jnp.float32)
    return jnp.where(moving, jnp.tanh((q.planar_speed - 0.1) / 0.2), 0.0) * early


def power(q: Quantities, c: RewardConfig) -> jnp.ndarray:
    return jnp.sum(jnp.abs(q.torque * q.joint_vel))


def torque(q: Quantities, c: RewardConfig) -> jnp.ndarray:
    return jnp.sum(jnp.square(q.torque))


def action_rate(q: Quantities, c: RewardConfig) -> jnp.ndarray:
    return jnp.sum(jnp.square(q.action - q.last_action))


def joint_pos_limit(q: Quantities, c: RewardConfig) -> jnp.ndarray:
    below = jnp.clip(q.joint_lower - q.joint_pos, 0.0, None)
    above = jnp.clip(q.joint_pos - q.joint_upper, 0.0, None)
    return jnp.sum(below + above)


def joint_vel_limit(q: Quantities, c: RewardConfig) -> jnp.ndarray:
    return jnp.sum(jnp.clip(jnp.abs(q.joint_vel) - q.joint_vel_limit, 0.0, None))


def joint_vel(q: Quantities, c: RewardConfig) -> jnp.ndarray:
    return jnp.sum(jnp.square(q.joint_vel))


def joint_acc(q: Quantities, c: RewardConfig) -> jnp.ndarray:
    return jnp.sum(jnp.square(q.joint_acc))


def contact_trunk_thigh(q: Quantities, c: RewardConfig) -> jnp.ndarray:
    return jnp.sum(q.trunk_contacts) + jnp.sum(q.knee_contacts).astype(jnp.float32)


def contact_calf(q: Quantities, c: RewardConfig) -> jnp.ndarray:
    return jnp.sum(q.shin_contacts).astype(jnp.float32)


def overspeed(q: Quantities, c: RewardConfig) -> jnp.ndarray:
    return jnp.clip(q.planar_speed - c.max_speed, 0.0, None)


def backward(q: Quantities, c: RewardConfig) -> jnp.ndarray:
    return jnp.clip(-q.lin_vel_body[0], 0.0, None)


def feet_air_time(q: Quantities, c: RewardConfig) -> jnp.ndarray:
    air = jnp.minimum(q.air_time, c.air_max) - c.air_min
    return jnp.sum(air * q.first_contact)


def foot_clearance(q: Quantities, c: RewardConfig) -> jnp.ndarray:
    """Metres of sole below the next tread + clearance_target, over the swing feet facing a
    riser: a foot carried low into a step nose (what stubs it) costs, a foot lifted first does
    not; flat ground and the way down (no rise ahead) cost nothing."""
    riser = q.ground_ahead_of_foot - q.ground_under_foot > c.clearance_step
    deficit = jnp.clip(q.ground_ahead_of_foot + c.clearance_target - q.sole_height, 0.0, None)
    return jnp.sum(jnp.where(riser & ~q.foot_contact, deficit, 0.0))


def lin_vel_z(q: Quantities, c: RewardConfig) -> jnp.ndarray:
    return jnp.square(q.lin_vel_body[2])


def ang_vel_xy(q: Quantities, c: RewardConfig) -> jnp.ndarray:
    return jnp.sum(jnp.square(q.ang_vel_body[:2]))


def roll(q: Quantities, c: RewardConfig) -> jnp.ndarray:
    """A stair's pitch is free: the body's sideways lean alone."""
    return jnp.square(q.gravity_body[1])


TERMS: dict[str, Callable[[Quantities, RewardConfig], jnp.ndarray]] = {
    f.__name__: f
    for f in (
        nav_coarse,
        nav_fine,
        heading,
        centreline,
        stall,
        movement,
        power,
        torque,
        action_rate,
        joint_pos_limit,
        joint_vel_limit,
        joint_vel,
        joint_acc,
        contact_trunk_thigh,
        contact_calf,
        overspeed,
        backward,
        feet_air_time,
        foot_clearance,
        lin_vel_z,
        ang_vel_xy,
        roll,
    )
}
"""All reward terms by name; each name is also a weight field of RewardConfig."""


def active_terms(config: RewardConfig) -> tuple[str, ...]:
    """Names of the terms with a non-zero weight."""
    return tuple(name for name in TERMS if getattr(config, name) != 0.0)


def compute(q: Quantities, config: RewardConfig, dt: float) -> tuple[jnp.ndarray, dict]:
    """Total reward and the weighted terms {name: [] value}, each already times weight * dt."""
    terms = {
        name: TERMS[name](q, config) * getattr(config, name) * dt for name in active_terms(config)
    }
    total = sum(terms.values()) if terms else jnp.zeros(())
    return total, terms


def feet_quantities(height: Callable, feet: jnp.ndarray, radius: jnp.ndarray, yaw: jnp.ndarray,
                    contact: jnp.ndarray, c: RewardConfig) -> dict[str, jnp.ndarray]:
    """The Quantities fields foot_clearance reads, from the foot spheres' centres `feet` [4, 3]
    (world), their radii [4], the base's heading and the feet's contacts [4]; zeros while its
    weight is 0 (no terrain lookups)."""
    if c.foot_clearance == 0.0:
        zero = jnp.zeros(4)
        return dict(foot_contact=jnp.zeros(4, bool), sole_height=zero, ground_under_foot=zero,
                    ground_ahead_of_foot=zero)
    x, y = feet[:, 0], feet[:, 1]
    ax, ay = c.clearance_ahead * jnp.cos(yaw), c.clearance_ahead * jnp.sin(yaw)
    return dict(foot_contact=contact, sole_height=feet[:, 2] - radius,
                ground_under_foot=height(x, y), ground_ahead_of_foot=height(x + ax, y + ay))


def centreline_geometry(
    point: jnp.ndarray, line: jnp.ndarray, cumulative: jnp.ndarray
) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Planar distance of `point` to a polyline and the arc length of its projection.

    Args:
      point: [2] xy.
      line: [K, 2] polyline xy (padding points repeat the last point: zero-length segments).
      cumulative: [K] arc length at each polyline point.
    Returns:
      (distance [], arc length of the closest point [])
    """
    a, b = line[:-1], line[1:]
    ab = b - a
    len2 = jnp.sum(ab * ab, axis=-1)
    t = jnp.clip(jnp.sum((point - a) * ab, axis=-1) / jnp.maximum(len2, 1e-12), 0.0, 1.0)
    closest = a + t[:, None] * ab
    dist = jnp.linalg.norm(point - closest, axis=-1)
    i = jnp.argmin(dist)
    arc = cumulative[i] + t[i] * jnp.sqrt(len2[i])
    return dist[i], arc
