"""Height grid -> closed triangle mesh with vertical risers, for viewers (GLB / OBJ / STL / PLY).

Every grid point becomes a flat-topped cell of side ``resolution`` centred on it. Cells of equal
height are merged into rectangles (runs along x, stacked along y); where neighbouring cells differ
a vertical wall joins them; the outside is closed by skirts down to a flat bottom. Each face
includes every mesh vertex lying on its boundary (no T-junctions), so the mesh is watertight.
Coordinates: x, y as the grid (point (ix, iy) at origin + (ix, iy) * res), z up, metres. The file
is written as is: GLB viewers, which expect y up, show the terrain z-up.
"""

from __future__ import annotations

import bisect
import os
from collections import defaultdict

import numpy as np
import trimesh

from .tile import HEIGHT_QUANTUM, Tile

MESH_FORMATS = (".glb", ".gltf", ".obj", ".stl", ".ply", ".off")


def _top_rectangles(hq: np.ndarray) -> list[tuple[int, int, int, int, int]]:
    """[ny, nx] int heights -> rectangles (x0, x1, y0, y1, h) in lattice corners (x1, y1
    exclusive), covering every cell once: equal-height runs per row, merged with identical runs
    of the rows above."""
    ny, nx = hq.shape
    out = []
    active: dict[tuple[int, int, int], int] = {}
    for iy in range(ny + 1):
        runs = set()
        if iy < ny:
            row = hq[iy]
            starts = np.flatnonzero(np.r_[True, row[1:] != row[:-1]])
            ends = np.r_[starts[1:], nx]
            runs = {(int(a), int(b), int(row[a])) for a, b in zip(starts, ends, strict=True)}
        for key in list(active):
            if key not in runs:
                y0 = active.pop(key)
                out.append((key[0], key[1], y0, iy, key[2]))
        for key in runs:
            active.setdefault(key, iy)
    return out


