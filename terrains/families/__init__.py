"""The stair families and ``make_tile``: one module per family.

Each family module has VARIANTS and either ``layout(level, variant) -> (Layout, transform)``
(stairs with walls, centred in the tile by common.build_tile) or ``make(...) -> Tile`` (pyramid;
building, which also takes ``seed=`` and ``schedule=`` and samples a staircase per tile).
Every tile can be walked "up" (the default) or "down" (Tile.reversed(): same heights).
"""

from __future__ import annotations

from dataclasses import replace
from types import ModuleType
from typing import Sequence

from ..levels import PAPER_FAMILIES, check_family, check_landing, get_level
from ..tile import DEFAULT_RESOLUTION, DEFAULT_TILE_SIZE, Tile
from . import building, l_shaped, pyramid, spiral, straight, u_shaped
from .common import build_tile

FAMILIES: dict[str, ModuleType] = {
    "pyramid": pyramid,
    "straight": straight,
    "l_shaped": l_shaped,
    "u_shaped": u_shaped,
    "spiral": spiral,
    "building": building,
    "pyramid_tall": pyramid,    # the pyramid to 21 cm risers (levels.py); tiles say "pyramid_tall"
}
assert tuple(FAMILIES)[:len(PAPER_FAMILIES)] == PAPER_FAMILIES


__all__ = ["FAMILIES", "PAPER_FAMILIES", "make_tile", "variants"]


def variants(family: str) -> tuple[str, ...]:
    """The variant names of ``family``; unknown family -> ValueError."""
    check_family(family)
    return FAMILIES[family].VARIANTS


def make_tile(family: str, level: int, variant: str | None = None, schedule: str = "train",
              resolution: float = DEFAULT_RESOLUTION,
              tile_size: float = DEFAULT_TILE_SIZE, direction: str = "up",
              seed: int = 0, building_landing: Sequence[float] | None = None) -> Tile:
    """One tile of ``family`` at 0-based ``level`` of ``schedule``: heights [n, n],
    n = tile_size / resolution. ``variant`` None -> the family's first variant.
    ``direction`` "down": the same tile walked from the top landing to the foot.
    ``seed``: which of the staircases sampled for (level, variant) (building only; the other
    families are deterministic and ignore it).
    ``building_landing``: (lo, hi) m, the landing-depth range the staircase is drawn from instead
    of the level's (building only; the other dimensions are drawn as without it)."""
    check_family(family)
    lv = get_level(family, level, schedule)
    if building_landing is not None:
        landing = check_landing(building_landing)
        if family == "building":
            lv = replace(lv, landing=landing)
    mod = FAMILIES[family]
    variant = mod.VARIANTS[0] if variant is None else variant
    if variant not in mod.VARIANTS:
        raise ValueError(f"unknown variant {variant!r} for {family!r}; known variants: "
                         f"{', '.join(mod.VARIANTS)}")
    level = int(level)
    if getattr(mod, "SEEDED", False):
        tile = mod.make(lv, level, variant, resolution, tile_size, seed=seed, schedule=schedule)
    elif hasattr(mod, "make"):   # the pyramid, also under the name pyramid_tall
        tile = mod.make(lv, level, variant, resolution, tile_size, family=family)
    else:
        lay, how = mod.layout(lv, variant)
        tile = build_tile(lay, how, family, level, variant, resolution, tile_size)
    tile.spec["schedule"] = schedule
    return tile.with_direction(direction)
