"""Command line: python -m terrains {preview, export, import, atlas} ...

  preview FAMILY --level N [--variant V] [--schedule S] --out file.png
  export  FAMILY --level N [--variant V] [--schedule S] --out file.glb|.obj|.stl|.ply
  export  saved.npz --out file.glb           (a saved tile or atlas)
  import  mesh.obj --start x,y --goal x,y --out tile.npz [--preview file.png]
  atlas   FAMILY [FAMILY ...] [--schedule S] [--levels 1,2,3] [--variants K] --out atlas.npz
Levels are 1-based on the command line. Errors print one line and exit with status 2.
"""

from __future__ import annotations

import argparse
import sys

from .levels import SCHEDULES
from .tile import DEFAULT_RESOLUTION, DEFAULT_TILE_SIZE


def _xy(text: str) -> tuple[float, float]:
    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected x,y in metres, got {text!r}") from None
    return x, y


def _tile_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("family", help="pyramid, straight, l_shaped, u_shaped or spiral")
    p.add_argument("--level", type=int, required=True, help="1-based level")
    p.add_argument("--variant", default=None, help="e.g. left/right, cw/ccw, +x (default: first)")
    p.add_argument("--schedule", default="train", choices=SCHEDULES)
    p.add_argument("--resolution", type=float, default=DEFAULT_RESOLUTION, help="metres")
    p.add_argument("--tile-size", type=float, default=DEFAULT_TILE_SIZE, help="metres")
    p.add_argument("--out", required=True)


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m terrains", description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    _tile_args(sub.add_parser("preview", help="hill-shaded PNG of one tile"))
    p = sub.add_parser("export", help="mesh of a tile, or of a saved tile/atlas .npz")
    _tile_args(p)
    p._actions[[a.dest for a in p._actions].index("level")].required = False
    p = sub.add_parser("import", help="staircase mesh -> tile .npz by ray casting")
    p.add_argument("mesh")
    p.add_argument("--start", type=_xy, required=True, help="x,y in the mesh frame")
    p.add_argument("--goal", type=_xy, required=True, help="x,y in the mesh frame")
    p.add_argument("--resolution", type=float, default=DEFAULT_RESOLUTION)
    p.add_argument("--max-step", type=float, default=0.25, help="highest step a robot takes, m")
    p.add_argument("--ceiling", type=float, default=float("inf"), help="ignore surfaces above")
    p.add_argument("--out", required=True, help="tile .npz")
    p.add_argument("--preview", default=None, help="also write a PNG preview")
    p = sub.add_parser("atlas", help="build and save an atlas .npz")
    p.add_argument("families", nargs="+")
    p.add_argument("--schedule", default="train", choices=SCHEDULES)
    p.add_argument("--levels", default=None, help="1-based, comma separated (default: all)")
    p.add_argument("--variants", type=int, default=2, help="columns per family")
    p.add_argument("--resolution", type=float, default=DEFAULT_RESOLUTION)
    p.add_argument("--tile-size", type=float, default=DEFAULT_TILE_SIZE)
    p.add_argument("--border", type=float, default=2.0)
    p.add_argument("--out", required=True)
    return ap


def _make(a):
    from .families import make_tile
    from .levels import levels
    if a.level is None:
        raise ValueError("--level is required for a family")
    count = len(levels(a.family, a.schedule))
    if not 1 <= a.level <= count:
        raise ValueError(f"--level {a.level} out of range: {a.family} has levels 1..{count} "
                         f"in schedule {a.schedule!r}")
    return make_tile(a.family, a.level - 1, a.variant, a.schedule, a.resolution, a.tile_size)


def run(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit status."""
    a = _parser().parse_args(argv)
    if a.cmd == "preview":
        from .preview import render_tile
        render_tile(_make(a), a.out)
        print(f"wrote {a.out}")
    elif a.cmd == "export":
        from .mesh import export_mesh
        if a.family.endswith(".npz"):
            heights, res = _load_npz_heights(a.family)
        else:
            t = _make(a)
            heights, res = t.heights, t.resolution
        mesh = export_mesh(heights, res, a.out)
        print(f"wrote {a.out}: {len(mesh.vertices)} vertices, {len(mesh.faces)} triangles")
    elif a.cmd == "import":
        from .mesh_import import import_mesh
        t = import_mesh(a.mesh, a.start, a.goal, a.resolution, a.max_step, a.ceiling)
        t.save(a.out)
        print(f"wrote {a.out}: {t.heights.shape[1]} x {t.heights.shape[0]} points, "
              f"rise {t.goal_height - t.floor_height:.3f} m, path "
              f"{t.spec['path_length']:.2f} m")
        if a.preview:
            from .preview import render_tile
            render_tile(t, a.preview)
            print(f"wrote {a.preview}")
    elif a.cmd == "atlas":
        from .atlas import build_atlas
        levels = None if a.levels is None else [int(v) - 1 for v in a.levels.split(",")]
        at = build_atlas(a.families, a.schedule, levels, a.variants, a.resolution, a.tile_size,
                         a.border)
        at.save(a.out)
        print(f"wrote {a.out}: {at.rows} x {at.cols} tiles, heights {at.heights.shape}")
    return 0


def _load_npz_heights(path: str):
    """Heights and resolution of a saved tile or atlas."""
    from .atlas import Atlas
    from .tile import Tile
    try:
        t = Tile.load(path)
        return t.heights, t.resolution
    except ValueError as e:
        if "not a saved tile" not in str(e):
            raise
    at = Atlas.load(path)
    return at.heights, at.resolution


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status (errors: one line on stderr, 2)."""
    try:
        return run(argv)
    except (ValueError, FileNotFoundError, OSError) as e:
        print(f"error: {str(e).splitlines()[0] if str(e) else type(e).__name__}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
