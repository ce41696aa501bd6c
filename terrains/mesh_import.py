"""A user's staircase mesh (OBJ / STL / GLB / PLY) -> Tile: the height grid by casting rays
straight down (terrains.raycast), the start and the goal from the user, the centre-line the
shortest walkable path between them, kept away from walls, crossing landings through their
middles and reaching (and leaving) the flights at either end along their axes (terrains.approach).
"""

from __future__ import annotations

import os

import numpy as np

from .approach import approach, grow, min_on
from .path import Line, resample
from .raycast import IMPORT_FORMATS, MAX_EXTENT, height_grid, load_mesh, raycast_down
from .tile import CENTRELINE_POINTS, HEIGHT_QUANTUM, SPAWN_MARGIN, Tile, sample_heights

CENTRE_CAP = 1.0    # m, clearance beyond which the route no longer cares
CENTRE_MIN = 0.05   # m, clearance floor of the cost (bounds it at (CAP/MIN)^POWER per metre)
CENTRE_POWER = 4.0
FLAT_PATCH = 0.4    # m, a flat patch holding a disc of this radius is a landing, not a tread
RISER_SLACK = 1.0   # m, a landing's risers count as this much farther than its walls


def _edges(h: np.ndarray, limit: float) -> np.ndarray:
    """[ny, nx] bool: points with a 4-neighbour more than ``limit`` higher or lower, and the
    points on the grid's border (the mesh ends there)."""
    out = np.zeros(h.shape, bool)
    bx = np.abs(np.diff(h, axis=1)) > limit
    by = np.abs(np.diff(h, axis=0)) > limit
    out[:, 1:] |= bx
    out[:, :-1] |= bx
    out[1:] |= by
    out[:-1] |= by
    out[[0, -1], :] = True
    out[:, [0, -1]] = True
    return out


def chamfer_distance(seeds: np.ndarray, resolution: float, cap: float) -> np.ndarray:
    """Distance (m, 8-neighbour chamfer) from every point to the nearest True of ``seeds``
    [ny, nx], exact enough for steering, computed up to ``cap`` (farther points get cap)."""
    d = np.where(seeds, 0.0, np.inf)
    diag = resolution * np.sqrt(2.0)
    for _ in range(int(np.ceil(cap / resolution)) + 2):
        new = d.copy()
        np.minimum(new[1:], d[:-1] + resolution, out=new[1:])
        np.minimum(new[:-1], d[1:] + resolution, out=new[:-1])
        np.minimum(new[:, 1:], d[:, :-1] + resolution, out=new[:, 1:])
        np.minimum(new[:, :-1], d[:, 1:] + resolution, out=new[:, :-1])
        np.minimum(new[1:, 1:], d[:-1, :-1] + diag, out=new[1:, 1:])
        np.minimum(new[:-1, :-1], d[1:, 1:] + diag, out=new[:-1, :-1])
        np.minimum(new[1:, :-1], d[:-1, 1:] + diag, out=new[1:, :-1])
        np.minimum(new[:-1, 1:], d[1:, :-1] + diag, out=new[:-1, 1:])
        if np.array_equal(new, d):
            break
        d = new
    return np.minimum(d, cap)


def clearance(heights: np.ndarray, resolution: float, max_step: float) -> np.ndarray:
    """[ny, nx] m: on large flat patches the distance to the patch's edge, elsewhere the distance
    to the nearest impassable edge (see the module docstring), capped at CENTRE_CAP."""
    d, _, _ = _fields(heights, resolution, max_step)
    return d


