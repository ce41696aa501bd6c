"""A height grid as axis-aligned boxes: vertical risers and sharp edges, for MuJoCo itself.

The heightfield the trainer collides with interpolates between grid points, so a riser is a
slope one cell wide. The ground truth (and the sim-to-sim runner) instead stand the robot on
boxes: every grid point owns the square cell around it (half a resolution each way) and becomes a
column from a common bottom up to its height; equal-height neighbours merge into one box. A
riser then stands vertically half-way between the last low point and the first high one, where
the heightfield's slope passes mid-height, and every tread keeps its true height.

A tile from a generator and a mesh ray-cast by ``terrains.mesh_import`` both arrive here as a
height grid, so this is the one place both become boxes.

Frame: x forward, y left, z up, metres; ``heights[iy, ix]`` is at (x0 + ix * res, y0 + iy * res).
"""

from __future__ import annotations

import numpy as np

BOTTOM_DEPTH = 0.5
"""m: the boxes reach this far below the lowest height of the grid (as a heightfield's base)."""


def grid_boxes(
    heights: np.ndarray,
    resolution: float,
    origin: tuple[float, float] = (0.0, 0.0),
    quantum: float = 1e-4,
) -> np.ndarray:
    """Boxes that cover a height grid: [M, 6] (cx, cy, cz, hx, hy, hz), centre and half-sizes.

    Args:
      heights: [ny, nx] terrain heights (m) at (x0 + ix * res, y0 + iy * res).
      resolution: grid spacing (m).
      origin: (x0, y0), world position of heights[0, 0].
      quantum: heights closer than this (m) are the same level and merge.

    Cells of equal height merge greedily: runs along x within a row, then identical runs of
    consecutive rows into one box. The boxes' union is exactly the column of every cell.
    """
    h = np.asarray(heights, np.float64)
    if h.ndim != 2 or min(h.shape) < 1:
        raise ValueError(f"heights must be a 2-D grid, got shape {h.shape}")
    if not np.all(np.isfinite(h)):
        raise ValueError("heights contain NaN or infinite values")
    if not resolution > 0:
        raise ValueError(f"resolution must be > 0, got {resolution}")
    level = np.round(h / quantum).astype(np.int64)
    bottom = float(h.min()) - BOTTOM_DEPTH
    ny, nx = level.shape
    open_runs: dict[tuple[int, int, int], int] = {}  # (x0, x1, level) -> first row
    boxes: list[tuple[int, int, int, int, int]] = []  # (x0, x1, y0, y1, level), [x0, x1)

    def row_runs(row: np.ndarray) -> list[tuple[int, int, int]]:
        cuts = np.flatnonzero(np.diff(row)) + 1
        starts = np.concatenate([[0], cuts])
        ends = np.concatenate([cuts, [nx]])
        return [(int(a), int(b), int(row[a])) for a, b in zip(starts, ends, strict=True)]

    for iy in range(ny):
        runs = set(row_runs(level[iy]))
        for run in [r for r in open_runs if r not in runs]:  # runs that end below this row
            boxes.append((run[0], run[1], open_runs.pop(run), iy, run[2]))
        for run in runs:
            open_runs.setdefault(run, iy)
    for run, y0 in open_runs.items():
        boxes.append((run[0], run[1], y0, ny, run[2]))

    return _centred(np.array(boxes, np.float64).reshape(-1, 5), resolution, origin, quantum,
                    bottom)


def _centred(b: np.ndarray, resolution: float, origin: tuple[float, float], quantum: float,
             bottom: float) -> np.ndarray:
    """Grid boxes ``b`` [M, 5] (x0, x1, y0, y1, level; [x0, x1) in cells) as [M, 6] (cx, cy, cz,
    hx, hy, hz) in metres from ``bottom`` up to level * quantum, sorted by y then x."""
    x0, y0 = origin
    lo_x = x0 + (b[:, 0] - 0.5) * resolution
    hi_x = x0 + (b[:, 1] - 0.5) * resolution
    lo_y = y0 + (b[:, 2] - 0.5) * resolution
    hi_y = y0 + (b[:, 3] - 0.5) * resolution
    top = b[:, 4] * quantum
    out = np.stack(
        [
            0.5 * (lo_x + hi_x),
            0.5 * (lo_y + hi_y),
            0.5 * (top + bottom),
            0.5 * (hi_x - lo_x),
            0.5 * (hi_y - lo_y),
            0.5 * (top - bottom),
        ],
        axis=-1,
    )
    return out[np.lexsort((out[:, 0], out[:, 1]))]


def box_top_height(
    boxes: np.ndarray, x: np.ndarray, y: np.ndarray, default: float = -np.inf
) -> np.ndarray:
    """The highest box top over each (x, y): what a ray cast straight down would hit. [...]"""
    x, y = np.broadcast_arrays(np.asarray(x, np.float64), np.asarray(y, np.float64))
    out = np.full(x.shape, default)
    for cx, cy, cz, hx, hy, hz in boxes:
        inside = (np.abs(x - cx) <= hx) & (np.abs(y - cy) <= hy)
        out = np.where(inside, np.maximum(out, cz + hz), out)
    return out
