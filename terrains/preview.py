"""Hill-shaded preview of a tile (matplotlib, Agg backend): height map, spawn area, goal and
centre-line."""

from __future__ import annotations

import os

import numpy as np

from .tile import Tile


def render_tile(tile: Tile, path: str | os.PathLike, size_px: int = 600,
                title: str | None = None) -> None:
    """Write a PNG of ``tile``: colour = height, shaded by slope; spawn rectangle (green), goal
    (red star and heading), centre-line (white)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LightSource

    h = tile.heights.astype(np.float64)
    res = tile.resolution
    ny, nx = h.shape
    extent = (-res / 2, (nx - 0.5) * res, -res / 2, (ny - 0.5) * res)
    dpi = 100
    fig, ax = plt.subplots(figsize=(size_px / dpi, size_px / dpi), dpi=dpi)
    ls = LightSource(azdeg=315, altdeg=40)
    walk_top = (max(tile.goal_height, tile.floor_height) if not tile.walls.any()
                else float(h[~tile.walls].max()))
    vmax = max(walk_top, 1e-3) * 1.15
    cmap = plt.get_cmap("viridis")
    rgb = ls.shade(np.clip(h, 0, vmax), cmap=cmap, vert_exag=3.0, dx=res, dy=res,
                   blend_mode="soft", vmin=0.0, vmax=vmax)
    rgb[tile.walls] = (0.35, 0.35, 0.38, 1.0)
    ax.imshow(rgb, origin="lower", extent=extent, interpolation="nearest")
    x, y, _, hx, hy, yaw, _ = tile.spawn
    ax.add_patch(plt.Rectangle((x - hx, y - hy), 2 * hx, 2 * hy, fill=False, ec="lime", lw=2))
    ax.arrow(x, y, 0.6 * np.cos(yaw), 0.6 * np.sin(yaw), color="lime", width=0.04)
    c = tile.centreline
    ax.plot(c[:, 0], c[:, 1], "-", color="white", lw=1.5)
    ax.plot(c[:, 0], c[:, 1], ".", color="white", ms=3)
    gx, gy, gz, gyaw = tile.goal
    ax.plot([gx], [gy], marker="*", color="red", ms=16, mec="k")
    ax.arrow(gx, gy, 0.5 * np.cos(gyaw), 0.5 * np.sin(gyaw), color="red", width=0.03)
    spec = tile.spec
    if title is None and tile.family == "imported":
        title = f"imported {tile.variant}  rise {tile.goal_height - tile.floor_height:.2f} m"
    rise = abs(tile.goal_height - tile.floor_height)
    label = title or (f"{tile.family} {tile.variant} {tile.direction}  level {tile.level + 1} "
                      f"({spec.get('schedule', '?')})  riser {spec.get('riser', 0) * 100:.1f} cm"
                      f"  rise {rise:.2f} m")
    ax.set_title(label, fontsize=9)
    ax.set_xlabel("x (m)", fontsize=8)
    ax.set_ylabel("y (m)", fontsize=8)
    ax.tick_params(labelsize=7)
    sm = plt.cm.ScalarMappable(cmap=cmap, norm=plt.Normalize(0, vmax))
    cb = fig.colorbar(sm, ax=ax, fraction=0.04, pad=0.02)
    cb.set_label("height (m); walls grey", fontsize=7)
    cb.ax.tick_params(labelsize=7)
    fig.tight_layout()
    fig.savefig(os.fspath(path), dpi=dpi)
    plt.close(fig)
