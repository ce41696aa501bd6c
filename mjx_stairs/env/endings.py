"""How a step ends an episode (success, falls, leaving the atlas, trunk contact, timeout) and
the metrics every step reports."""

from __future__ import annotations

from typing import Callable, NamedTuple

import jax.numpy as jnp
import numpy as np

from mjx_stairs.env import rewards as rw
from mjx_stairs.env.config import EnvConfig
from mjx_stairs.env.geometry import Kinematics

STEP_METRICS = ("done", "episode_success", "terminated", "truncated", "nan_reset",
                "trunk_termination", "tilt_termination", "low_termination",
                "outside_termination", "level", "at_top", "goal_distance", "moved_up")
"""The metrics of every step besides `reward/<term>` (means over robots in the trainer's log)."""

DOWN_METRICS = ("done_down", "episode_success_down")
"""More metrics on an atlas walked both ways: episodes that ended walking down, and their
successes (the trainer logs success_down from them)."""


LINE_POINTS = 5
"""Points on the segment along the heading that the `low` ending averages the terrain over."""


def ground_under(height: Callable, x, y, yaw, length: float, xp=jnp):
    """[...] "the terrain under the base" of the `low` ending for bases at (x, y) with heading
    `yaw` [...] (EnvConfig.low_line_m): ``height(x, y)`` there for length 0, else its mean at
    LINE_POINTS points spaced evenly on a `length` segment along the heading, centred on (x, y).
    ``xp``: jnp, or numpy for host arrays."""
    if length <= 0:
        return height(x, y)
    t = np.linspace(-length / 2, length / 2, LINE_POINTS)
    c, s = xp.cos(yaw)[..., None], xp.sin(yaw)[..., None]
    return height(x[..., None] + t * c, y[..., None] + t * s).mean(-1)


SLOPE_POINTS = 9
"""Points on the segment along the heading that the `tilt` ending fits the slope to."""


def slope_along(height: Callable, x, y, yaw, length: float, xp=jnp):
    """[...] the terrain's slope angle (rad, rising ahead > 0) along heading `yaw` at (x, y)
    [...] (EnvConfig.tilt_slope_m): the least-squares line through the terrain height at
    SLOPE_POINTS points spaced evenly on a `length` segment centred there; 0 for length 0."""
    if length <= 0:
        return xp.zeros_like(x)
    t = np.linspace(-length / 2, length / 2, SLOPE_POINTS)
    c, s = xp.cos(yaw)[..., None], xp.sin(yaw)[..., None]
    h = height(x[..., None] + t * c, y[..., None] + t * s)
    return xp.arctan(((h - h.mean(-1, keepdims=True)) * t).sum(-1) / float((t * t).sum()))


def upright(body_z, yaw, slope, xp=jnp):
    """[...] cos of the angle between the body's z axis `body_z` [..., 3] (world frame) and the
    normal of a terrain rising at `slope` rad along heading `yaw`: the world's vertical tipped
    back by `slope` about the axis across the heading. The `tilt` ending fires when it is under
    cos(max_tilt); with slope 0 it is body_z's world z, the world-vertical rule."""
    ss = xp.sin(slope)
    return (-ss * xp.cos(yaw) * body_z[..., 0] - ss * xp.sin(yaw) * body_z[..., 1]
            + xp.cos(slope) * body_z[..., 2])


class Endings(NamedTuple):
    """How the step ended the episode ([] each); `done` = terminated | truncated."""

    success: jnp.ndarray
    success_count: jnp.ndarray
    tilted: jnp.ndarray
    too_low: jnp.ndarray
    fell: jnp.ndarray
    outside: jnp.ndarray
    trunk_hit: jnp.ndarray
    terminated: jnp.ndarray
    truncated: jnp.ndarray
    done: jnp.ndarray


def endings(c: EnvConfig, kin: Kinematics, q: rw.Quantities, info: dict, finite: jnp.ndarray,
            base_clearance: jnp.ndarray, world_size: tuple[float, float], hold_steps: int,
            episode_steps: int, slope: jnp.ndarray | float = 0.0) -> Endings:
    """Success (close and slow, held for `hold_steps`), terminations and the timeout. A robot
    whose physics blew up (not `finite`) is terminated. `slope`: the terrain's slope along the
    heading that the tilt is read against (slope_along; 0: the world's vertical)."""
    close = (q.planar_goal_distance < c.success_distance) & (q.planar_speed < c.success_speed)
    success_count = jnp.where(close, info["success_count"] + 1, 0)
    success = jnp.maximum(info["success"], (success_count >= hold_steps).astype(jnp.float32))
    pos = kin.pos
    tilted = upright(kin.rot[:, 2], kin.yaw, slope) < jnp.cos(c.max_tilt)
    too_low = base_clearance < c.min_base_height
    fell = tilted | too_low
    outside = ((pos[0] < 0) | (pos[1] < 0) | (pos[0] > world_size[0])
               | (pos[1] > world_size[1]))
    trunk_hit = jnp.any(q.trunk_contacts) & c.terminate_on_trunk_contact
    terminated = fell | outside | trunk_hit | ~finite
    truncated = (info["step"] + 1 >= episode_steps) & ~terminated
    return Endings(success, success_count, tilted, too_low, fell, outside, trunk_hit,
                   terminated, truncated, terminated | truncated)


