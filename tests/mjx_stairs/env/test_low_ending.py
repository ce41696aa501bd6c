"""The `low` ending's "terrain under the base" (endings.ground_under, EnvConfig.low_line_m): the
point under the base, or the mean along the heading, which follows a stair's slope."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from mjx_stairs.env import endings

RISER, TREAD = 0.178, 0.28  # a commercial-code stair, rising along +x from x = 0


def stair(x, y):
    """Heights of the stair (numpy or jnp arrays): flat floor before x = 0, then steps."""
    xp = jnp if isinstance(x, jnp.ndarray) else np
    return RISER * xp.clip(xp.floor(x / TREAD) + 1, 0, 12) * (x >= 0) + 0.0 * y


def clearance(length: float, yaw: float, xs: np.ndarray, lift: float = 0.25) -> np.ndarray:
    """Base z minus the ground under it, for bases held `lift` above the stair's slope."""
    z = RISER / TREAD * xs + lift
    ground = endings.ground_under(stair, xs, np.zeros_like(xs), np.full_like(xs, yaw), length,
                                  xp=np)
    return z - ground


@pytest.mark.parametrize("yaw", [0.0, np.pi])  # climbing, descending
def test_the_line_rule_follows_the_slope_where_the_point_rule_jumps_a_riser(yaw):
    xs = np.linspace(1.0, 2.5, 301)  # well inside the flight
    point, line = clearance(0.0, yaw, xs), clearance(0.3, yaw, xs)
    assert np.ptp(point) > 0.9 * RISER  # the sawtooth: a whole riser at every nose
    assert np.ptp(line) < 0.4 * RISER  # 5 points 7.5 cm apart on a 28 cm tread
    # a base 0.25 m above the slope dips 0.07 m over the point under it before every nose
    assert point.min() < 0.12 < line.min()


def test_on_flat_ground_and_along_a_step_both_rules_agree():
    xs = np.linspace(-3.0, -0.3, 50)  # the floor before the stair
    np.testing.assert_allclose(clearance(0.3, 0.7, xs), clearance(0.0, 0.7, xs), atol=1e-12)
    on_tread = np.full(20, 1.0 * TREAD + 0.14)  # mid-tread, side-on: the line lies on one step
    np.testing.assert_allclose(clearance(0.3, np.pi / 2, on_tread),
                               clearance(0.0, np.pi / 2, on_tread), atol=1e-12)


def test_device_and_host_give_the_same_ground():
    rng = np.random.default_rng(0)
    x, y, yaw = rng.uniform(-1, 3, 64), rng.uniform(-1, 1, 64), rng.uniform(-np.pi, np.pi, 64)
    host = endings.ground_under(stair, x, y, yaw, 0.3, xp=np)
    device = endings.ground_under(stair, jnp.asarray(x), jnp.asarray(y), jnp.asarray(yaw), 0.3)
    np.testing.assert_allclose(np.asarray(device), host, atol=1e-5)
    assert endings.ground_under(stair, x, y, yaw, 0.0, xp=np) == pytest.approx(stair(x, y))
