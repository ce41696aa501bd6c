"""Per-episode goals drawn on the staircase (env.goal_draw, issue 21): the authors' stage-2
goal, not only the top landing.

The authors' Isaac Lab code draws each episode's goal uniformly from "flat patches" of the
robot's own tile lying 0.2-10 m above its ground, so a goal can sit on any raised step, landing
or flight (near goals as well as far ones), with a yaw drawn in [-pi, pi], and in 5 % of
episodes the goal is the spawn pose itself (reference/authors_code.md, section 1). Here the goal
is a point of the tile's centre-line at an arc length drawn uniformly over the part of the line
that lies at least `min_rise` above the tile's floor, at the terrain height there (the
convention of the tiles' own goals); the yaw is uniform in [-pi, pi] or the line's heading.

Off by default (env.goal_draw.enabled = false): the episode holds no goal and every reader
uses the tile's goal, as before. When on, info["goal"] [4] (x, y, z, yaw) and info["goal_arc"]
[] (its arc length along the centre-line) hold the episode's goal; evaluation turns it off
(env.config.evaluation_config), so tests always use the tiles' goals.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from mjx_stairs.env.config import EnvConfig
from mjx_stairs.env.tiles import TileTables, waypoint_on


def active(config: EnvConfig) -> bool:
    return config.goal_draw.enabled


def goal_of(info: dict, tiles: TileTables) -> jnp.ndarray:
    """[4] the episode's goal (x, y, z, yaw): the drawn one when info holds it, else the
    tile's."""
    return info["goal"] if "goal" in info else tiles.goal[info["tile"]]


def along_line(info: dict, tiles: TileTables, arc: jnp.ndarray) -> jnp.ndarray:
    """[] the distance along the tile's centre-line from arc length `arc` to the episode's goal
    (the path term of the centre-line reward): to the line's end for the tile's own goal."""
    if "goal_arc" in info:
        return jnp.abs(info["goal_arc"] - arc)
    return jnp.maximum(tiles.line_len[info["tile"]] - arc, 0.0)


def draw(rng: jax.Array, tiles: TileTables, tile: jnp.ndarray, spawn_xy: jnp.ndarray,
         spawn_yaw: jnp.ndarray, config: EnvConfig) -> dict[str, jnp.ndarray]:
    """This episode's goal on ``tile`` for a robot spawned at (spawn_xy, spawn_yaw):
    {"goal" [4], "goal_arc" []} when configured, else {}."""
    if not active(config):
        return {}
    gc = config.goal_draw
    k = jax.random.split(jax.random.fold_in(rng, 7), 3)
    line3, cum = tiles.line3[tile], tiles.line_cum[tile]
    raised = line3[:, 2] >= tiles.floor[tile] + gc.min_rise
    # uniform over [first, last] raised arc length
    lo = jnp.min(jnp.where(raised, cum, cum[-1]))
    hi = jnp.max(jnp.where(raised, cum, lo))
    s = lo + jax.random.uniform(k[0]) * (hi - lo)
    # the point at s with the line's heading there (the tile's goal at the line's end, also
    # when the staircase never rises that far)
    on_line = waypoint_on(None, line3, cum, tiles.goal[tile], 0.0, arc=s)
    yaw = jnp.where(gc.random_yaw, jax.random.uniform(k[1], minval=-jnp.pi, maxval=jnp.pi),
                    on_line[3])
    drawn = jnp.where(s >= cum[-1], on_line, on_line.at[3].set(yaw))
    # The stationary goal: the spawn pose itself, on the tile's floor at the spawn.
    spawn_z = tiles.spawn[tile, 2]
    stay = jax.random.uniform(k[2]) < gc.stationary_prob
    still = jnp.concatenate([spawn_xy, spawn_z[None], jnp.asarray(spawn_yaw)[None]])
    goal = jnp.where(stay, still, drawn).astype(tiles.goal.dtype)
    arc = jnp.where(stay, 0.0, s).astype(cum.dtype)
    return {"goal": goal, "goal_arc": arc}