FAMILY_RATIOS = ("level", "at_top", "success")
"""Per family of an atlas of several, as `<ratio>/<family>#num` and `#den` (the trainer logs
num / den as `<ratio>/<family>`): the mean level and the share at the top level of the family's
robot-steps, and the success of its episodes that ended. The logged `level` mixes families whose
top levels differ (the paper families end at 12-15 cm risers, the building family at 21 cm)."""


CORNERS = {  # name: (damping range N m s/rad, action delay range s), both ends included
    "damping_low_delay_long": ((0.0, 0.3), (0.015, 1.0)),
    "damping_low_delay_none": ((0.0, 0.3), (0.0, 0.0)),
    "damping_high_delay_none": ((1.0, 1e9), (0.0, 0.0)),
}
"""Robots whose episode drew its joints' damping and action delay in these ranges, for the
success of their episodes as `success/<name>` (`#num` / `#den`) when training draws both: the
corner of damping 0.1 with 20 ms that the evaluation physics falls in (docs/results.md 8ac,
8ad), and the two ends without delay that a policy trained there loses."""


def corner_draws(info: dict, timestep: float) -> tuple[jnp.ndarray, jnp.ndarray] | None:
    """(joint damping [], action delay s []) this episode drew, read before an auto-reset
    replaces them; None unless both are drawn."""
    if "joint_damping" not in info or "delay_steps" not in info:
        return None
    return info["joint_damping"], info["delay_steps"] * timestep


def metric_names(reward_terms: tuple[str, ...], both_ways: bool = False,
                 families: tuple[str, ...] = (), corners: bool = False) -> tuple[str, ...]:
    """The keys of `state.metrics`: `reward/<term>` per active term, then STEP_METRICS (then
    DOWN_METRICS on an atlas walked both ways, then FAMILY_RATIOS' keys for `families` when
    there are several, then the CORNERS' success keys with `corners`)."""
    per_family = tuple(f"{r}/{f}#{part}" for f in families for r in FAMILY_RATIOS
                       for part in ("num", "den")) if len(families) > 1 else ()
    per_corner = tuple(f"success/{c}#{part}" for c in CORNERS for part in ("num", "den"))
    return (tuple(f"reward/{k}" for k in reward_terms) + STEP_METRICS
            + (DOWN_METRICS if both_ways else ()) + per_family + (per_corner if corners else ()))


def family_metrics(families: tuple[str, ...], family: jnp.ndarray, level: jnp.ndarray,
                   top_level: int, e: Endings,
                   drawn: tuple[jnp.ndarray, jnp.ndarray] | None = None) -> dict[str, jnp.ndarray]:
    """{FAMILY_RATIOS' `#num` / `#den` keys: []} of this step for a robot of family index
    `family` at `level` (before the auto-reset); none for an atlas of one family (metric_names).
    With `drawn` (corner_draws), the CORNERS' success keys too."""
    done, out = e.done.astype(jnp.float32), {}
    for i, name in enumerate(families if len(families) > 1 else ()):
        mine = (family == i).astype(jnp.float32)
        for ratio, num, den in (("level", level * mine, mine),
                                ("at_top", (level == top_level) * mine, mine),
                                ("success", e.success * done * mine, done * mine)):
            out[f"{ratio}/{name}#num"], out[f"{ratio}/{name}#den"] = num, den
    if drawn is None:
        return out
    damping, delay = drawn
    for name, ((d_lo, d_hi), (s_lo, s_hi)) in CORNERS.items():
        mine = ((damping >= d_lo) & (damping <= d_hi) & (delay >= s_lo - 1e-6)
                & (delay <= s_hi + 1e-6)).astype(jnp.float32)
        out[f"success/{name}#num"] = e.success * done * mine
        out[f"success/{name}#den"] = done * mine
    return out


def down_metrics(e: Endings, down: jnp.ndarray) -> dict[str, jnp.ndarray]:
    """{DOWN_METRICS: []} of this step for a robot whose episode walks down (`down`)."""
    ended = (e.done & down).astype(jnp.float32)
    return dict(zip(DOWN_METRICS, (ended, e.success * ended), strict=True))


def metrics(terms: dict, e: Endings, finite: jnp.ndarray, level: jnp.ndarray, top_level: int,
            goal_distance: jnp.ndarray, moved_up: jnp.ndarray) -> dict[str, jnp.ndarray]:
    """{metric: []} of this step, keyed by metric_names (level: before the auto-reset)."""
    f32 = lambda x: x.astype(jnp.float32)
    done = f32(e.done)
    values = (  # in STEP_METRICS order
        done, e.success * done, f32(e.terminated), f32(e.truncated), f32(~finite),
        f32(e.trunk_hit & ~e.fell), f32(e.tilted), f32(e.too_low & ~e.tilted),
        f32(e.outside & ~e.fell), f32(level), f32(level == top_level),
        goal_distance, f32(moved_up & e.done),
    )
    return {**{f"reward/{k}": v for k, v in terms.items()},
            **dict(zip(STEP_METRICS, values, strict=True))}
