"""terrains: procedural stair tiles, their level schedules, the atlas, mesh import/export.

numpy + trimesh only (no JAX). Frame: x forward, y left, z up, metres; heights[iy, ix] is the
height at grid point (ix * res, iy * res).
"""

from .atlas import Atlas, build_atlas, build_cell_atlas
from .families import FAMILIES, make_tile, variants
from .levels import SCHEDULES, Level, get_level, levels
from .tile import (
    CENTRELINE_POINTS,
    DEFAULT_RESOLUTION,
    DEFAULT_TILE_SIZE,
    HEIGHT_QUANTUM,
    WALL_RISE,
    Tile,
    quantise,
    sample_heights,
)

__all__ = [
    "Atlas", "CENTRELINE_POINTS", "DEFAULT_RESOLUTION", "DEFAULT_TILE_SIZE", "FAMILIES",
    "HEIGHT_QUANTUM", "SCHEDULES", "WALL_RISE", "Level", "Tile", "build_atlas", "build_cell_atlas",
    "get_level",
    "levels", "make_tile", "quantise", "sample_heights", "variants",
]