def _side_runs(lo_side: np.ndarray, hi_side: np.ndarray) -> list[tuple[int, int, int, int, int]]:
    """Walls along lattice lines. lo_side/hi_side: [L, m] heights of the cells on either side
    of edge k of line l. Returns (l, k0, k1, a, b): edges k0..k1-1 of line l, a on the first
    side, b on the second, a != b."""
    L, m = lo_side.shape
    change = np.ones((L, m), bool)
    change[:, 1:] = (lo_side[:, 1:] != lo_side[:, :-1]) | (hi_side[:, 1:] != hi_side[:, :-1])
    flat = np.flatnonzero(change)
    nxt = np.r_[flat[1:], L * m]
    line, k0 = np.divmod(flat, m)
    k1 = np.where(nxt // m == line, nxt % m, m)
    a, b = lo_side.ravel()[flat], hi_side.ravel()[flat]
    keep = a != b
    return list(zip(line[keep].tolist(), k0[keep].tolist(), k1[keep].tolist(),
                    a[keep].tolist(), b[keep].tolist(), strict=True))


def heights_to_mesh(heights: np.ndarray, resolution: float, origin=(0.0, 0.0),
                    base: float | None = None) -> trimesh.Trimesh:
    """[ny, nx] heights (point (ix, iy) at origin + (ix, iy) * res) -> watertight Trimesh of the
    solid between ``base`` (default: 0.1 m below the lowest point) and the surface.

    Long: one meshing pass (faces, then walls) that shares its index tables.
    """
    hq = np.round(np.asarray(heights, np.float64) / HEIGHT_QUANTUM).astype(np.int64)
    ny, nx = hq.shape
    zb = int(hq.min() - round(0.1 / HEIGHT_QUANTUM)) if base is None else int(
        round(base / HEIGHT_QUANTUM))
    if zb >= hq.min():
        raise ValueError(f"mesh base {base} must lie below the lowest height {hq.min() * 1e-3}")
    pad = np.full((ny + 2, nx + 2), zb, np.int64)
    pad[1:-1, 1:-1] = hq
    rects = _top_rectangles(hq)
    # walls on lines y = j (between rows j-1 and j), edges i; and on lines x = i, edges j
    hwalls = _side_runs(pad[:-1, 1:-1], pad[1:, 1:-1])         # (j, i0, i1, south, north)
    vwalls = _side_runs(pad[1:-1, :-1].T, pad[1:-1, 1:].T)     # (i, j0, j1, west, east)

    # essential vertices (corners of every face), indexed for boundary look-ups
    corners: set[tuple[int, int, int]] = set()
    for x0, x1, y0, y1, h in rects:
        corners.update(((x0, y0, h), (x1, y0, h), (x1, y1, h), (x0, y1, h)))
    for j, i0, i1, a, b in hwalls:
        corners.update(((i0, j, a), (i0, j, b), (i1, j, a), (i1, j, b)))
    for i, j0, j1, a, b in vwalls:
        corners.update(((i, j0, a), (i, j0, b), (i, j1, a), (i, j1, b)))
    corners.update(((0, 0, zb), (nx, 0, zb), (nx, ny, zb), (0, ny, zb)))
    on_hline = defaultdict(list)   # (j, h) -> sorted i
    on_vline = defaultdict(list)   # (i, h) -> sorted j
    on_post = defaultdict(list)    # (i, j) -> sorted h
    for i, j, h in corners:
        on_hline[(j, h)].append(i)
        on_vline[(i, h)].append(j)
        on_post[(i, j)].append(h)
    for d in (on_hline, on_vline, on_post):
        for v in d.values():
            v.sort()

    def between(seq, a, b):
        """Values of sorted seq strictly between a and b, in the order a -> b."""
        lo, hi = min(a, b), max(a, b)
        vals = seq[bisect.bisect_right(seq, lo):bisect.bisect_left(seq, hi)]
        return vals if a < b else vals[::-1]

    verts: dict[tuple[int, int, int], int] = {}
    extra: list[tuple[float, float, float]] = []   # fan centres, in lattice units
    tris: list[tuple[int, int, int]] = []

    def vid(p):
        k = verts.get(p)
        if k is None:
            k = verts[p] = len(verts)
        return k

    def polygon(ring: list[tuple[int, int, int]]):
        """Triangulate a planar convex ring (counter-clockwise about the outward normal)."""
        ids = [vid(p) for p in ring]
        if len(ids) == 4:
            tris.extend(((ids[0], ids[1], ids[2]), (ids[0], ids[2], ids[3])))
            return
        c = np.mean(np.array(ring, float), 0)
        extra.append(tuple(c))
        ci = -len(extra)   # negative: index into extra, fixed below
        tris.extend((ci, ids[k], ids[(k + 1) % len(ids)]) for k in range(len(ids)))

    def rect_ring(x0, x1, y0, y1, h):
        ring = [(x0, y0, h)] + [(i, y0, h) for i in between(on_hline[(y0, h)], x0, x1)]
        ring += [(x1, y0, h)] + [(x1, j, h) for j in between(on_vline[(x1, h)], y0, y1)]
        ring += [(x1, y1, h)] + [(i, y1, h) for i in between(on_hline[(y1, h)], x1, x0)]
        ring += [(x0, y1, h)] + [(x0, j, h) for j in between(on_vline[(x0, h)], y1, y0)]
        return ring

    for x0, x1, y0, y1, h in rects:
        polygon(rect_ring(x0, x1, y0, y1, h))
    polygon(rect_ring(0, nx, 0, ny, zb)[::-1])          # bottom, facing down
    for j, i0, i1, south, north in hwalls:                # plane y = j
        lo, hi = min(south, north), max(south, north)
        ring = ([(i0, j, lo)] + [(i, j, lo) for i in between(on_hline[(j, lo)], i0, i1)]
                + [(i1, j, lo)] + [(i1, j, z) for z in between(on_post[(i1, j)], lo, hi)]
                + [(i1, j, hi)] + [(i, j, hi) for i in between(on_hline[(j, hi)], i1, i0)]
                + [(i0, j, hi)] + [(i0, j, z) for z in between(on_post[(i0, j)], hi, lo)])
        polygon(ring if south < north else ring[::-1])    # ring as built faces -y
    for i, j0, j1, west, east in vwalls:                  # plane x = i
        lo, hi = min(west, east), max(west, east)
        ring = ([(i, j0, lo)] + [(i, j, lo) for j in between(on_vline[(i, lo)], j0, j1)]
                + [(i, j1, lo)] + [(i, j1, z) for z in between(on_post[(i, j1)], lo, hi)]
                + [(i, j1, hi)] + [(i, j, hi) for j in between(on_vline[(i, hi)], j1, j0)]
                + [(i, j0, hi)] + [(i, j0, z) for z in between(on_post[(i, j0)], hi, lo)])
        polygon(ring if west > east else ring[::-1])      # ring as built faces +x

    lattice = np.array(list(verts), float).reshape(-1, 3)
    if extra:
        lattice = np.concatenate([lattice, np.array(extra, float)], 0)
    faces = np.array(tris, np.int64)
    faces = np.where(faces < 0, len(verts) + (-faces - 1), faces)
    xyz = np.empty_like(lattice)
    xyz[:, 0] = origin[0] + (lattice[:, 0] - 0.5) * resolution
    xyz[:, 1] = origin[1] + (lattice[:, 1] - 0.5) * resolution
    xyz[:, 2] = lattice[:, 2] * HEIGHT_QUANTUM
    return trimesh.Trimesh(vertices=xyz, faces=faces, process=False)


def export_mesh(heights: np.ndarray, resolution: float, path: str | os.PathLike,
                origin=(0.0, 0.0)) -> trimesh.Trimesh:
    """Write heights [ny, nx] as a mesh file; format from the extension (MESH_FORMATS)."""
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext not in MESH_FORMATS:
        raise ValueError(f"{path}: unsupported mesh format {ext or '(none)'}; use one of "
                         f"{', '.join(MESH_FORMATS)}")
    mesh = heights_to_mesh(heights, resolution, origin)
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    mesh.export(path)
    return mesh


def export_tile(tile: Tile, path: str | os.PathLike) -> trimesh.Trimesh:
    """Write ``tile`` as a mesh (tile frame) to ``path`` (.glb/.obj/.stl/.ply)."""
    return export_mesh(tile.heights, tile.resolution, path)
