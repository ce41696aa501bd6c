"""Fixed test suites of staircases (data in suites.toml) and writing staircases as a folder of
meshes, each with a JSON of the same stem: the suite format the evaluator reads.

    {"mesh": "name.stl", "start": [x, y, z, yaw], "goal": [x, y, z, yaw],
     "route": [[x, y], ...], ...}

all in the mesh frame (metres, z up; the mesh frame is the tile frame: grid point (ix, iy) at
(ix * res, iy * res)). ``start`` is the spawn centre on the floor and its heading, ``goal`` the
goal point and heading, ``route`` the centre-line the waypoint follows. Further keys (name,
family, level, variant, direction, tile_size, resolution, spawn_half, spec) describe the case;
readers ignore what they do not know.
"""

from __future__ import annotations

import json
import os
import tomllib
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from .building import Staircase, spiral_max_risers, staircase_tile, tile_size_for
from .families import make_tile
from .tile import DEFAULT_RESOLUTION, DEFAULT_TILE_SIZE, Tile

SUITES_FILE = Path(__file__).with_name("suites.toml")


@dataclass(frozen=True)
class Case:
    """One staircase of a suite: either a building ``staircase`` or a ``family`` level
    (0-based, of ``schedule``, variant), walked ``direction``."""

    name: str
    direction: str
    staircase: Staircase | None = None
    family: str = "building"
    level: int = 0
    variant: str | None = None
    schedule: str = "test"

    def tile(self, resolution: float = DEFAULT_RESOLUTION, tile_size: float | None = None) -> Tile:
        """The case's tile; ``tile_size`` None: a building staircase gets the smallest whole
        metre that holds it, a family level the default 10 m."""
        if self.staircase is not None:
            return staircase_tile(self.staircase, resolution, tile_size, self.direction,
                                  family="building", variant=self.variant)
        return make_tile(self.family, self.level, self.variant, self.schedule, resolution,
                         DEFAULT_TILE_SIZE if tile_size is None else tile_size,
                         direction=self.direction)


def suite_names() -> tuple[str, ...]:
    with open(SUITES_FILE, "rb") as f:
        return tuple(tomllib.load(f))


def load_suite(name: str) -> list[Case]:
    """The cases of suite ``name`` ("code", "paper"); unknown name -> ValueError."""
    with open(SUITES_FILE, "rb") as f:
        data = tomllib.load(f)
    if name not in data:
        raise ValueError(f"unknown suite {name!r}; known suites: {', '.join(data)}")
    d = data[name]
    cases = []
    if "limits" in d:
        for lim, dims in d["limits"].items():
            for key, sh in d["shapes"].items():
                s = _code_staircase(sh, dims, f"{name}_{lim}_{key}")
                for direction in d["directions"]:
                    cases.append(Case(f"{s.name}_{direction}", direction, s, variant=key))
    else:
        for fam in d["families"]:
            for lvl in d["levels"]:
                for direction in d["directions"]:
                    cases.append(Case(f"{name}_{fam}_level{lvl}_{direction}", direction,
                                      family=fam, level=lvl - 1, schedule=d["schedule"]))
    return cases


def find_case(suite: str, name: str) -> Case:
    """The case ``name`` of suite ``suite``; unknown -> ValueError naming the known cases."""
    cases = {c.name: c for c in load_suite(suite)}
    if name not in cases:
        raise ValueError(f"no case {name!r} in suite {suite!r}; known: {', '.join(cases)}")
    return cases[name]


def _code_staircase(sh: dict, dims: dict, name: str) -> Staircase:
    kw = {k: v for k, v in sh.items() if k not in ("shape", "flights", "landing")}
    landing = dims["width"] if sh.get("landing") == "width" else sh.get("landing", 1.2)
    flights = (3,) if sh["flights"] == "fill" else tuple(sh["flights"])
    s = Staircase(sh["shape"], dims["riser"], dims["tread"], dims["width"], flights,
                  landing=landing, name=name, **kw)
    if sh["flights"] == "fill":
        s = replace(s, flights=(min(spiral_max_risers(s), 18),))
    return s


def case_record(tile: Tile, mesh_name: str, name: str) -> dict:
    """The JSON record of one case (see the module docstring)."""
    x, y, z, hx, hy, yaw, yaw_half = (float(v) for v in tile.spawn)
    spec = {k: v for k, v in tile.spec.items()
            if k in ("riser", "tread", "width", "steps", "flights_risers", "risers",
                     "total_rise", "landing", "shape", "turn", "open_side", "inner_radius",
                     "turns", "winders", "difficulty", "schedule", "height_error")}
    return dict(
        mesh=mesh_name, start=[round(v, 5) for v in (x, y, z, yaw)],
        goal=[round(float(v), 5) for v in tile.goal],
        route=[[round(float(p[0]), 4), round(float(p[1]), 4)] for p in tile.centreline],
        name=name, family=tile.family, level=int(tile.level) + 1, variant=tile.variant,
        direction=tile.direction, spawn_half=[round(v, 5) for v in (hx, hy, yaw_half)],
        tile_size=float(tile.heights.shape[1] * tile.resolution),
        resolution=float(tile.resolution), spec=spec)


def write_case(tile: Tile, folder: str | os.PathLike, name: str, fmt: str = "stl") -> dict:
    """Write ``name``.<fmt> (the tile's mesh) and ``name``.json into ``folder``."""
    from .mesh import export_tile
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    mesh_name = f"{name}.{fmt}"
    export_tile(tile, folder / mesh_name)
    rec = case_record(tile, mesh_name, name)
    tmp = folder / f".{name}.json.tmp"
    tmp.write_text(json.dumps(rec) + "\n")
    os.replace(tmp, folder / f"{name}.json")
    return rec


def write_suite(cases: list[Case], folder: str | os.PathLike,
                resolution: float = DEFAULT_RESOLUTION, fmt: str = "stl") -> list[dict]:
    """Every case as a mesh + JSON in ``folder``; returns the records."""
    return [write_case(c.tile(resolution), folder, c.name, fmt) for c in cases]


def suite_tile_size(cases: list[Case], resolution: float = DEFAULT_RESOLUTION) -> float:
    """One tile side that holds every case of a suite (for an atlas of equal tiles)."""
    sizes = [tile_size_for(c.staircase, resolution) if c.staircase is not None
             else DEFAULT_TILE_SIZE for c in cases]
    return float(np.max(sizes))
