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
    [n, 2] the world xy of each tile's first and last grid point (what the height map reads);
    floor / top [n] the lower and higher of the tile's start and goal floor heights; width [n]
    the stair's clear width (0 where the atlas does not know it); down [n] walked down.
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
        self.down = jnp.asarray(np.asarray(atlas.direction) == 1)
        ends = np.stack([atlas.floor_height, atlas.goal_height]).astype(np.float32)
        self.floor, self.top = jnp.asarray(ends.min(0)), jnp.asarray(ends.max(0))
        width = getattr(atlas, "width", None)
        self.width = jnp.asarray(np.zeros(len(ends[0])) if width is None else width, jnp.float32)

    def centreline(self, tile: int) -> np.ndarray:
        """[K, 2] the tile's centre-line (x, y), on the host."""
        return np.asarray(self.line[tile])

    def waypoint(self, pos: jnp.ndarray, tile: jnp.ndarray, lookahead: float,
                 arc: jnp.ndarray | None = None, heading: str = "ahead") -> jnp.ndarray:
        """(x, y, z, yaw): the point `lookahead` m further along the tile's centre-line than
        pos's projection on it (arc length `arc`, when the caller has it), with the line's
        heading there (`heading` "ahead"; "here": at the projection; "chord": from the projection
        to the point); the tile's goal once that is nearer along the line than `lookahead`."""
        return waypoint_on(pos, self.line3[tile], self.line_cum[tile], self.goal[tile],
                           lookahead, arc, heading)


def _segment(cum: jnp.ndarray, s: jnp.ndarray) -> jnp.ndarray:
    """The index of the segment holding arc length s: the last i with cum[i] <= s, clipped to
    [0, K - 2] (a repeated point's zero-length segment is skipped)."""
    return jnp.clip(jnp.searchsorted(cum, s, side="right") - 1, 0, cum.shape[0] - 2)


def waypoint_on(pos: jnp.ndarray, line3: jnp.ndarray, cum: jnp.ndarray, goal: jnp.ndarray,
                lookahead: float, arc: jnp.ndarray | None = None,
                heading: str = "ahead") -> jnp.ndarray:
    """(x, y, z, yaw): the waypoint of TileTables.waypoint on any route, line3 [K, 3] with arc
    lengths cum [K] (its length cum[-1]), ending at goal [4]."""
    total = cum[-1]
    if arc is None:
        _, arc = rw.centreline_geometry(pos[:2], line3[:, :2], cum)
    s = arc + lookahead
    i = _segment(cum, s)
    seg = line3[i + 1] - line3[i]
    seg_len = cum[i + 1] - cum[i]
    t = jnp.clip((s - cum[i]) / jnp.maximum(seg_len, 1e-6), 0.0, 1.0)
    point = line3[i] + t * seg
    if heading != "ahead":  # the yaw from where the robot's projection is
        j = _segment(cum, arc)
        seg = line3[j + 1] - line3[j]  # "here": the segment it is on
        if heading == "chord":  # from the projection itself to the point
            f = jnp.clip((arc - cum[j]) / jnp.maximum(cum[j + 1] - cum[j], 1e-6), 0.0, 1.0)
            seg = point - (line3[j] + f * seg)
    yaw = jnp.arctan2(seg[1], seg[0])
    waypoint = jnp.concatenate([point, yaw[None]])
    return jnp.where(s >= total, goal, waypoint)
