"""The Atlas: a grid of tiles (rows = levels, columns = variants of one or more families) merged
into one heightfield with a flat border, plus per-tile tables in the WORLD frame.

World frame: the atlas corner point is (0, 0); ``heights[iy, ix]`` is at (ix * res, iy * res).
Tile t = row * cols + col has its corner at (border + col * tile_size, border + row * tile_size),
i.e. at grid index (round(origin / res)); its [n, n] points follow from there.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .families import FAMILIES, make_tile, variants
from .levels import check_family, check_landing
from .levels import levels as level_table
from .tile import (
    CENTRELINE_POINTS,
    DEFAULT_RESOLUTION,
    DEFAULT_TILE_SIZE,
    Tile,
    atomic_savez,
    load_npz,
    pad_tile,
)

_TABLES = ("origin", "spawn", "goal", "centreline", "level", "family", "variant",
           "floor_height", "goal_height", "direction", "width")
_LATER = {"direction": np.int32, "width": np.float32}  # tables that older files may lack
ATLAS_DIRECTIONS = ("up", "down", "both")


@dataclass(eq=False)
class Atlas:
    """Tiles merged into one heightfield.

    heights:      [NY, NX] float32, m, whole atlas including the border; the atlas corner point
                  is world (0, 0).
    resolution:   m between points.  tile_size: m.  border: flat border (height 0) around, m.
    rows, cols:   rows = levels, cols = variants (families side by side).
    families:     family names; ``family`` indexes into it.
    schedule:     level schedule the rows come from.  level_ids: [rows] 0-based level per row.
    Per tile t = row * cols + col, WORLD frame:
    origin [n, 2] tile corner xy; spawn [n, 7]; goal [n, 4]; centreline [n, K, 3];
    level [n] int32 (0-based); family [n] int32; variant [n] int32 (index into the family's
    variants); floor_height [n] float32; goal_height [n] float32.
    direction [n] int32: 0 = up (spawn at the foot), 1 = down (spawn on the top landing).
    width [n] float32: the stair's clear width (m; the tile spec's "width", 0 where it has none).
    variant_names: per family, the names its variant ids refer to.
    """

    heights: np.ndarray
    resolution: float
    tile_size: float
    border: float
    rows: int
    cols: int
    families: tuple[str, ...]
    origin: np.ndarray
    spawn: np.ndarray
    goal: np.ndarray
    centreline: np.ndarray
    level: np.ndarray
    family: np.ndarray
    variant: np.ndarray
    floor_height: np.ndarray
    goal_height: np.ndarray
    direction: np.ndarray = None  # type: ignore[assignment]
    width: np.ndarray = None  # type: ignore[assignment]
    schedule: str = "train"
    variant_names: tuple[tuple[str, ...], ...] = ()

    def __post_init__(self):
        for key, dtype in _LATER.items():
            if getattr(self, key) is None:
                setattr(self, key, np.zeros(len(self.level), dtype))

    @property
    def num_tiles(self) -> int:
        return self.rows * self.cols

    @property
    def tile_points(self) -> int:
        """Grid points per tile side, tile_size / resolution."""
        return int(round(self.tile_size / self.resolution))

    def tile_heights(self, t: int) -> np.ndarray:
        """[n, n] view of tile ``t``'s heights inside the atlas."""
        ix, iy = np.round(self.origin[t] / self.resolution).astype(int)
        n = self.tile_points
        return self.heights[iy:iy + n, ix:ix + n]

    def save(self, path: str | os.PathLike) -> None:
        """Write one .npz atomically (temporary file, then os.replace)."""
        meta = dict(resolution=self.resolution, tile_size=self.tile_size, border=self.border,
                    rows=self.rows, cols=self.cols, families=list(self.families),
                    schedule=self.schedule, variant_names=[list(v) for v in self.variant_names])
        atomic_savez(path, kind=np.array("atlas"), heights=self.heights,
                     meta=np.array(json.dumps(meta)),
                     **{k: getattr(self, k) for k in _TABLES})

    @classmethod
    def load(cls, path: str | os.PathLike) -> Atlas:
        """Read an atlas written by save(); missing file -> FileNotFoundError, anything
        unreadable -> one-line ValueError naming the file."""
        data = load_npz(path, "atlas", ("heights", "meta")
                        + tuple(k for k in _TABLES if k not in _LATER))
        for key, dtype in _LATER.items():   # saved before the table existed: "up", width 0
            if key not in data:
                data[key] = np.zeros(len(data["level"]), dtype)
        try:
            m = json.loads(str(data["meta"]))
            atlas = cls(heights=data["heights"], resolution=float(m["resolution"]),
                        tile_size=float(m["tile_size"]), border=float(m["border"]),
                        rows=int(m["rows"]), cols=int(m["cols"]),
                        families=tuple(m["families"]), schedule=str(m["schedule"]),
                        variant_names=tuple(tuple(v) for v in m["variant_names"]),
                        **{k: data[k] for k in _TABLES})
        except (KeyError, ValueError, TypeError) as e:
            raise ValueError(f"{path}: corrupt atlas file ({e})") from None
        n = atlas.num_tiles
        if atlas.heights.ndim != 2 or any(len(data[k]) != n for k in _TABLES):
            raise ValueError(f"{path}: corrupt atlas file (tables do not match {n} tiles)")
        return atlas