def _fields(heights: np.ndarray, resolution: float, max_step: float):
    """(clearance, d_flat, large): see clearance(); d_flat [ny, nx] distance to the nearest
    height change; large [ny, nx] bool on flat patches holding a disc of radius FLAT_PATCH."""
    h = np.asarray(heights, np.float64)
    d_wall = chamfer_distance(_edges(h, max_step), resolution, CENTRE_CAP)
    d_flat = chamfer_distance(_edges(h, HEIGHT_QUANTUM / 2), resolution, CENTRE_CAP)
    large = d_flat >= FLAT_PATCH - 1e-9
    for _ in range(int(np.ceil(1.5 * FLAT_PATCH / resolution))):   # grow over the patch
        g = large.copy()
        g[1:] |= large[:-1] & (h[1:] == h[:-1])
        g[:-1] |= large[1:] & (h[:-1] == h[1:])
        g[:, 1:] |= large[:, :-1] & (h[:, 1:] == h[:, :-1])
        g[:, :-1] |= large[:, 1:] & (h[:, :-1] == h[:, 1:])
        if np.array_equal(g, large):
            break
        large = g
    return np.where(large, np.minimum(d_wall, d_flat + RISER_SLACK), d_wall), d_flat, large


def centring_cost(heights: np.ndarray, resolution: float, max_step: float) -> np.ndarray:
    """[ny, nx] cost per metre, >= 1: (CENTRE_CAP / clearance) ** CENTRE_POWER."""
    d = np.clip(clearance(heights, resolution, max_step), CENTRE_MIN, CENTRE_CAP)
    return (CENTRE_CAP / d) ** CENTRE_POWER


def walk_distance(heights: np.ndarray, resolution: float, start_ij: tuple[int, int],
                  max_step: float) -> tuple[np.ndarray, np.ndarray]:
    """Cheapest walking path cost from grid point start_ij = (iy, ix) over 8-neighbours whose
    heights differ by at most ``max_step``, each step costing its length times the mean
    centring_cost of its ends. Returns (cost [ny, nx], inf where unreachable; parent move index
    [ny, nx])."""
    h = np.asarray(heights, np.float64)
    ny, nx = h.shape
    moves = [(0, 1), (0, -1), (1, 0), (-1, 0), (1, 1), (1, -1), (-1, 1), (-1, -1)]
    cost = resolution * centring_cost(h, resolution, max_step)
    dist = np.full((ny, nx), np.inf)
    parent = np.full((ny, nx), -1, np.int8)
    dist[start_ij] = 0.0
    while True:
        changed = False
        for m, (di, dj) in enumerate(moves):
            dst = (slice(max(di, 0), ny + min(di, 0)), slice(max(dj, 0), nx + min(dj, 0)))
            src = (slice(max(-di, 0), ny + min(-di, 0)), slice(max(-dj, 0), nx + min(-dj, 0)))
            ok = np.abs(h[dst] - h[src]) <= max_step
            if di and dj:  # diagonal: both axis neighbours must be passable too
                ok &= np.abs(h[src[0], dst[1]] - h[src]) <= max_step
                ok &= np.abs(h[dst[0], src[1]] - h[src]) <= max_step
                ok &= np.abs(h[dst] - h[src[0], dst[1]]) <= max_step
                ok &= np.abs(h[dst] - h[dst[0], src[1]]) <= max_step
            step = np.hypot(di, dj) * 0.5 * (cost[dst] + cost[src])
            cand = np.where(ok, dist[src] + step, np.inf)
            better = cand < dist[dst] - 1e-12
            if better.any():
                dist[dst] = np.where(better, cand, dist[dst])
                parent[dst] = np.where(better, m, parent[dst])
                changed = True
        if not changed:
            return dist, parent


def _trace(parent: np.ndarray, goal_ij: tuple[int, int]) -> np.ndarray:
    """Follow parent moves back from goal_ij; returns [m, 2] (iy, ix) from start to goal."""
    moves = [(0, 1), (0, -1), (1, 0), (-1, 0), (1, 1), (1, -1), (-1, 1), (-1, -1)]
    out = [goal_ij]
    i, j = goal_ij
    while parent[i, j] >= 0:
        di, dj = moves[parent[i, j]]
        i, j = i - di, j - dj
        out.append((i, j))
    return np.array(out[::-1])


def _patch(seed_ij: tuple[int, int], h: np.ndarray, large: np.ndarray) -> np.ndarray:
    """[ny, nx] bool: the large flat patch of equal height holding ``seed_ij``."""
    return grow(seed_ij, large & (h == h[seed_ij]))


