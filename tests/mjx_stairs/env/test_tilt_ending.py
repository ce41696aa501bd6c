"""The `tilt` ending's upright (endings.slope_along, endings.upright, EnvConfig.tilt_slope_m):
the world's vertical, or the normal of the terrain's slope along the heading, so that a robot
climbing a steep stair nose up is not read as fallen while one tipped off the slope still is."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from mjx_stairs.env import endings

RISER, TREAD = 0.197, 0.254  # a residential-code stair (37.8 deg), rising along +x from x = 0
PITCH = np.arctan2(RISER, TREAD)
MAX_TILT = 1.0  # rad, EnvConfig's


def stair(x, y):
    """Heights of the stair (numpy or jnp arrays): flat floor before x = 0, then 16 steps."""
    xp = jnp if isinstance(x, jnp.ndarray) else np
    return RISER * xp.clip(xp.floor(x / TREAD) + 1, 0, 16) * (x >= 0) + 0.0 * y


def body_z(pitch_up: float, yaw: float) -> np.ndarray:
    """The body's z axis (world frame) of a base pitched `pitch_up` rad nose up, heading `yaw`."""
    return np.array([-np.sin(pitch_up) * np.cos(yaw), -np.sin(pitch_up) * np.sin(yaw),
                     np.cos(pitch_up)])


@pytest.mark.parametrize("yaw, sign", [(0.0, 1.0), (np.pi, -1.0)])  # climbing, descending
def test_the_fitted_slope_is_the_stairs_pitch_inside_the_flight(yaw, sign):
    xs = np.linspace(1.0, 3.0, 201)
    slope = endings.slope_along(stair, xs, np.zeros_like(xs), np.full_like(xs, yaw), 0.8, xp=np)
    assert np.all(np.abs(slope - sign * PITCH) < np.radians(8))  # a sawtooth over 3 treads
    assert abs(np.mean(slope) - sign * PITCH) < np.radians(2)
    floor = endings.slope_along(stair, -xs, np.zeros_like(xs), np.full_like(xs, yaw), 0.8, xp=np)
    np.testing.assert_allclose(floor, 0.0, atol=1e-12)
    np.testing.assert_array_equal(endings.slope_along(stair, xs, xs, xs, 0.0, xp=np), 0.0)


def test_a_climber_nose_up_on_the_stair_is_upright_a_robot_tipped_off_it_is_not():
    cos_max = np.cos(MAX_TILT)
    x = np.array([2.0])
    climbing = endings.slope_along(stair, x, 0 * x, 0 * x, 0.8, xp=np)
    # 65 deg nose up climbing a 37.8 deg stair: tilted from the world's vertical, not the stair's
    up = endings.upright(body_z(np.radians(65), 0.0), 0.0, climbing, xp=np)
    assert body_z(np.radians(65), 0.0)[2] < cos_max < up[0]
    # the same pitch on the floor, or facing down the same stair: tilted by both rules
    assert endings.upright(body_z(np.radians(65), 0.0), 0.0, 0.0, xp=np) < cos_max
    descending = endings.slope_along(stair, x, 0 * x, x * 0 + np.pi, 0.8, xp=np)
    assert endings.upright(body_z(np.radians(65), np.pi), np.pi, descending, xp=np)[0] < cos_max
    # rolled 60 deg on the stair: tilted by both rules (the slope tips the normal forward only)
    rolled = np.array([0.0, -np.sin(np.radians(60)), np.cos(np.radians(60))])
    assert endings.upright(rolled, 0.0, climbing, xp=np)[0] < cos_max
    # with slope 0 the rule is the world's: the body's z axis's world z
    rng = np.random.default_rng(0)
    z = rng.normal(size=(32, 3))
    z /= np.linalg.norm(z, axis=1, keepdims=True)
    np.testing.assert_allclose(endings.upright(z, rng.uniform(-3, 3, 32), 0.0, xp=np), z[:, 2])


def test_device_and_host_give_the_same_upright():
    rng = np.random.default_rng(1)
    x, y, yaw = rng.uniform(-1, 4, 64), rng.uniform(-1, 1, 64), rng.uniform(-np.pi, np.pi, 64)
    z = rng.normal(size=(64, 3))
    z /= np.linalg.norm(z, axis=1, keepdims=True)
    host = endings.upright(z, yaw, endings.slope_along(stair, x, y, yaw, 0.8, xp=np), xp=np)
    j = [jnp.asarray(a, jnp.float32) for a in (x, y, yaw, z)]
    device = endings.upright(j[3], j[2], endings.slope_along(stair, j[0], j[1], j[2], 0.8))
    np.testing.assert_allclose(np.asarray(device), host, atol=1e-5)