def build_atlas(families: Sequence[str], schedule: str = "train",
                levels: Sequence[int] | None = None, variants_per_family: int = 2,
                resolution: float = DEFAULT_RESOLUTION, tile_size: float = DEFAULT_TILE_SIZE,
                border: float = 2.0, direction: str = "up", seed: int = 0,
                building_landing: Sequence[float] | None = None) -> Atlas:
    """Tiles of ``families`` (0-based ``levels`` of ``schedule``, default all) in a grid:
    row = level, columns = for each family ``variants_per_family`` tiles cycling through its
    variants. heights [NY, NX] with NX = (2 border + cols tile_size) / res + 1.

    direction: "up", "down" (every tile walked down: same heights, spawn on the top landing),
    or "both": each column is followed by the same tile walked down (twice the columns; the
    heights are copied, so an env can pick a direction by picking a column).
    seed: the building family samples a staircase per tile from (schedule, level, variant,
    seed + k), k = how many times the column cycle has passed the variant (so repeated
    variants in a row are different staircases); the other families ignore it.
    building_landing: (lo, hi) m, one landing-depth range for every building level instead of
    the level's own (None: the levels'); the other families ignore it."""
    families = tuple(families)
    if not families:
        raise ValueError("build_atlas needs at least one family")
    for f in families:
        check_family(f)
    if variants_per_family < 1:
        raise ValueError(f"variants_per_family must be >= 1, got {variants_per_family}")
    _check_border(border, resolution)
    if building_landing is not None:
        building_landing = check_landing(building_landing)
    if direction not in ATLAS_DIRECTIONS:
        raise ValueError(f"unknown direction {direction!r}; known: {', '.join(ATLAS_DIRECTIONS)}")
    dirs = ("up", "down") if direction == "both" else (direction,)
    sizes = {len(level_table(f, schedule)) for f in families}
    if levels is None:
        if len(sizes) != 1:
            raise ValueError(f"families {families} have different level counts in {schedule!r}; "
                             f"pass levels=")
        levels = list(range(sizes.pop()))
    levels = [int(v) for v in levels]
    if not levels:
        raise ValueError("build_atlas needs at least one level")
    cols = len(families) * variants_per_family * len(dirs)

    def row_tiles(lvl: int):
        for col in range(cols):
            k, di = divmod(col, len(dirs))
            fi, vi = divmod(k, variants_per_family)
            fam = families[fi]
            names = variants(fam)
            cycle, vi = divmod(vi, len(names))
            if di == 0:
                tile = make_tile(fam, lvl, names[vi], schedule, resolution, tile_size,
                                 direction=dirs[0], seed=seed + cycle,
                                 building_landing=building_landing)
            else:
                tile = tile.reversed()
            yield tile, fi, vi

    return _assemble([list(row_tiles(lvl)) for lvl in levels], resolution, tile_size, border,
                     families=families, schedule=schedule,
                     variant_names=tuple(variants(f) for f in families))


