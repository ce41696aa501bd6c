"""Rotations, headings and terrain sampling, shared by the env (jnp, traced) and the tools
(numpy, on the host: pass ``xp=np``).

Quaternions are (w, x, y, z), MuJoCo's order; yaw is the heading about the world z axis.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax.numpy as jnp


def quat_to_mat(q: jnp.ndarray, xp: Any = jnp) -> jnp.ndarray:
    """[4] (w, x, y, z) -> [3, 3] rotation matrix (body -> world)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    return xp.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def mat_yaw(rot: jnp.ndarray, xp: Any = jnp) -> jnp.ndarray:
    """Heading of a [3, 3] body -> world rotation: the yaw of its x axis."""
    return xp.arctan2(rot[1, 0], rot[0, 0])


def quat_yaw(q: jnp.ndarray, xp: Any = jnp) -> jnp.ndarray:
    """Heading of a (w, x, y, z) quaternion (= mat_yaw(quat_to_mat(q)))."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    return xp.arctan2(2 * (x * y + w * z), 1 - 2 * (y * y + z * z))


def yaw_quat(yaw: jnp.ndarray, xp: Any = jnp) -> jnp.ndarray:
    """[4] quaternion of a rotation by `yaw` about z."""
    return xp.array([xp.cos(yaw / 2), 0.0, 0.0, xp.sin(yaw / 2)])


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


class Kinematics(NamedTuple):
    """The base's pose and velocities, computed once per step from qpos [19] / qvel [18]."""

    pos: jnp.ndarray  # [3] world
    rot: jnp.ndarray  # [3, 3] body -> world
    yaw: jnp.ndarray  # []
    lin_vel_body: jnp.ndarray  # [3]
    gravity_body: jnp.ndarray  # [3] unit gravity in the body frame


def base_kinematics(qpos: jnp.ndarray, qvel: jnp.ndarray) -> Kinematics:
    rot = quat_to_mat(qpos[3:7])
    return Kinematics(qpos[:3], rot, mat_yaw(rot), rot.T @ qvel[:3],
                      rot.T @ jnp.array([0.0, 0.0, -1.0]))
