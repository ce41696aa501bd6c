"""A height grid as axis-aligned boxes: vertical risers and sharp edges, for MuJoCo itself.

The heightfield the trainer collides with interpolates between grid points, so a riser is a
slope one cell wide. The ground truth (and the sim-to-sim runner) instead stand the robot on
boxes: every grid point owns the square cell around it (half a resolution each way) and becomes a
column from a common bottom up to its height; equal-height neighbours merge into one box. A
riser then stands vertically half-way between the last low point and the first high one, where
the heightfield's slope passes mid-height, and every tread keeps its true height.

Thin boxes get a wide box under them. A riser that is not along x or y (a spiral's, a curved
wall) cuts its treads into strips one cell wide. A foot sphere that lands fast sinks its centre
below a tread's top for a step or two (it does on the heightfield too), and inside a strip
narrower than a foot the nearest face is the cut between two strips of one tread, not the top:
MuJoCo pushes the sphere sideways from both strips and never up, so the foot sinks into the
tread and sticks there (the ground truth counted 90 % falls on spiral tiles where the MJX
evaluation has ~95 % success). So a box narrower than ``MIN_WIDTH`` in y (then in x) gets
a copy extended that way over every neighbouring row (column) whose cells under it all stand at
least as high, its top ``UNDER_TOP`` below the strip's: a sunk foot meets that wide box's top
and is pushed up. The copy never rises above a cell it covers, so the union is unchanged, and
lying under the tops it leaves a foot standing on a tread (mm deep) one contact per box it
stands on, as before. Grids whose treads are rectangles (straight, L- and U-shaped tiles) have
no thin box.

Every other box gets one too (``supports="all"``, the default). The same sinking happens at any
seam between boxes, not only among strips: a foot that lands fast against a riser, or between
two boxes of one tread, ends with its centre inside one box next to its side face and inside the
solid of the other, and the two boxes push it sideways against each other and never up (issue
19, experiments/gt_sunk_feet.py, 192 robots of stage2_u: 11, 16 and 11 robots held a foot over 1
cm inside the steps for 5 to 964 policy steps on U-shaped extended L3, L4 and straight extended
L4, almost all of them robots that fell; with supports, none longer than 4). So under every box
lies a copy ``UNDER_TOP`` below its top, grown over the neighbouring rows, then columns, that
stand at least as high (under the treads above it and the walls); a sunk foot is inside that
copy well away from its sides and is pushed up. A wide box's copy is also ``UNDER_TOP`` narrower
on every side, so that a foot or knee touching a riser meets the riser's box alone, one contact
as before (a thin box's copy, on spiral tiles, keeps its sides). ``supports="thin"`` is the
earlier builder.

A tile from a generator and a mesh ray-cast by ``terrains.mesh_import`` both arrive here as a
height grid, so this is the one place both become boxes.

Frame: x forward, y left, z up, metres; ``heights[iy, ix]`` is at (x0 + ix * res, y0 + iy * res).
"""

from __future__ import annotations

import numpy as np

BOTTOM_DEPTH = 0.5
"""m: the boxes reach this far below the lowest height of the grid (as a heightfield's base)."""

MIN_WIDTH = 0.1
"""m: boxes narrower than this in y or x get a wide box under them (module docstring); over four
foot radii (0.022 m), 4 cells at 0.025 m."""

UNDER_TOP = 0.01
"""m: how far under the thin box's top its wide box's top lies: below a standing foot's
penetration (mm), above a sunk foot's (the foot radius, 0.022 m)."""