def build_cell_atlas(cells: Sequence[tuple[str, str, int]], variants_per_cell: int = 2,
                     resolution: float = DEFAULT_RESOLUTION, tile_size: float = DEFAULT_TILE_SIZE,
                     border: float = 2.0) -> Atlas:
    """Any list of (family, schedule, 0-based level) cells, one row each, in one atlas: row r
    holds ``variants_per_cell`` variants of cell r. The atlas has one family, "cells" (index 0),
    so a robot of row r is placed with ``level=r, family=0``; ``level`` keeps each tile's own
    0-based level in its schedule. For evaluating many cells under one compiled program."""
    if not cells:
        raise ValueError("build_cell_atlas needs at least one cell")
    _check_border(border, resolution)
    grid = []
    for fam, schedule, lvl in cells:
        check_family(fam)
        names = variants(fam)
        grid.append([(make_tile(fam, int(lvl), names[c % len(names)], schedule, resolution,
                                tile_size), 0, c % len(names)) for c in range(variants_per_cell)])
    return _assemble(grid, resolution, tile_size, border, families=("cells",), schedule="cells",
                     variant_names=(tuple(f"v{c}" for c in range(variants_per_cell)),))


def build_tile_atlas(rows: Sequence[Sequence[Tile]], border: float = 2.0,
                     points: int | None = None) -> Atlas:
    """Any tiles, one row of the atlas per entry of ``rows`` (equal lengths), of one resolution
    but of any sizes: every tile is padded with wall to the largest (or to ``points`` points a
    side; tile.pad_tile), so a staircase bigger than the usual tile is not cropped. One family,
    "tiles" (index 0): a robot of row r is placed with ``level=r, family=0``."""
    rows = [list(r) for r in rows]
    if not rows or not rows[0] or len({len(r) for r in rows}) != 1:
        raise ValueError("build_tile_atlas needs rows of tiles of equal, non-zero lengths")
    resolution = float(rows[0][0].resolution)
    if any(abs(t.resolution - resolution) > 1e-9 for r in rows for t in r):
        raise ValueError("build_tile_atlas: the tiles have different resolutions")
    _check_border(border, resolution)
    n = max(max(t.heights.shape) for r in rows for t in r) if points is None else int(points)
    grid = [[(pad_tile(t, n), 0, c) for c, t in enumerate(r)] for r in rows]
    return _assemble(grid, resolution, n * resolution, border, families=("tiles",),
                     schedule="tiles", variant_names=(tuple(f"v{c}" for c in
                                                            range(len(rows[0]))),))


def _check_border(border: float, resolution: float) -> None:
    if border < 0:
        raise ValueError(f"border must be >= 0, got {border}")
    if abs(round(border / resolution) * resolution - border) > 1e-6 * max(border, 1.0):
        raise ValueError(f"border {border} m must be a whole multiple of the resolution "
                         f"{resolution} m")


def _assemble(grid: list[list[tuple[Tile, int, int]]], resolution: float, tile_size: float,
              border: float, **meta) -> Atlas:
    """The Atlas of ``grid[row][col] = (tile, family index, variant index)`` with a flat
    border; ``meta``: families, schedule, variant_names."""
    n = int(round(tile_size / resolution))
    b = int(round(border / resolution))
    rows, cols = len(grid), len(grid[0])
    heights = np.zeros((2 * b + rows * n + 1, 2 * b + cols * n + 1), np.float32)
    tabs = {k: [] for k in _TABLES}
    for row, tiles in enumerate(grid):
        for col, (tile, fi, vi) in enumerate(tiles):
            iy, ix = b + row * n, b + col * n
            heights[iy:iy + n, ix:ix + n] = tile.heights
            _append(tabs, tile, np.array([ix, iy]) * resolution, fi, vi)
    return Atlas(heights=heights, resolution=resolution, tile_size=tile_size, border=border,
                 rows=rows, cols=cols, **meta,
                 **{k: np.asarray(v, _dtype(k)) for k, v in tabs.items()})


