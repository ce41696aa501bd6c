"""The ``building`` family: real indoor staircases (terrains/building/), one sampled per tile.

Variants are the shapes and turns (``building.VARIANTS``); a level is a ``BuildingLevel`` of
ranges; the staircase of a tile is drawn from a seed fixed by (schedule, level, variant, seed),
so a tile is reproducible and the ``test`` schedule (same ranges) gets other staircases than
``train``. The longest flights are shortened until the staircase fits ``tile_size``.
"""

from __future__ import annotations

import numpy as np

from ..building import VARIANTS as _VARIANTS
from ..building import sample_staircase, staircase_tile, variant_seed
from ..levels import BuildingLevel
from ..tile import Tile

VARIANTS = tuple(_VARIANTS)
SEEDED = True   # make() takes seed= and schedule=


def make(lv: BuildingLevel, level: int, variant: str, resolution: float, tile_size: float,
         seed: int = 0, schedule: str = "train") -> Tile:
    """[n, n] tile, n = tile_size / resolution, of the staircase sampled for this tile."""
    rng = np.random.default_rng(variant_seed(schedule, level, variant, seed))
    s = sample_staircase(lv, variant, rng, max_size=tile_size, resolution=resolution)
    tile = staircase_tile(s, resolution, tile_size, family="building", level=level,
                          variant=variant)
    tile.spec["seed"] = int(seed)
    return tile