def grid_boxes(
    heights: np.ndarray,
    resolution: float,
    origin: tuple[float, float] = (0.0, 0.0),
    quantum: float = 1e-4,
    supports: str = "all",
) -> np.ndarray:
    """Boxes that cover a height grid: [M, 6] (cx, cy, cz, hx, hy, hz), centre and half-sizes.

    Args:
      heights: [ny, nx] terrain heights (m) at (x0 + ix * res, y0 + iy * res).
      resolution: grid spacing (m).
      origin: (x0, y0), world position of heights[0, 0].
      quantum: heights closer than this (m) are the same level and merge.
      supports: "all" (every box gets a support copy under it) or "thin" (only boxes narrower
        than MIN_WIDTH, the builder of 9f67b4d); module docstring.

    Cells of equal height merge greedily: runs along x within a row, then identical runs of
    consecutive rows into one box. Under each box (``supports``), a wide box UNDER_TOP lower over
    the neighbouring cells at least as high (module docstring). The boxes' union is exactly the
    column of every cell.
    """
    h = np.asarray(heights, np.float64)
    if h.ndim != 2 or min(h.shape) < 1:
        raise ValueError(f"heights must be a 2-D grid, got shape {h.shape}")
    if not np.all(np.isfinite(h)):
        raise ValueError("heights contain NaN or infinite values")
    if not resolution > 0:
        raise ValueError(f"resolution must be > 0, got {resolution}")
    if supports not in ("all", "thin"):
        raise ValueError(f"supports must be 'all' or 'thin', got {supports!r}")
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

    thin = int(np.ceil(MIN_WIDTH / resolution - 1e-9))  # cells: narrower is fewer
    grown = _with_supports(boxes, level, thin, int(round(UNDER_TOP / quantum)), supports == "all")
    return _centred(np.array(grown, np.float64).reshape(-1, 6), resolution, origin, quantum,
                    bottom)


def _extent(fits: np.ndarray, lo: int, hi: int) -> tuple[int, int]:
    """[lo, hi) widened both ways over the consecutive True entries of ``fits`` around it."""
    while lo > 0 and fits[lo - 1]:
        lo -= 1
    while hi < fits.size and fits[hi]:
        hi += 1
    return lo, hi


def _with_supports(boxes: list[tuple[int, int, int, int, int]], level: np.ndarray,
                min_cells: int, sink: int, every: bool = False) -> list[tuple[int, ...]]:
    """``boxes`` (x0, x1, y0, y1, level) as (..., 0) and, under each one narrower than
    ``min_cells`` in y (then x), or under every box if ``every``, a copy ``sink`` levels lower
    grown over the rows (columns) whose cells under it all stand at least as high, as
    (x0, x1, y0, y1, level, inset) with inset 1 for a wide box's copy (its sides drawn in by
    UNDER_TOP), 0 for a thin one's; copies that grew nowhere or lie inside another copy
    dropped."""
    under = []
    for x0, x1, y0, y1, lv in boxes:
        box = (x0, x1, y0, y1)
        thin = y1 - y0 < min_cells or x1 - x0 < min_cells
        if not (thin or every):
            continue
        if y1 - y0 < min_cells or not thin:
            y0, y1 = _extent(level[:, x0:x1].min(1) >= lv, y0, y1)
        if x1 - x0 < min_cells or not thin:
            x0, x1 = _extent(level[y0:y1, :].min(0) >= lv, x0, x1)
        if (x0, x1, y0, y1) != box:
            under.append((x0, x1, y0, y1, lv - sink, 0 if thin else 1))
    plain = [(*b, 0) for b in boxes]
    if not under:
        return plain
    u = np.unique(np.array(under, np.int64), axis=0)
    keep = np.ones(len(u), bool)
    for i0 in range(0, len(u), 256):  # [i, j]: copy i inside another copy j, 256 rows at a time
        c = u[i0 : i0 + 256, None]
        inside = ((u[None, :, 0] <= c[..., 0]) & (u[None, :, 1] >= c[..., 1])
                  & (u[None, :, 2] <= c[..., 2]) & (u[None, :, 3] >= c[..., 3])
                  & (u[None, :, 4] >= c[..., 4]) & (u[None, :, 5] <= c[..., 5]))
        inside[np.arange(len(c)), i0 + np.arange(len(c))] = False
        keep[i0 : i0 + 256] = ~inside.any(1)
    return plain + [tuple(int(v) for v in row) for row in u[keep]]


def _centred(b: np.ndarray, resolution: float, origin: tuple[float, float], quantum: float,
             bottom: float) -> np.ndarray:
    """Grid boxes ``b`` [M, 6] (x0, x1, y0, y1, level, inset; [x0, x1) in cells) as [M, 6]
    (cx, cy, cz, hx, hy, hz) in metres from ``bottom`` up to level * quantum, sides drawn in by
    inset * UNDER_TOP, sorted by y then x."""
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
            0.5 * (hi_x - lo_x) - b[:, 5] * UNDER_TOP,
            0.5 * (hi_y - lo_y) - b[:, 5] * UNDER_TOP,
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