def _dtype(key: str):
    return np.int32 if key in ("level", "family", "variant", "direction") else np.float32


def join_columns(atlases: Sequence[Atlas]) -> Atlas:
    """Atlases of the same rows, grid, tile size, border and schedule side by side (the first's
    columns, then the second's, ...), as one atlas: for families with different numbers of
    columns (build_atlas gives every family the same). Each family may appear in one only."""
    a0 = atlases[0]
    families = tuple(f for a in atlases for f in a.families)
    if len(set(families)) != len(families):
        raise ValueError(f"join_columns: a family appears in two atlases: {families}")
    for a in atlases:
        if (a.rows, a.resolution, a.tile_size, a.border, a.schedule) != (
                a0.rows, a0.resolution, a0.tile_size, a0.border, a0.schedule):
            raise ValueError("join_columns: the atlases differ in rows, resolution, tile size, "
                             f"border or schedule ({a.families} against {a0.families})")
    n, b = a0.tile_points, int(round(a0.border / a0.resolution))
    cols = sum(a.cols for a in atlases)
    heights = np.zeros((2 * b + a0.rows * n + 1, 2 * b + cols * n + 1), np.float32)
    parts, col0, fam0 = [], 0, 0
    for a in atlases:
        heights[b:b + a.rows * n, b + col0 * n:b + (col0 + a.cols) * n] = \
            a.heights[b:b + a.rows * n, b:b + a.cols * n]
        parts.append(_shifted_tables(a, col0 * a0.tile_size, fam0))
        col0, fam0 = col0 + a.cols, fam0 + len(a.families)
    tabs = {k: np.concatenate([p[k].reshape(a0.rows, a.cols, *p[k].shape[1:])
                               for p, a in zip(parts, atlases, strict=True)], axis=1)
            .reshape(a0.rows * cols, *parts[0][k].shape[1:]) for k in _TABLES}
    return Atlas(heights=heights, resolution=a0.resolution, tile_size=a0.tile_size,
                 border=a0.border, rows=a0.rows, cols=cols, families=families,
                 schedule=a0.schedule,
                 variant_names=tuple(v for a in atlases for v in a.variant_names), **tabs)


def _shifted_tables(a: Atlas, dx: float, fam0: int) -> dict[str, np.ndarray]:
    """``a``'s tables moved ``dx`` m along x, family indices counted from ``fam0``."""
    out = {k: np.array(getattr(a, k)) for k in _TABLES}
    for k in ("origin", "spawn", "goal"):
        out[k][:, 0] += np.float32(dx)
    out["centreline"][..., 0] += np.float32(dx)
    out["family"] += fam0
    return out


def _append(tabs: dict, tile: Tile, origin: np.ndarray, fi: int, vi: int) -> None:
    """Add ``tile``'s tables, shifted by ``origin`` [2] to the world frame."""
    spawn, goal, line = tile.spawn.copy(), tile.goal.copy(), tile.centreline.copy()
    spawn[:2] += origin
    goal[:2] += origin
    line[:, :2] += origin
    assert line.shape == (CENTRELINE_POINTS, 3)
    tabs["origin"].append(origin)
    tabs["spawn"].append(spawn)
    tabs["goal"].append(goal)
    tabs["centreline"].append(line)
    tabs["level"].append(tile.level)
    tabs["family"].append(fi)
    tabs["variant"].append(vi)
    tabs["floor_height"].append(tile.floor_height)
    tabs["goal_height"].append(tile.goal_height)
    tabs["direction"].append(0 if tile.direction == "up" else 1)
    tabs["width"].append(float(tile.spec.get("width", 0.0) or 0.0))


__all__ = ["Atlas", "build_atlas", "build_cell_atlas", "build_tile_atlas", "join_columns",
           "FAMILIES"]
