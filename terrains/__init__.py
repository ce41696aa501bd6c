"""terrains: procedural stair tiles, their level schedules, the atlas, mesh import/export.

numpy + trimesh only (no JAX). Frame: x forward, y left, z up, metres; heights[iy, ix] is the
height at grid point (ix * res, iy * res).
"""

from .atlas import Atlas, build_atlas, build_cell_atlas, build_tile_atlas, join_columns
from .building import Staircase, difficulty, sample_staircase, staircase_tile
from .families import FAMILIES, PAPER_FAMILIES, make_tile, variants
from .levels import SCHEDULES, BuildingLevel, Level, get_level, levels
from .tile import (
    CENTRELINE_POINTS,
    DEFAULT_RESOLUTION,
    DEFAULT_TILE_SIZE,
    DIRECTIONS,
    HEIGHT_QUANTUM,
    WALL_RISE,
    Tile,
    quantise,
    sample_heights,
)

__all__ = [
    "Atlas", "BuildingLevel", "CENTRELINE_POINTS", "DEFAULT_RESOLUTION", "DEFAULT_TILE_SIZE",
    "DIRECTIONS", "FAMILIES", "HEIGHT_QUANTUM", "PAPER_FAMILIES", "SCHEDULES", "Staircase",
    "WALL_RISE", "Level", "Tile", "build_atlas", "build_cell_atlas", "build_tile_atlas",
    "difficulty", "get_level", "join_columns",
    "levels",
    "make_tile", "quantise", "sample_heights", "sample_staircase", "staircase_tile", "variants",
]
