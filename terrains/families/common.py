"""What every stair family shares: painting regions into a grid, centring the staircase in the
tile, applying the variant (mirror / half turn) and finishing the Tile.

A family describes its staircase in a canonical frame as a ``Layout``: walkable regions painted in
order (later ones win), everything left unpainted is wall. ``build_tile`` centres the walkable
bounding box in the tile, maps the variant, evaluates the regions at the grid points, raises the
walls to WALL_RISE above the highest walking surface and quantises every height.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..path import Arc, Line, Segment, resample
from ..tile import (
    CENTRELINE_POINTS,
    SPAWN_MARGIN,
    WALL_RISE,
    Tile,
    quantise,
    sample_heights,
)

EPS = 1e-7
MIN_WALL = 0.2        # m, thinnest wall: the divider of a U and the tile's outer walls
START_LENGTH = 1.5    # m, start floor in front of the first riser
TOP_LENGTH = 1.5      # m, top landing behind the last riser
MAX_RESOLUTION = 0.1  # m, coarser grids cannot draw 0.2 m walls two points thick

# A region maps canonical coordinates X, Y ([ny, nx] each) to (mask [ny, nx] bool, heights).
Region = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


def rect(x0: float, x1: float, y0: float, y1: float, z: float) -> Region:
    """Flat rectangle [x0, x1) x [y0, y1) at height z."""
    def region(X, Y):
        m = (X >= x0 - EPS) & (X < x1 - EPS) & (Y >= y0 - EPS) & (Y < y1 - EPS)
        return m, np.full(X.shape, z)
    return region


def flight(axis: int, lo: float, n: int, riser: float, tread: float, c0: float, c1: float,
           base: float, ascending: int = 1) -> Region:
    """The n-1 treads of a flight of n risers along ``axis`` (0: x, 1: y), covering
    [lo, lo + (n-1) tread) along it and [c0, c1) across. ascending=+1: riser k (1..n) at
    lo + (k-1) tread going up in +axis, the floor before lo is at ``base`` and the landing after at
    base + n riser. ascending=-1: risers go up toward -axis; the landing before lo is at
    base + n riser, the floor after lo + (n-1) tread at ``base``."""
    hi = lo + (n - 1) * tread

    def region(X, Y):
        u, v = (X, Y) if axis == 0 else (Y, X)
        m = (u >= lo - EPS) & (u < hi - EPS) & (v >= c0 - EPS) & (v < c1 - EPS)
        j = np.clip(np.floor((u - lo) / tread + 1e-6), 0, n - 2)
        k = j + 1 if ascending > 0 else n - 1 - j
        return m, base + k * riser
    return region


def sector_flight(centre: tuple[float, float], r_in: float, r_out: float, n: int, riser: float,
                  dtheta: float, base: float) -> Region:
    """Spiral flight counter-clockwise from angle 0: riser k (1..n) on the radial line at angle
    (k-1) dtheta, the n-1 treads between r_in and r_out; landing beyond (n-1) dtheta (< pi)."""
    sweep = (n - 1) * dtheta

    def region(X, Y):
        dx, dy = X - centre[0], Y - centre[1]
        r = np.hypot(dx, dy)
        th = np.arctan2(dy, dx)
        m = (r >= r_in - EPS) & (r < r_out - EPS) & (th >= -EPS) & (th < sweep - EPS)
        j = np.clip(np.floor(th / dtheta + 1e-6), 0, n - 2)
        return m, base + (j + 1) * riser
    return region


def rotated_rect(origin: tuple[float, float], u: tuple[float, float], a0: float, a1: float,
                 b0: float, b1: float, z: float) -> Region:
    """Flat rectangle in the frame (origin, u, u rotated +90 deg): a in [a0, a1) along u,
    b in [b0, b1) along the perpendicular, at height z."""
    ux, uy = u

    def region(X, Y):
        dx, dy = X - origin[0], Y - origin[1]
        a = dx * ux + dy * uy
        b = -dx * uy + dy * ux
        m = (a >= a0 - EPS) & (a < a1 - EPS) & (b >= b0 - EPS) & (b < b1 - EPS)
        return m, np.full(X.shape, z)
    return region


@dataclass
class Layout:
    """A staircase in its canonical frame (metres, any origin).

    regions:     walkable regions, painted in order.
    outline:     [m, 2] points whose bounding box is the walkable area (centred in the tile).
    spawn_rect:  (x0, x1, y0, y1) start floor; the spawn area is it shrunk by SPAWN_MARGIN.
    spawn_yaw:   heading toward the stairs, rad.
    goal:        (x, y, yaw) on the top landing.
    path:        centre-line segments from the spawn centre to the goal.
    floor_height, goal_height: m.
    flights:     dicts describing each flight (canonical frame), see tile.spec["flights"].
    spec:        dimensions for tile.spec.
    top_rect:    (x0, x1, y0, y1) the flat top landing, axis-aligned, or None; the spawn area of
                 the descending tile is it shrunk by SPAWN_MARGIN (None: searched on the grid).
    """

    regions: list[Region]
    outline: np.ndarray
    spawn_rect: tuple[float, float, float, float]
    spawn_yaw: float
    goal: tuple[float, float, float]
    path: list[Segment]
    floor_height: float
    goal_height: float
    flights: list[dict] = field(default_factory=list)
    spec: dict = field(default_factory=dict)
    spawn_yaw_half_range: float = np.pi / 4
    top_rect: tuple[float, float, float, float] | None = None


# ------------------------------------------------------------------ variant transforms
# Every transform is its own inverse: "mirror" flips y about the tile centre, "turn" rotates
# half a turn about it.
def _map_xy(x, y, how: str, size: float):
    if how == "mirror":
        return x, size - y
    if how == "turn":
        return size - x, size - y
    return x, y


def _map_dir(dx, dy, how: str):
    if how == "mirror":
        return dx, -dy
    if how == "turn":
        return -dx, -dy
    return dx, dy


def _map_yaw(yaw: float, how: str) -> float:
    if how == "mirror":
        yaw = -yaw
    elif how == "turn":
        yaw = yaw + np.pi
    return float(np.arctan2(np.sin(yaw), np.cos(yaw)))


def footprint(layout: Layout, resolution: float) -> float:
    """Side (m) of the smallest square tile that holds ``layout`` and its walls."""
    lo, hi = layout.outline.min(0), layout.outline.max(0)
    return float((hi - lo).max()) + 2 * max(MIN_WALL, 2 * resolution)


def check_grid(resolution: float, tile_size: float) -> int:
    """Validate resolution and tile size; returns points per side, round(tile_size/resolution)."""
    if not (0 < resolution <= MAX_RESOLUTION):
        raise ValueError(f"resolution must be in (0, {MAX_RESOLUTION}] m, got {resolution}")
    n = int(round(tile_size / resolution))
    if n < 8 or abs(n * resolution - tile_size) > 1e-6 * tile_size:
        raise ValueError(f"tile_size {tile_size} m must be a whole multiple (>= 8) of the "
                         f"resolution {resolution} m")
    return n


def build_tile(layout: Layout, how: str, family: str, level: int, variant: str,
               resolution: float, tile_size: float) -> Tile:
    """Centre ``layout`` in a square tile, apply variant transform ``how`` ("", "mirror", "turn")
    and paint it: [n, n] heights, walls at WALL_RISE above the highest walking point."""
    n = check_grid(resolution, tile_size)
    lo, hi = layout.outline.min(0), layout.outline.max(0)
    need = footprint(layout, resolution)
    if need > tile_size + 1e-9:
        raise ValueError(f"{family} level {level + 1} does not fit a {tile_size} m tile: it needs "
                         f"{need:.2f} m (staircase plus walls); use a larger tile_size")
    off = tile_size / 2 - (lo + hi) / 2  # canonical -> centred

    g = np.arange(n) * resolution
    GX, GY = np.meshgrid(g, g)                       # tile-frame grid points, [n, n]
    QX, QY = _map_xy(GX, GY, how, tile_size)         # centred canonical frame
    X, Y = QX - off[0], QY - off[1]                  # canonical frame
    heights = np.zeros((n, n))
    walk = np.zeros((n, n), bool)
    for region in layout.regions:
        m, h = region(X, Y)
        heights[m] = np.broadcast_to(h, m.shape)[m]
        walk |= m
    top = heights[walk].max() if walk.any() else 0.0
    heights[~walk] = top + WALL_RISE
    heights = quantise(heights)

    def to_tile(p):  # [m, 2] canonical -> tile frame
        q = np.asarray(p, float) + off
        x, y = _map_xy(q[..., 0], q[..., 1], how, tile_size)
        return np.stack([x, y], -1)

    x0, x1, y0, y1 = layout.spawn_rect
    corners = to_tile(np.array([[x0, y0], [x1, y1]]))
    cx, cy = corners.mean(0)
    half_x = (x1 - x0) / 2 - SPAWN_MARGIN
    half_y = (y1 - y0) / 2 - SPAWN_MARGIN
    if min(half_x, half_y) <= 0:
        raise ValueError(f"{family} level {level + 1}: start floor {x1 - x0:.2f} x {y1 - y0:.2f} m "
                         f"too small for a spawn area with {SPAWN_MARGIN} m margins")
    spawn = np.array([cx, cy, layout.floor_height, half_x, half_y,
                      _map_yaw(layout.spawn_yaw, how), layout.spawn_yaw_half_range], np.float32)
    gx, gy = to_tile(np.array([layout.goal[:2]]))[0]
    goal = np.array([gx, gy, layout.goal_height, _map_yaw(layout.goal[2], how)], np.float32)

    xy = to_tile(resample(layout.path, CENTRELINE_POINTS))
    z = sample_heights(heights, resolution, xy[:, 0], xy[:, 1])
    centreline = np.concatenate([xy, z[:, None]], 1).astype(np.float32)

    flights = [_map_flight(f, to_tile, how) for f in layout.flights]
    spec = dict(layout.spec, flights=flights, wall_height=float(top + WALL_RISE),
                tile_size=tile_size)
    if layout.top_rect is not None:   # spawn area of the descending tile: [x, y, half_x, half_y]
        x0, x1, y0, y1 = layout.top_rect
        c = to_tile(np.array([[x0, y0], [x1, y1]]))
        spec["top_spawn"] = [float(v) for v in (*c.mean(0), (x1 - x0) / 2 - SPAWN_MARGIN,
                                                (y1 - y0) / 2 - SPAWN_MARGIN)]
    return Tile(heights=heights, resolution=resolution, spawn=spawn, goal=goal,
                centreline=centreline, floor_height=float(layout.floor_height),
                goal_height=float(layout.goal_height), family=family, level=level,
                variant=variant, walls=~walk, spec=spec)


def _map_flight(f: dict, to_tile, how: str) -> dict:
    """A flight description mapped to the tile frame (points through to_tile, directions and
    sweep direction through the transform)."""
    out = dict(f)
    for key in ("start", "centre"):
        if key in f:
            out[key] = [float(v) for v in to_tile(np.array([f[key]]))[0]]
    for key in ("dir", "open_dir"):
        if key in f:
            out[key] = [float(v) for v in _map_dir(*f[key], how)]
    if "theta0" in f:  # arc: angles about the centre
        th0, sweep = f["theta0"], f["sweep"]
        if how == "mirror":
            th0, sweep = -th0, -sweep
        elif how == "turn":
            th0 = th0 + np.pi
        out["theta0"], out["sweep"] = float(th0), float(sweep)
    if "walk" in f:  # angles of the walking line's ends on the arc
        sign, shift = (-1.0, 0.0) if how == "mirror" else (1.0, np.pi if how == "turn" else 0.0)
        out["walk"] = [float(sign * a + shift) for a in f["walk"]]
    return out


def line(p0, p1) -> Line:
    return Line(tuple(map(float, p0)), tuple(map(float, p1)))


def arc(centre, radius, theta0, theta1) -> Arc:
    return Arc(tuple(map(float, centre)), float(radius), float(theta0), float(theta1))
