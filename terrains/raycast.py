"""Mesh file -> height grid: a triangle mesh (OBJ / STL / GLB / PLY, metres, z up) read and
ray-cast straight down on a grid over its footprint.

Vertical rays hit the highest surface under each grid point, so a mesh with a ceiling must be
cropped first or cast with ``ceiling=``. trimesh's own ray casters need rtree or embree, which
the project does not install; ``raycast_down`` does the same for vertical rays in numpy.
"""

from __future__ import annotations

import os

import numpy as np
import trimesh

from .tile import quantise

IMPORT_FORMATS = (".obj", ".stl", ".glb", ".gltf", ".ply", ".off")
_CHUNK = 4_000_000  # (triangle, grid point) candidate pairs per batch
MAX_EXTENT = 200.0  # m; a wider footprint is taken for a mesh in millimetres


def load_mesh(path: str | os.PathLike) -> trimesh.Trimesh:
    """Read a triangle mesh; missing, unreadable, empty or non-3-D -> one-line error naming the
    file (FileNotFoundError for a missing file, ValueError otherwise)."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"{path}: no such mesh file")
    ext = os.path.splitext(path)[1].lower()
    if ext not in IMPORT_FORMATS:
        raise ValueError(f"{path}: unsupported mesh format {ext or '(none)'}; use one of "
                         f"{', '.join(IMPORT_FORMATS)}")
    if os.path.getsize(path) == 0:
        raise ValueError(f"{path}: empty file")
    try:
        mesh = trimesh.load(path, force="mesh")
    except Exception as e:  # trimesh raises many kinds on bad input
        msg = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise ValueError(f"{path}: cannot read mesh ({msg})") from None
    if not isinstance(mesh, trimesh.Trimesh):
        raise ValueError(f"{path}: no triangle mesh in the file (got {type(mesh).__name__})")
    if len(mesh.faces) == 0 or len(mesh.vertices) == 0:
        raise ValueError(f"{path}: empty mesh (no triangles)")
    v = np.asarray(mesh.vertices)
    if v.ndim != 2 or v.shape[1] != 3 or not np.isfinite(v).all():
        raise ValueError(f"{path}: not a 3-D mesh (vertices of shape {v.shape})")
    ext_xy = np.ptp(v[:, :2], axis=0)
    if min(ext_xy) <= 0:
        raise ValueError(f"{path}: not a 3-D staircase (flat footprint {ext_xy[0]:g} x "
                         f"{ext_xy[1]:g} m in x, y)")
    return mesh


def raycast_down(vertices: np.ndarray, faces: np.ndarray, x: np.ndarray, y: np.ndarray,
                 ceiling: float = np.inf) -> np.ndarray:
    """Height of the highest triangle (below ``ceiling``) under each grid point.

    vertices [V, 3], faces [F, 3]; x [nx], y [ny] increasing evenly spaced grid coordinates.
    Returns [ny, nx] float64, NaN where a vertical ray hits nothing."""
    tri = np.asarray(vertices, np.float64)[np.asarray(faces)]          # [F, 3, 3]
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    det = (b[:, 1] - c[:, 1]) * (a[:, 0] - c[:, 0]) + (c[:, 0] - b[:, 0]) * (a[:, 1] - c[:, 1])
    scale = np.maximum(np.ptp(tri[:, :, :2], axis=1).max(1), 1e-12) ** 2
    keep = np.abs(det) > 1e-9 * scale         # vertical (edge-on) triangles cannot be hit
    a, b, c, det = a[keep], b[keep], c[keep], det[keep]
    nx, ny = len(x), len(y)
    out = np.full(ny * nx, -np.inf)
    if len(a) == 0:
        return np.full((ny, nx), np.nan)
    dx = x[1] - x[0] if nx > 1 else 1.0
    dy = y[1] - y[0] if ny > 1 else 1.0
    lo = np.minimum(np.minimum(a, b), c)
    hi = np.maximum(np.maximum(a, b), c)
    ix0 = np.clip(np.ceil((lo[:, 0] - x[0]) / dx - 1e-9), 0, nx).astype(np.int64)
    ix1 = np.clip(np.floor((hi[:, 0] - x[0]) / dx + 1e-9), -1, nx - 1).astype(np.int64)
    iy0 = np.clip(np.ceil((lo[:, 1] - y[0]) / dy - 1e-9), 0, ny).astype(np.int64)
    iy1 = np.clip(np.floor((hi[:, 1] - y[0]) / dy + 1e-9), -1, ny - 1).astype(np.int64)
    w = np.maximum(ix1 - ix0 + 1, 0)
    cnt = w * np.maximum(iy1 - iy0 + 1, 0)
    cum = np.cumsum(cnt)
    start = 0
    while start < len(cnt):
        base = cum[start - 1] if start else 0
        stop = max(int(np.searchsorted(cum, base + _CHUNK, side="right")), start + 1)
        sel = np.arange(start, stop)
        n = cnt[sel]
        t = np.repeat(sel, n)
        k = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
        px = ix0[t] + k % w[t]
        py = iy0[t] + k // w[t]
        X, Y = x[px], y[py]
        l1 = ((b[t, 1] - c[t, 1]) * (X - c[t, 0]) + (c[t, 0] - b[t, 0]) * (Y - c[t, 1])) / det[t]
        l2 = ((c[t, 1] - a[t, 1]) * (X - c[t, 0]) + (a[t, 0] - c[t, 0]) * (Y - c[t, 1])) / det[t]
        l3 = 1.0 - l1 - l2
        z = l1 * a[t, 2] + l2 * b[t, 2] + l3 * c[t, 2]
        hit = (l1 >= -1e-9) & (l2 >= -1e-9) & (l3 >= -1e-9) & (z <= ceiling)
        np.maximum.at(out, py[hit] * nx + px[hit], z[hit])
        start = stop
    out[np.isneginf(out)] = np.nan
    return out.reshape(ny, nx)


def height_grid(path: str, resolution: float, ceiling: float = np.inf,
                origin: tuple[float, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(origin [2], heights [ny, nx]) of the mesh file ``path`` ray-cast on a grid over its
    footprint (see import_mesh), quantised; points no ray hits take the lowest hit height. A
    footprint wider than MAX_EXTENT (a mesh in millimetres), or one smaller than two grid
    points, or no surface under the grid -> one-line ValueError naming the file."""
    mesh = load_mesh(path)
    lo, hi = mesh.bounds[0], mesh.bounds[1]
    ext = hi - lo
    if max(ext[0], ext[1]) > MAX_EXTENT:
        raise ValueError(f"{path}: footprint {ext[0]:g} x {ext[1]:g} units is wider than "
                         f"{MAX_EXTENT:g} m: the mesh looks like millimetres; scale it by 0.001 "
                         f"(metres, z up)")
    o = np.asarray(lo[:2] + resolution / 2 if origin is None else origin, np.float64)
    nx = int(np.floor((hi[0] - o[0]) / resolution + 1e-6)) + 1
    ny = int(np.floor((hi[1] - o[1]) / resolution + 1e-6)) + 1
    if nx < 2 or ny < 2:
        raise ValueError(f"{path}: footprint smaller than two grid points at {resolution} m")
    xs, ys = o[0] + np.arange(nx) * resolution, o[1] + np.arange(ny) * resolution
    h = raycast_down(mesh.vertices, mesh.faces, xs, ys, ceiling)
    if np.isnan(h).all():
        raise ValueError(f"{path}: no surface found under the grid (nothing below the ceiling?)")
    return o, quantise(np.where(np.isnan(h), np.nanmin(h), h))
