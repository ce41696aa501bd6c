"""Measurements on a tile's height grid, independent of how the tile was built."""

from __future__ import annotations

import numpy as np

from terrains import HEIGHT_QUANTUM as Q

WALL_MIN_RISE = 0.5  # m, a wall must stand at least this much above its walking neighbour


def walkable(tile) -> np.ndarray:
    """[ny, nx] bool: points no higher than the goal landing (everything higher is wall)."""
    return tile.heights <= tile.goal_height + Q / 2


def nearest(tile, x, y) -> np.ndarray:
    """Heights of the grid points nearest to (x, y)."""
    ny, nx = tile.heights.shape
    ix = np.clip(np.round(np.asarray(x) / tile.resolution).astype(int), 0, nx - 1)
    iy = np.clip(np.round(np.asarray(y) / tile.resolution).astype(int), 0, ny - 1)
    return tile.heights[iy, ix].astype(np.float64)


def jumps(profile: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(indices, sizes) of the non-zero steps of a 1-D height profile."""
    d = np.diff(profile)
    idx = np.nonzero(np.abs(d) > Q / 2)[0]
    return idx, d[idx]


def straight_flight_profile(tile, flight: dict, pad: float = 0.4) -> tuple[np.ndarray, float]:
    """Heights on the grid line through an axis-aligned flight's middle, from ``pad`` before its
    first riser to ``pad`` after its last, in climbing order; returns (profile, spacing)."""
    res = tile.resolution
    (sx, sy), (dx, dy) = flight["start"], flight["dir"]
    length = (flight["n"] - 1) * tile.spec["tread"]
    s = np.arange(-pad, length + pad, res)
    return nearest(tile, sx + dx * s, sy + dy * s), res


def run_length_through(mask_line: np.ndarray, i: int) -> int:
    """Length of the run of True in a 1-D mask containing index i (0 if mask_line[i] is False)."""
    if not mask_line[i]:
        return 0
    lo = i
    while lo > 0 and mask_line[lo - 1]:
        lo -= 1
    hi = i
    while hi < len(mask_line) - 1 and mask_line[hi + 1]:
        hi += 1
    return hi - lo + 1


def flood(tile, max_step: float) -> np.ndarray:
    """[ny, nx] bool: points reachable from the spawn centre moving between 4-neighbours whose
    heights differ by at most ``max_step``."""
    h = tile.heights.astype(np.float64)
    iy = int(round(tile.spawn[1] / tile.resolution))
    ix = int(round(tile.spawn[0] / tile.resolution))
    seen = np.zeros(h.shape, bool)
    seen[iy, ix] = True
    ok_x = np.abs(np.diff(h, axis=1)) <= max_step   # [ny, nx-1] passable x edges
    ok_y = np.abs(np.diff(h, axis=0)) <= max_step   # [ny-1, nx]
    while True:
        new = seen.copy()
        new[:, 1:] |= seen[:, :-1] & ok_x
        new[:, :-1] |= seen[:, 1:] & ok_x
        new[1:, :] |= seen[:-1, :] & ok_y
        new[:-1, :] |= seen[1:, :] & ok_y
        if (new == seen).all():
            return seen
        seen = new
