"""A user's staircases as tiles for evaluation: a mesh with start, goal and an optional route, or
a folder of cases (a mesh beside a JSON file of the same stem, the format suites.write_case
writes):

    {"mesh": "name.stl", "start": [x, y, z, yaw], "goal": [x, y, z, yaw],
     "route": [[x, y], ...]}          (route optional; start/goal may give just x, y)

all in the mesh frame (metres, z up). The mesh is ray-cast into a tile (mesh_import), walled
where its grid ends (a ring of wall WALL_RING thick round the footprint), and the waypoint
follows the route: the user's, or the importer's path. Tiles of different sizes share an atlas
by padding (tile.pad_tile: the extra points are wall). Every bad input is one line naming the file.
"""

from __future__ import annotations

import json
import os
from dataclasses import replace
from pathlib import Path

import numpy as np

from .mesh_import import import_mesh
from .path import Line, resample
from .tile import CENTRELINE_POINTS, DIRECTIONS, Tile, pad_tile, sample_heights

WALL_RING = 0.2  # m, thickness of the wall round an imported mesh's footprint


def parse_pose(text: str, name: str) -> tuple[float, float, float | None]:
    """"x,y" or "x,y,yaw" (metres, radians) -> (x, y, yaw or None); else one-line ValueError."""
    try:
        vals = [float(v) for v in str(text).split(",")]
    except ValueError:
        vals = []
    if len(vals) not in (2, 3) or not np.isfinite(vals).all():
        raise ValueError(f"--{name}: expected x,y or x,y,yaw (metres, radians), got {text!r}")
    return vals[0], vals[1], vals[2] if len(vals) == 3 else None


