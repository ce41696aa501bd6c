"""Command line: python -m terrains {preview, export, import, atlas, suite, sample} ...

  preview FAMILY --level N [--variant V] [--schedule S] [--direction up|down] [--seed K]
          --out file.png
  export  FAMILY --level N [--variant V] [--schedule S] [--direction D] --out file.glb|.obj|.stl
  export  saved.npz --out file.glb           (a saved tile or atlas)
  import  mesh.obj --start x,y --goal x,y --out tile.npz [--preview file.png]
  atlas   FAMILY [FAMILY ...] [--schedule S] [--levels 1,2,3] [--variants K] [--direction D]
          --out atlas.npz
  suite   NAME --out DIR [--previews]       (a fixed suite: code, paper; mesh + JSON per case)
  sample  [--levels 1,5,10] [--variants all] [--directions up,down] [--seeds K] --out DIR
          (building staircases sampled from the building family's levels; mesh + JSON each)
Levels are 1-based on the command line. Errors print one line and exit with status 2.
"""

from __future__ import annotations

import argparse
import sys

from .levels import SCHEDULES
from .tile import DEFAULT_RESOLUTION, DEFAULT_TILE_SIZE, DIRECTIONS


def _xy(text: str) -> tuple[float, float]:
    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected x,y in metres, got {text!r}") from None
    return x, y


def _tile_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("family",
                   help="pyramid, straight, l_shaped, u_shaped, spiral, building or pyramid_tall")
    p.add_argument("--level", type=int, required=True, help="1-based level")
    p.add_argument("--variant", default=None,
                   help="e.g. left/right, cw/ccw, +x, u_left, spiral_cw (default: first)")
    p.add_argument("--schedule", default="train", choices=SCHEDULES)
    p.add_argument("--direction", default="up", choices=DIRECTIONS)
    p.add_argument("--seed", type=int, default=0, help="building: which sampled staircase")
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
    p.add_argument("--direction", default="up", choices=("up", "down", "both"))
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", required=True)
    p = sub.add_parser("suite", help="write a fixed suite (code, paper) as meshes + JSON")
    p.add_argument("name")
    _folder_args(p)
    p = sub.add_parser("sample", help="write sampled building staircases as meshes + JSON")
    p.add_argument("--levels", default="1,5,10", help="1-based building levels")
    p.add_argument("--schedule", default="train", choices=SCHEDULES)
    p.add_argument("--variants", default="all", help="comma separated, or all")
    p.add_argument("--directions", default="up,down")
    p.add_argument("--seeds", type=int, default=1, help="staircases per level and variant")
    p.add_argument("--tile-size", type=float, default=DEFAULT_TILE_SIZE,
                   help="the sampler fits every staircase into this square")
    _folder_args(p)
    return ap


def _folder_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--resolution", type=float, default=DEFAULT_RESOLUTION)
    p.add_argument("--format", default="stl", choices=("stl", "obj", "ply", "glb"))
    p.add_argument("--previews", action="store_true", help="also write name.png per case")
    p.add_argument("--out", required=True, help="folder")


def _make(a):
    from .families import make_tile
    from .levels import levels
    if a.level is None:
        raise ValueError("--level is required for a family")
    count = len(levels(a.family, a.schedule))
    if not 1 <= a.level <= count:
        raise ValueError(f"--level {a.level} out of range: {a.family} has levels 1..{count} "
                         f"in schedule {a.schedule!r}")
    return make_tile(a.family, a.level - 1, a.variant, a.schedule, a.resolution, a.tile_size,
                     direction=a.direction, seed=a.seed)


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
                         a.border, direction=a.direction, seed=a.seed)
        at.save(a.out)
        print(f"wrote {a.out}: {at.rows} x {at.cols} tiles, heights {at.heights.shape}")
    elif a.cmd in ("suite", "sample"):
        _write_folder(a)
    return 0


def _sample_cases(a):
    """(name, tile) of the sampled building staircases the ``sample`` command asks for."""
    from .families import make_tile, variants
    from .levels import levels as level_table
    count = len(level_table("building", a.schedule))
    lvls = [int(v) for v in a.levels.split(",")]
    for lv in lvls:
        if not 1 <= lv <= count:
            raise ValueError(f"--levels {lv} out of range: building has levels 1..{count}")
    names = variants("building") if a.variants == "all" else tuple(a.variants.split(","))
    dirs = tuple(a.directions.split(","))
    for d in dirs:
        if d not in DIRECTIONS:
            raise ValueError(f"--directions: unknown direction {d!r}; known: up, down")
    for lv in lvls:
        for v in names:
            for seed in range(a.seeds):
                up = make_tile("building", lv - 1, v, a.schedule, a.resolution, a.tile_size,
                               seed=seed)
                for d in dirs:
                    yield f"building_level{lv}_{v}_s{seed}_{d}", up.with_direction(d)


def _write_folder(a) -> None:
    from .suites import load_suite, write_case
    if a.cmd == "suite":
        cases = ((c.name, c.tile(a.resolution)) for c in load_suite(a.name))
    else:
        cases = _sample_cases(a)
    n = 0
    for name, tile in cases:
        write_case(tile, a.out, name, a.format)
        if a.previews:
            from .preview import render_tile
            render_tile(tile, f"{a.out}/{name}.png", size_px=450, title=name)
        n += 1
    print(f"wrote {n} cases ({a.format} + json) to {a.out}")


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
