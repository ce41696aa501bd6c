"""Building staircases: real indoor stairs described by a parameter record, sampled per tile.

- staircase.py: the record (``Staircase``: shape, turn, riser, tread, width, flights, landing,
  spiral core and turn, winders, open side, tread height errors), its check, ``difficulty``.
- regions.py: tread heights and the regions a flight, a spiral sector or a winder paints.
- layouts.py: ``layout``, a staircase as a ``families.common.Layout`` in its canonical frame
  (the shapes and what they mean are described there).
- sampling.py: ``sample_staircase`` inside a ``levels.BuildingLevel``, ``fit`` to a tile,
  ``staircase_tile`` paints it into a Tile.
"""

from .layouts import DIVIDER, OPEN_WIDTH, layout, spiral_angles, spiral_max_risers
from .sampling import (
    TILE_STEP,
    fit,
    sample_staircase,
    staircase_tile,
    tile_size_for,
    variant_seed,
)
from .staircase import FLIGHTS, SHAPES, VARIANTS, Staircase, check, difficulty, difficulty_key

__all__ = [
    "DIVIDER", "FLIGHTS", "OPEN_WIDTH", "SHAPES", "TILE_STEP", "VARIANTS", "Staircase", "check",
    "difficulty", "difficulty_key", "fit", "layout", "sample_staircase", "spiral_angles",
    "spiral_max_risers", "staircase_tile", "tile_size_for", "variant_seed",
]
