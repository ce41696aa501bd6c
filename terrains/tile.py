"""The Tile: one staircase as a height grid plus spawn, goal and centre-line; the bilinear sampler.

Frame: x forward, y left, z up, metres. ``heights[iy, ix]`` is the terrain height at the grid
POINT (x0 + ix * res, y0 + iy * res); a tile's first point is its corner (x0 = y0 = 0 in the
tile frame).
"""

from __future__ import annotations

import json
import os
import tempfile
import zipfile
from dataclasses import dataclass, field, replace

import numpy as np

HEIGHT_QUANTUM = 0.001      # m; every height is a multiple of it (vertical geometry is exact)
CENTRELINE_POINTS = 64      # K: fixed length of every centre-line polyline
DEFAULT_RESOLUTION = 0.025  # m between grid points
DEFAULT_TILE_SIZE = 10.0    # m, side of a square tile
WALL_RISE = 0.8             # m, walls stand this much above the highest walking surface of a tile
SPAWN_MARGIN = 0.35         # m, spawn rectangle clearance from walls, risers and edges
GOAL_FLAT_RADIUS = 0.35     # m, the terrain is flat (goal height) within this radius of the goal
DIRECTIONS = ("up", "down")
MAX_SPAWN_HALF = 0.5        # m, largest half-size of a spawn square searched on the grid


def quantise(h: np.ndarray) -> np.ndarray:
    """Round heights to multiples of HEIGHT_QUANTUM; returns float32 of the same shape."""
    return (np.round(np.asarray(h, np.float64) / HEIGHT_QUANTUM) * HEIGHT_QUANTUM).astype(
        np.float32)


