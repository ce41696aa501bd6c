"""The per-tile tables of an atlas on the device: spawn areas, goals, centre-lines, waypoints."""

from __future__ import annotations

from typing import Any

import jax.numpy as jnp
import numpy as np

from mjx_stairs.env import rewards as rw


class TileTables:
    """n = tiles, K = centre-line points per tile (row-major over the atlas's levels x variants).

    spawn [n, 7] (x, y, z, half x, half y, yaw, yaw half-range), goal [n, 4] (x, y, z, yaw),
    line3 [n, K, 3] / line [n, K, 2] the centre-lines, line_cum [n, K] arc length at each point,
    line_len [n] total length; origin [n, 2] (host) the tiles' lower-left corners; lo / hi
    [n, 2] the world xy of each tile's first and last grid point (what the height map reads).
    """

    def __init__(self, atlas: Any):
        self.spawn = jnp.asarray(atlas.spawn, jnp.float32)
        self.goal = jnp.asarray(atlas.goal, jnp.float32)
        line3 = np.asarray(atlas.centreline, np.float32)
        seg = np.linalg.norm(np.diff(line3[..., :2], axis=1), axis=-1)
        cumulative = np.concatenate([np.zeros_like(seg[:, :1]), np.cumsum(seg, axis=1)], axis=1)
        self.line3 = jnp.asarray(line3)  # waypoints take their z from it
        self.line = self.line3[..., :2]
        self.line_cum = jnp.asarray(cumulative, jnp.float32)
        self.line_len = jnp.asarray(cumulative[:, -1], jnp.float32)
        self.origin = np.asarray(atlas.origin, np.float32)
        # The height map reads only the robot's own tile: what lies past a tile's edge in an
        # atlas (a neighbour's floor behind a thin wall, a border) is no part of that staircase.
        res = float(atlas.resolution)
        extent = (int(round(atlas.tile_size / res)) - 1) * res
        self.lo = jnp.asarray(self.origin)
        self.hi = jnp.asarray(self.origin + np.float32(extent))
        self.level = jnp.asarray(atlas.level, jnp.int32)
        self.family = jnp.asarray(atlas.family, jnp.int32)

    def centreline(self, tile: int) -> np.ndarray:
        """[K, 2] the tile's centre-line (x, y), on the host."""
        return np.asarray(self.line[tile])

    def waypoint(self, pos: jnp.ndarray, tile: jnp.ndarray, lookahead: float,
                 arc: jnp.ndarray | None = None) -> jnp.ndarray:
        """(x, y, z, yaw): the point `lookahead` m further along the tile's centre-line than
        pos's projection on it (arc length `arc`, when the caller has it), with the line's
        heading there; the tile's goal once that is nearer along the line than `lookahead`."""
        goal = self.goal[tile]
        line, cum, total = self.line3[tile], self.line_cum[tile], self.line_len[tile]
        if arc is None:
            _, arc = rw.centreline_geometry(pos[:2], self.line[tile], cum)
        s = arc + lookahead
        i = jnp.clip(jnp.searchsorted(cum, s, side="right") - 1, 0, cum.shape[0] - 2)
        seg = line[i + 1] - line[i]
        seg_len = cum[i + 1] - cum[i]
        t = jnp.clip((s - cum[i]) / jnp.maximum(seg_len, 1e-6), 0.0, 1.0)
        point = line[i] + t * seg
        yaw = jnp.arctan2(seg[1], seg[0])
        waypoint = jnp.concatenate([point, yaw[None]])
        return jnp.where(s >= total, goal, waypoint)