def through_landings(cells: np.ndarray, h: np.ndarray, d_flat: np.ndarray, large: np.ndarray,
                     resolution: float, clear: np.ndarray | None = None) -> list[np.ndarray]:
    """Route cells [m, 2] (iy, ix) -> list of [k, 2] xy pieces, where every run of cells on one
    large flat patch becomes entry -> nearest ridge point -> ridge point nearest the exit -> exit
    (the ridge: the points within a grid step of the largest d_flat among the patch's points
    within 2 CENTRE_CAP of the run, so that a ring-shaped floor is not left for its corners).
    A run stays as searched if the pieces would leave the patch or come closer to a wall than
    0.8 x the run's closest approach (``clear``: the clearance field; the margin covers the
    chamfer metric's error), e.g. across a curved landing."""
    out, i, m = [], 0, len(cells)
    xy = cells[:, ::-1] * resolution
    while i < m:
        ij = tuple(cells[i])
        if not large[ij]:
            out.append(xy[i:i + 1])
            i += 1
            continue
        patch = _patch(ij, h, large)
        j = i
        while j + 1 < m and patch[tuple(cells[j + 1])]:
            j += 1
        run = np.zeros(h.shape, bool)
        run[cells[i:j + 1, 0], cells[i:j + 1, 1]] = True
        local = patch & (chamfer_distance(run, resolution, 2 * CENTRE_CAP) < 2 * CENTRE_CAP)
        top = d_flat[local].max()
        ridge = np.argwhere(local & (d_flat >= top - 0.75 * resolution))[:, ::-1] * resolution
        e, x = xy[i], xy[j]
        re = ridge[np.argmin(np.hypot(*(ridge - e).T))]
        rx = ridge[np.argmin(np.hypot(*(ridge - x).T))]
        piece = np.array([e, re, rx, x])
        closest = 0.0 if clear is None else clear[cells[i:j + 1, 0], cells[i:j + 1, 1]].min()
        if _on_patch(piece, patch, resolution) and (
                clear is None or min_on(piece, clear, resolution) >= 0.8 * closest):
            out.append(piece)
        else:
            out.append(xy[i:j + 1])
        i = j + 1
    return out


def _on_patch(piece: np.ndarray, patch: np.ndarray, resolution: float) -> bool:
    """Whether the polyline [k, 2] stays on ``patch`` (sampled every quarter grid step)."""
    for a, b in zip(piece[:-1], piece[1:], strict=True):
        n = max(int(np.ceil(np.hypot(*(b - a)) / (resolution / 4))), 1)
        p = a + (b - a) * (np.arange(n + 1) / n)[:, None]
        ij = np.round(p[:, ::-1] / resolution).astype(int)
        if not patch[ij[:, 0], ij[:, 1]].all():
            return False
    return True


def route_points(cells: np.ndarray, h: np.ndarray, resolution: float, max_step: float,
                 start: np.ndarray, goal: np.ndarray) -> np.ndarray:
    """The searched route cells [m, 2] (iy, ix) -> [k, 2] xy from ``start`` to ``goal``: at
    either end along the flight's axis where approach() finds one, through_landings between."""
    clear, d_flat, large = _fields(h, resolution, max_step)
    n = len(cells)
    head = approach(cells, h, large, clear, resolution, start)
    tail = approach(cells[::-1], h, large, clear, resolution, goal)
    lo = head[1] if head else 0
    if tail and n - tail[1] <= lo:       # one short flight: its axis from the start suffices
        tail = None
    hi = n - tail[1] if tail else n
    mid = np.concatenate(through_landings(cells[lo:hi], h, d_flat, large, resolution, clear))
    first = head[0] if head else [start]
    last = tail[0][::-1] if tail else [goal]
    return np.concatenate([first, mid[0 if head else 1:len(mid) if tail else -1], last])


def _simplify(pts: np.ndarray, tol: float) -> np.ndarray:
    """Ramer-Douglas-Peucker on [m, 2] points."""
    if len(pts) < 3:
        return pts
    a, b = pts[0], pts[-1]
    d = b - a
    n = np.hypot(*d)
    rel = pts - a
    dist = (np.abs(d[0] * rel[:, 1] - d[1] * rel[:, 0]) / n if n > 0
            else np.hypot(rel[:, 0], rel[:, 1]))
    k = int(np.argmax(dist))
    if dist[k] <= tol:
        return np.array([a, b])
    return np.concatenate([_simplify(pts[:k + 1], tol)[:-1], _simplify(pts[k:], tol)])


