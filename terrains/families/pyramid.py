"""Stage-1 inverted pyramid: the robot starts LOW on the middle platform and climbs out over
square rings of steps to the high outer border. No walls.

Rings of tread ``level.tread`` around a 3.0 m platform; as many risers as leave a border of at
least 1.5 m (7 risers and a 1.7 m border on a 10 m tile at 0.30 m treads).
Variants = the goal's direction: "+x", "-x", "+y", "-y"; the goal sits mid-border.
"""

from __future__ import annotations

import numpy as np

from ..levels import Level
from ..path import Line, resample
from ..tile import CENTRELINE_POINTS, SPAWN_MARGIN, Tile, quantise, sample_heights
from .common import check_grid

VARIANTS = ("+x", "-x", "+y", "-y")
PLATFORM = 3.0
MIN_BORDER = 1.5
_DIRS = {"+x": (1.0, 0.0), "-x": (-1.0, 0.0), "+y": (0.0, 1.0), "-y": (0.0, -1.0)}


def make(lv: Level, level: int, variant: str, resolution: float, tile_size: float,
         family: str = "pyramid") -> Tile:
    """[n, n] tile, n = tile_size / resolution; platform at height 0 centred at tile_size / 2.
    ``family``: the name the tile carries (``pyramid_tall`` reuses this generator)."""
    n = check_grid(resolution, tile_size)
    half, t, r = tile_size / 2, lv.tread, lv.riser
    steps = int(np.floor((half - PLATFORM / 2 - MIN_BORDER) / t + 1e-9)) + 1
    if steps < 1:
        raise ValueError(f"pyramid level {level + 1} does not fit a {tile_size} m tile: needs "
                         f"{PLATFORM + 2 * MIN_BORDER:.2f} m at least")
    g = np.arange(n) * resolution
    GX, GY = np.meshgrid(g, g)
    d = np.maximum(np.abs(GX - half), np.abs(GY - half))  # Chebyshev distance from the centre
    k = np.clip(np.floor((d - PLATFORM / 2) / t + 1e-6) + 1, 0, steps)
    heights = quantise(k * r)
    top = steps * r
    last = PLATFORM / 2 + (steps - 1) * t           # distance of the last riser
    reach = (last + half) / 2                       # goal: mid-border
    dx, dy = _DIRS[variant]
    gx, gy = half + dx * reach, half + dy * reach
    yaw = float(np.arctan2(dy, dx))
    ph = PLATFORM / 2 - SPAWN_MARGIN
    spawn = np.array([half, half, 0.0, ph, ph, yaw, np.pi], np.float32)
    xy = resample([Line((half, half), (gx, gy))], CENTRELINE_POINTS)
    z = sample_heights(heights, resolution, xy[:, 0], xy[:, 1])
    spec = dict(riser=r, tread=t, steps=steps, platform=PLATFORM, border=half - last,
                total_rise=top, tile_size=tile_size, wall_height=None,
                flights=[dict(kind="straight", start=[half + dx * PLATFORM / 2,
                                                      half + dy * PLATFORM / 2],
                              dir=[dx, dy], n=steps, base=0.0, width=PLATFORM)])
    return Tile(heights=heights, resolution=resolution, spawn=spawn,
                goal=np.array([gx, gy, top, yaw], np.float32),
                centreline=np.concatenate([xy, z[:, None]], 1), floor_height=0.0,
                goal_height=float(quantise(top)), family=family, level=level,
                variant=variant, walls=np.zeros_like(heights, bool), spec=spec)