@dataclass(frozen=True, eq=False)
class Tile:
    """One terrain tile.

    heights:      [ny, nx] float32, m; heights[iy, ix] at (ix * res, iy * res) in the tile frame.
    resolution:   m between grid points.
    spawn:        [7] float32 (x, y, z_floor, half_dx, half_dy, yaw_centre, yaw_half_range): spawn
                  uniformly in the axis-aligned rectangle, yaw uniform in yaw_centre +- half range.
    goal:         [4] float32 (x, y, z, yaw), z = terrain height at the goal.
    centreline:   [K, 3] float32 polyline from the spawn centre to the goal, K = CENTRELINE_POINTS,
                  padded by repeating the goal point.
    floor_height: height of the start floor, m.
    goal_height:  height of the goal landing, m.
    family, level (0-based), variant: where the tile comes from.
    walls:        [ny, nx] bool, True on walls (not walkable).
    spec:         dict of the dimensions the tile was built from (riser, tread, width, steps, ...).
    direction:    "up" (spawn at the foot, goal on the top landing) or "down" (the same heights,
                  spawn on the top landing, goal at the foot, centre-line reversed): reversed().
    """

    heights: np.ndarray
    resolution: float
    spawn: np.ndarray
    goal: np.ndarray
    centreline: np.ndarray
    floor_height: float
    goal_height: float
    family: str
    level: int
    variant: str
    walls: np.ndarray = field(default=None)  # type: ignore[assignment]
    spec: dict = field(default_factory=dict)
    direction: str = "up"

    def __post_init__(self):
        if self.direction not in DIRECTIONS:
            raise ValueError(f"unknown direction {self.direction!r}; known: "
                             f"{', '.join(DIRECTIONS)}")
        h = np.asarray(self.heights, np.float32)
        if h.ndim != 2 or min(h.shape) < 2:
            raise ValueError(f"Tile.heights must be a 2-D grid of at least 2x2, got {h.shape}")
        object.__setattr__(self, "heights", h)
        walls = np.zeros(h.shape, bool) if self.walls is None else np.asarray(self.walls, bool)
        object.__setattr__(self, "walls", walls)
        shapes = (("spawn", (7,)), ("goal", (4,)), ("centreline", (CENTRELINE_POINTS, 3)))
        for name, shape in shapes:
            arr = np.asarray(getattr(self, name), np.float32)
            if arr.shape != shape:
                raise ValueError(f"Tile.{name} must have shape {shape}, got {arr.shape}")
            object.__setattr__(self, name, arr)

    @property
    def size(self) -> tuple[float, float]:
        """(size_x, size_y) in metres covered by the grid points' cells: n * resolution."""
        return self.heights.shape[1] * self.resolution, self.heights.shape[0] * self.resolution

    def height_at(self, x, y) -> np.ndarray:
        """Bilinear terrain height at tile-frame points x, y (any equal shapes)."""
        return sample_heights(self.heights, self.resolution, x, y)

    def reversed(self) -> Tile:
        """The same staircase walked the other way (same heights and walls): spawn where the goal
        was, facing back down (or up) the route; goal at the old spawn centre, facing away from
        the stairs; centre-line reversed. The spawn area is the flat landing around the old goal
        (``spec["top_spawn"]`` where the generator knows it, else the largest flat, wall-free
        square with SPAWN_MARGIN around the goal, up to MAX_SPAWN_HALF). Twice reversed is the
        tile itself (as long as the spawn area is what the generator recorded)."""
        spec = dict(self.spec)
        back = spec.pop("reverse_spawn", None)         # kept so that reversing twice round-trips
        if back is None:
            top = spec.get("top_spawn")
            if top is None:
                half = flat_half(self.heights, self.walls, self.resolution, self.goal[:2])
                top = [self.goal[0], self.goal[1], half, half]
            back = [float(top[0]), float(top[1]), float(top[2]), float(top[3])]
        x, y, z, hx, hy, yaw, yaw_half = (float(v) for v in self.spawn)
        spec["reverse_spawn"] = [x, y, hx, hy]
        gx, gy, gz, gyaw = (float(v) for v in self.goal)
        spawn = [back[0], back[1], gz, back[2], back[3], _wrap(gyaw + np.pi), yaw_half]
        goal = [x, y, self.floor_height, _wrap(yaw + np.pi)]
        line = self.centreline
        distinct = len(line) - _trailing_repeats(line)
        rev = line[:distinct][::-1]
        rev = np.concatenate([rev, np.repeat(rev[-1:], len(line) - distinct, 0)], 0)
        return Tile(heights=self.heights, resolution=self.resolution, spawn=spawn, goal=goal,
                    centreline=rev, floor_height=self.goal_height, goal_height=self.floor_height,
                    family=self.family, level=self.level, variant=self.variant, walls=self.walls,
                    spec=spec, direction="down" if self.direction == "up" else "up")

    def with_direction(self, direction: str) -> Tile:
        """This tile walked ``direction`` ("up" or "down")."""
        if direction not in DIRECTIONS:
            raise ValueError(f"unknown direction {direction!r}; known: {', '.join(DIRECTIONS)}")
        return self if direction == self.direction else self.reversed()

    # ------------------------------------------------------------------ persistence
    def save(self, path: str | os.PathLike) -> None:
        """Write the tile to one .npz (atomically: temporary file, then os.replace)."""
        meta = dict(resolution=self.resolution, floor_height=self.floor_height,
                    goal_height=self.goal_height, family=self.family, level=int(self.level),
                    variant=self.variant, spec=self.spec, direction=self.direction)
        atomic_savez(path, kind=np.array("tile"), heights=self.heights, spawn=self.spawn,
                     goal=self.goal, centreline=self.centreline, walls=self.walls,
                     meta=np.array(json.dumps(meta, default=_json_default)))

    @classmethod
    def load(cls, path: str | os.PathLike) -> Tile:
        """Read a tile written by save(); missing -> FileNotFoundError, corrupt -> ValueError."""
        data = load_npz(path, "tile", ("heights", "spawn", "goal", "centreline", "walls", "meta"))
        try:
            meta = json.loads(str(data["meta"]))
            return cls(heights=data["heights"], resolution=float(meta["resolution"]),
                       spawn=data["spawn"], goal=data["goal"], centreline=data["centreline"],
                       floor_height=float(meta["floor_height"]),
                       goal_height=float(meta["goal_height"]), family=str(meta["family"]),
                       level=int(meta["level"]), variant=str(meta["variant"]),
                       walls=data["walls"], spec=dict(meta.get("spec", {})),
                       direction=str(meta.get("direction", "up")))
        except (KeyError, ValueError, TypeError) as e:
            raise ValueError(f"{path}: not a valid tile file ({e})") from None


def sample_heights(heights: np.ndarray, resolution: float, x, y) -> np.ndarray:
    """Bilinear height of grid ``heights`` [ny, nx] at points (x, y) (metres, grid frame: point
    (ix, iy) is at (ix * res, iy * res)); x, y broadcast together, result float64 of their shape.
    Outside the grid the coordinates are clamped to the edge."""
    h = np.asarray(heights, np.float64)
    ny, nx = h.shape
    fx = np.clip(np.asarray(x, np.float64) / resolution, 0.0, nx - 1)
    fy = np.clip(np.asarray(y, np.float64) / resolution, 0.0, ny - 1)
    fx, fy = np.broadcast_arrays(fx, fy)
    ix = np.minimum(np.floor(fx).astype(np.int64), nx - 2)
    iy = np.minimum(np.floor(fy).astype(np.int64), ny - 2)
    wx, wy = fx - ix, fy - iy
    h00, h01 = h[iy, ix], h[iy, ix + 1]
    h10, h11 = h[iy + 1, ix], h[iy + 1, ix + 1]
    return (h00 * (1 - wx) + h01 * wx) * (1 - wy) + (h10 * (1 - wx) + h11 * wx) * wy