def import_mesh(path: str | os.PathLike, start: tuple[float, float], goal: tuple[float, float],
                resolution: float = 0.025, max_step: float = 0.25, ceiling: float = np.inf,
                origin: tuple[float, float] | None = None) -> Tile:
    """Ray-cast a staircase mesh into a Tile.

    start, goal: (x, y) in the mesh's frame (z up). The grid covers the mesh footprint: its first
    point is at ``origin`` (default: footprint corner + resolution / 2) and the tile frame is the
    mesh frame shifted by it (``tile.spec['origin']``). Heights are quantised; points no ray hits
    take the lowest hit height. The centre-line is the shortest path stepping at most
    ``max_step`` between neighbours; everything that path search cannot reach is wall."""
    path = os.fspath(path)
    o, h = height_grid(path, resolution, ceiling, origin)
    ny, nx = h.shape

    def grid_index(p, name):
        ij = (int(round((p[1] - o[1]) / resolution)), int(round((p[0] - o[0]) / resolution)))
        if not (0 <= ij[0] < ny and 0 <= ij[1] < nx):
            raise ValueError(f"{path}: {name} {tuple(p)} lies outside the mesh footprint")
        return ij

    s_ij, g_ij = grid_index(start, "start"), grid_index(goal, "goal")
    dist, parent = walk_distance(h, resolution, s_ij, max_step)
    if not np.isfinite(dist[g_ij]):
        raise ValueError(f"{path}: no walkable route: goal {tuple(goal)} cannot be reached from "
                         f"start {tuple(start)} stepping at most {max_step} m")
    s_xy, g_xy = np.asarray(start, float) - o, np.asarray(goal, float) - o
    pts = _simplify(route_points(_trace(parent, g_ij), h.astype(np.float64), resolution,
                                 max_step, s_xy, g_xy), resolution / 2)
    pts = pts[np.r_[True, np.hypot(*np.diff(pts, axis=0).T) > 1e-9]]
    xy = resample([Line(tuple(p), tuple(q)) for p, q in zip(pts[:-1], pts[1:], strict=True)],
                  CENTRELINE_POINTS)
    z = sample_heights(h, resolution, xy[:, 0], xy[:, 1])
    d0, d1 = pts[1] - pts[0], pts[-1] - pts[-2]
    z_start, z_goal = float(h[s_ij]), float(h[g_ij])
    half = _flat_half(h, resolution, s_ij)
    spawn = [s_xy[0], s_xy[1], z_start, half, half, np.arctan2(d0[1], d0[0]), np.pi / 4]
    return Tile(heights=h, resolution=resolution, spawn=spawn,
                goal=[g_xy[0], g_xy[1], z_goal, np.arctan2(d1[1], d1[0])],
                centreline=np.concatenate([xy, z[:, None]], 1), floor_height=z_start,
                goal_height=z_goal, family="imported", level=0,
                variant=os.path.splitext(os.path.basename(path))[0],
                walls=~np.isfinite(dist),
                spec=dict(source=path, origin=o.tolist(), max_step=max_step,
                          path_length=float(np.hypot(*np.diff(pts, axis=0).T).sum())))


def _flat_half(h: np.ndarray, resolution: float, ij: tuple[int, int]) -> float:
    """Largest half-size (m, <= 0.5) of a square around ij that is flat together with a
    SPAWN_MARGIN border; 0 if none."""
    i, j = ij
    best = 0.0
    for half in np.arange(resolution, 0.5 + 1e-9, resolution):
        r = int(round((half + SPAWN_MARGIN) / resolution))
        win = h[max(i - r, 0):i + r + 1, max(j - r, 0):j + r + 1]
        if win.shape != (2 * r + 1, 2 * r + 1) or np.ptp(win) > 0:
            break
        best = float(half)
    return best


__all__ = ["IMPORT_FORMATS", "MAX_EXTENT", "height_grid", "import_mesh", "load_mesh",
           "raycast_down"]