def read_route_csv(path: str | os.PathLike) -> np.ndarray:
    """[m, 2] route points from a CSV file, one "x,y" per line (blank lines, lines starting with
    '#' and a first line that is not numbers are skipped); at least 2 points."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"{path}: no such route file")
    pts = []
    with open(path) as f:
        for k, line in enumerate(f, 1):
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            try:
                x, y = (float(v) for v in line.replace(";", ",").split(",")[:2])
            except ValueError:
                if not pts and k == 1:  # a header
                    continue
                raise ValueError(f"{path}:{k}: expected x,y, got {line!r}") from None
            pts.append((x, y))
    return _check_route(np.asarray(pts, np.float64).reshape(-1, 2), path)


def _check_route(pts: np.ndarray, where: str) -> np.ndarray:
    if len(pts) < 2 or not np.isfinite(pts).all():
        raise ValueError(f"{where}: a route needs at least 2 finite x,y points, got {len(pts)}")
    keep = np.r_[True, np.hypot(*np.diff(pts, axis=0).T) > 1e-9]
    if keep.sum() < 2:
        raise ValueError(f"{where}: the route has zero length")
    return pts[keep]


def offset_route(route, distance: float, taper_m: float = 0.0) -> np.ndarray:
    """The polyline ``route`` [m, 2] shifted sideways by ``distance`` m (+: left of the direction
    of travel), as a route a building map draws off the centre-line: each corner moves along the
    bisector of its two segments' normals, as far as keeps both segments ``distance`` away (a
    mitre, capped at 5x for near-reversals). Points on a straight stretch are dropped first, so
    a corner is one mitre; on the inside of a turn, a segment shorter than the shift would run
    backwards (a swallowtail: 2026-11-27, a centre-line of evenly spaced points shifted a third
    of a U's width inside looped back 0.5 m at both landing corners), so it is dropped and its
    neighbours meet where their shifted lines cross. ``taper_m`` > 0: the shift fades linearly
    to none over the route's last ``taper_m`` m, so that it still ends on its goal (as the
    training routes of mjx_stairs.env.routes do)."""
    pts = _corners(_check_route(np.asarray(route, np.float64).reshape(-1, 2), "offset_route"))
    seg = np.hypot(*np.diff(pts, axis=0).T)
    to_end = np.r_[np.cumsum(seg[::-1])[::-1], 0.0]
    if 0 < taper_m < to_end[0] and not np.isclose(to_end, taper_m).any():  # where the fade starts
        i = int(np.searchsorted(-to_end, -taper_m))  # the first point nearer the end
        a, b = pts[i - 1], pts[i]
        pts = np.insert(pts, i, b + (a - b) * (taper_m - to_end[i]) / seg[i - 1], axis=0)
        to_end = np.insert(to_end, i, taper_m)
    d = np.diff(pts, axis=0)
    d /= np.hypot(*d.T)[:, None]
    n = np.stack([-d[:, 1], d[:, 0]], 1)  # the left normal of each segment
    before, after = np.concatenate([n[:1], n]), np.concatenate([n, n[-1:]])
    bis = before + after
    size = np.linalg.norm(bis, axis=1, keepdims=True)
    bis = np.where(size > 1e-9, bis / np.maximum(size, 1e-12), after)
    cos = np.maximum(np.einsum("ij,ij->i", bis, after), 0.2)
    fade = np.clip(to_end / taper_m, 0.0, 1.0) if taper_m > 0 else np.ones(len(pts))
    return _no_swallowtails(pts, pts + bis * (distance * fade / cos)[:, None])


def _corners(pts: np.ndarray) -> np.ndarray:
    """pts without the interior points where the polyline goes straight on."""
    d = np.diff(pts, axis=0)
    d /= np.hypot(*d.T)[:, None]
    turn = np.abs(d[:-1, 0] * d[1:, 1] - d[:-1, 1] * d[1:, 0]) > 1e-9
    back = np.einsum("ij,ij->i", d[:-1], d[1:]) < 0
    return pts[np.r_[True, turn | back, True]]


def _no_swallowtails(orig: np.ndarray, off: np.ndarray) -> np.ndarray:
    """off (orig's points shifted) without the segments that run against their original ones:
    each goes, and its neighbours are extended to their crossing (an end segment: its inner
    point goes)."""
    off = off.copy()  # its crossing points are written in place
    while len(off) > 2:
        back = np.einsum("ij,ij->i", np.diff(off, axis=0), np.diff(orig, axis=0)) <= 0
        if not back.any():
            break
        j = int(np.argmax(back))  # segment j: off[j] -> off[j + 1]
        if 0 < j < len(off) - 2:
            p, r = off[j - 1], off[j] - off[j - 1]
            q, s = off[j + 1], off[j + 2] - off[j + 1]
            den = r[0] * s[1] - r[1] * s[0]
            if abs(den) > 1e-12:
                t = ((q - p)[0] * s[1] - (q - p)[1] * s[0]) / den
                off[j] = p + t * r
        k = j + 1 if j < len(off) - 2 else j  # the point that goes
        off, orig = np.delete(off, k, axis=0), np.delete(orig, k, axis=0)
    return off


def route_line(route: np.ndarray, heights: np.ndarray, resolution: float) -> np.ndarray:
    """[K, 3] centre-line of the polyline ``route`` [m, 2] (tile frame): its corners kept where
    it has at most K - 1 segments, else K points evenly along it; z from the heights."""
    if len(route) <= CENTRELINE_POINTS:
        xy = resample([Line(tuple(p), tuple(q)) for p, q in zip(route[:-1], route[1:],
                                                                  strict=True)],
                      CENTRELINE_POINTS)
    else:
        cum = np.r_[0.0, np.cumsum(np.hypot(*np.diff(route, axis=0).T))]
        s = np.linspace(0.0, cum[-1], CENTRELINE_POINTS)
        xy = np.stack([np.interp(s, cum, route[:, 0]), np.interp(s, cum, route[:, 1])], 1)
    z = sample_heights(heights, resolution, xy[:, 0], xy[:, 1])
    return np.concatenate([xy, z[:, None]], 1)


def mesh_tile(path: str | os.PathLike, start, goal, route=None, resolution: float = 0.025,
              max_step: float = 0.25, spawn_half=None, direction: str | None = None) -> Tile:
    """The tile of a staircase mesh (metres, z up) walked from ``start`` to ``goal`` ((x, y) or
    (x, y, yaw), mesh frame), walled round its footprint. ``route`` [m, 2] (mesh frame): the
    line the waypoint follows (default: the importer's path); ``spawn_half`` (half x, half y,
    yaw half range): the spawn area (default: the flat square round the start the importer
    finds); ``direction``: "up" / "down" (default: up when the goal is not lower than the
    start). ``tile.spec["origin"]``: the mesh-frame position of grid point (0, 0)."""
    tile = import_mesh(path, tuple(start[:2]), tuple(goal[:2]), resolution, max_step)
    o = np.asarray(tile.spec["origin"], np.float64)
    spawn, goal_row, line = tile.spawn.copy(), tile.goal.copy(), tile.centreline
    if route is not None:
        pts = _check_route(np.asarray(route, np.float64).reshape(-1, 2), os.fspath(path)) - o
        _check_on_walkable(pts, tile, os.fspath(path))
        line = route_line(pts, tile.heights, resolution)
        d0, d1 = line[1, :2] - line[0, :2], _last_step(line)
        spawn[5], goal_row[3] = np.arctan2(d0[1], d0[0]), np.arctan2(d1[1], d1[0])
    if len(start) > 2 and start[2] is not None:
        spawn[5] = start[2]
    if len(goal) > 2 and goal[2] is not None:
        goal_row[3] = goal[2]
    if spawn_half is not None:
        spawn[3], spawn[4], spawn[6] = spawn_half[0], spawn_half[1], spawn_half[2]
    if direction is None:
        direction = "up" if tile.goal_height >= tile.floor_height else "down"
    if direction not in DIRECTIONS:
        raise ValueError(f"{path}: unknown direction {direction!r}; known: up, down")
    tile = replace(tile, spawn=spawn, goal=goal_row, centreline=line, direction=direction)
    ring = int(np.ceil(WALL_RING / resolution - 1e-9))
    return pad_tile(tile, max(tile.heights.shape) + 2 * ring)


def _last_step(line: np.ndarray) -> np.ndarray:
    d = np.diff(line[:, :2], axis=0)
    d = d[np.hypot(*d.T) > 1e-9]
    return d[-1]


def _check_on_walkable(pts: np.ndarray, tile: Tile, where: str) -> None:
    """Every route corner (tile frame) on the grid and off the walls (what start cannot reach)."""
    ij = np.round(pts[:, ::-1] / tile.resolution).astype(int)
    ny, nx = tile.heights.shape
    for p, (i, j) in zip(pts + np.asarray(tile.spec["origin"]), ij, strict=True):
        if not (0 <= i < ny and 0 <= j < nx):
            raise ValueError(f"{where}: route point ({p[0]:g}, {p[1]:g}) lies outside the mesh "
                             f"footprint")
        if tile.walls[i, j]:
            raise ValueError(f"{where}: route point ({p[0]:g}, {p[1]:g}) is not walkable from "
                             f"the start (a wall, or cut off)")


def read_case(path: str | os.PathLike, resolution: float = 0.025,
              max_step: float = 0.25) -> tuple[str, Tile]:
    """(name, tile) of a case JSON (see the module docstring); the mesh path is relative to the
    JSON's folder. A missing file, a JSON that is not such a record, and every mesh_tile error
    -> one line naming the file."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such case file")
    try:
        rec = json.loads(path.read_text())
        mesh = rec["mesh"]
        start, goal = _pose(rec["start"], "start"), _pose(rec["goal"], "goal")
        route = None if rec.get("route") is None else np.asarray(rec["route"], np.float64)
        if route is not None and (route.ndim != 2 or route.shape[1] != 2):
            raise ValueError(f"route must be a list of [x, y] pairs, got shape {route.shape}")
        half = rec.get("spawn_half")
        half = None if half is None else [float(v) for v in half][:3]
        if half is not None and len(half) != 3:
            raise ValueError("spawn_half must be [half x, half y, yaw half range]")
        if not isinstance(mesh, str) or not mesh:
            raise ValueError(f"mesh must be a file name, got {mesh!r}")
        direction = rec.get("direction")
    except json.JSONDecodeError as e:
        raise ValueError(f"{path}: malformed case JSON (line {e.lineno}: {e.msg})") from None
    except (KeyError, TypeError, ValueError) as e:
        what = f"missing key {e}" if isinstance(e, KeyError) else str(e).splitlines()[0]
        raise ValueError(f"{path}: malformed case JSON ({what})") from None
    name = str(rec.get("name") or path.stem)
    return name, mesh_tile(path.parent / mesh, start, goal, route, resolution, max_step, half,
                           direction)


def _pose(v, name: str) -> tuple[float, float, float | None]:
    """[x, y], [x, y, yaw] or [x, y, z, yaw] -> (x, y, yaw or None)."""
    vals = [float(x) for x in v]
    if len(vals) not in (2, 3, 4) or not np.isfinite(vals).all():
        raise ValueError(f"{name} must be [x, y], [x, y, yaw] or [x, y, z, yaw], got {v!r}")
    return vals[0], vals[1], vals[-1] if len(vals) > 2 else None


def read_case_folder(folder: str | os.PathLike, resolution: float = 0.025,
                     max_step: float = 0.25) -> list[tuple[str, Tile]]:
    """Every case (*.json, sorted by name) of a folder, as (name, tile)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"{folder}: no such folder of cases")
    files = sorted(folder.glob("*.json"))
    if not files:
        raise ValueError(f"{folder}: no case files (NAME.json beside NAME.stl/.obj/.ply)")
    return [read_case(f, resolution, max_step) for f in files]