def _wrap(a: float) -> float:
    return float(np.arctan2(np.sin(a), np.cos(a)))


def _trailing_repeats(line: np.ndarray) -> int:
    """How many points at the end of ``line`` [K, d] repeat the one before them."""
    k = 0
    while k < len(line) - 1 and np.array_equal(line[-1 - k], line[-2 - k]):
        k += 1
    return k


def flat_half(heights: np.ndarray, walls: np.ndarray, resolution: float, xy) -> float:
    """Largest half-size (m, multiple of the resolution, <= MAX_SPAWN_HALF) of an axis-aligned
    square around ``xy`` that, grown by SPAWN_MARGIN, lies on the grid, is flat and has no wall;
    0 if none."""
    i, j = int(round(xy[1] / resolution)), int(round(xy[0] / resolution))
    best = 0.0
    for half in np.arange(resolution, MAX_SPAWN_HALF + 1e-9, resolution):
        r = int(np.floor((half + SPAWN_MARGIN) / resolution + 1e-6))
        if i - r < 0 or j - r < 0:
            break
        win = heights[i - r:i + r + 1, j - r:j + r + 1]
        if (win.shape != (2 * r + 1, 2 * r + 1) or np.ptp(win) > 0
                or walls[i - r:i + r + 1, j - r:j + r + 1].any()):
            break
        best = float(half)
    return best


def wall_height(tile: Tile) -> float:
    """The height padding takes: WALL_RISE above the highest walkable point, at least the
    tile's highest point."""
    walkable = tile.heights[~tile.walls] if (~tile.walls).any() else tile.heights
    return float(quantise(max(float(tile.heights.max()), float(walkable.max()) + WALL_RISE)))


def pad_tile(tile: Tile, points: int) -> Tile:
    """``tile`` in the middle of a square of ``points`` x ``points`` grid points, the rest wall
    (wall_height). Spawn, goal, centre-line and ``spec["origin"]`` follow the shift; a square
    tile of that size is returned as it is."""
    ny, nx = tile.heights.shape
    if points < max(ny, nx):
        raise ValueError(f"cannot pad a {nx} x {ny} tile into {points} x {points} points")
    if (ny, nx) == (points, points):
        return tile
    oy, ox = (points - ny) // 2, (points - nx) // 2
    h = np.full((points, points), wall_height(tile), np.float32)
    walls = np.ones((points, points), bool)
    h[oy:oy + ny, ox:ox + nx] = tile.heights
    walls[oy:oy + ny, ox:ox + nx] = tile.walls
    shift = np.array([ox, oy], np.float64) * tile.resolution
    spawn, goal, line = tile.spawn.copy(), tile.goal.copy(), tile.centreline.copy()
    spawn[:2] += shift
    goal[:2] += shift
    line[:, :2] += shift
    spec = dict(tile.spec)
    if "origin" in spec:
        spec["origin"] = (np.asarray(spec["origin"], np.float64) - shift).tolist()
    spec["padded_by"] = [int(ox), int(oy)]
    return replace(tile, heights=h, walls=walls, spawn=spawn, goal=goal, centreline=line,
                   spec=spec)


# ---------------------------------------------------------------------- npz helpers
def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def atomic_savez(path: str | os.PathLike, **arrays) -> None:
    """np.savez to ``path`` via a temporary file in the same folder and os.replace."""
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=".tmp_", suffix=".npz", dir=folder)
    try:
        with os.fdopen(fd, "wb") as f:
            np.savez(f, **arrays)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def load_npz(path: str | os.PathLike, kind: str, keys: tuple[str, ...]) -> dict[str, np.ndarray]:
    """Load every array of an .npz written by atomic_savez, checking its ``kind`` and ``keys``.
    Missing file -> FileNotFoundError; unreadable, wrong kind or missing keys -> ValueError;
    both one line naming the file."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"{path}: no such file")
    try:
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError, KeyError) as e:
        msg = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise ValueError(f"{path}: not a readable {kind} file ({msg})") from None
    found = str(data.get("kind", ""))
    if found != kind:
        raise ValueError(f"{path}: not a saved {kind} (kind={found or 'missing'})")
    missing = [k for k in keys if k not in data]
    if missing:
        raise ValueError(f"{path}: corrupt {kind} file, missing {', '.join(missing)}")
    return data
