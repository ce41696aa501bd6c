"""The stair families and ``make_tile``: one module per family.

Each family module has VARIANTS and either ``layout(level, variant) -> (Layout, transform)``
(stairs with walls, centred in the tile by common.build_tile) or ``make(...) -> Tile`` (pyramid).
"""

from __future__ import annotations

from types import ModuleType

from ..levels import check_family, get_level
from ..tile import DEFAULT_RESOLUTION, DEFAULT_TILE_SIZE, Tile
from . import l_shaped, pyramid, spiral, straight, u_shaped
from .common import build_tile

FAMILIES: dict[str, ModuleType] = {
    "pyramid": pyramid,
    "straight": straight,
    "l_shaped": l_shaped,
    "u_shaped": u_shaped,
    "spiral": spiral,
}


def variants(family: str) -> tuple[str, ...]:
    """The variant names of ``family``; unknown family -> ValueError."""
    check_family(family)
    return FAMILIES[family].VARIANTS


def make_tile(family: str, level: int, variant: str | None = None, schedule: str = "train",
              resolution: float = DEFAULT_RESOLUTION,
              tile_size: float = DEFAULT_TILE_SIZE) -> Tile:
    """One tile of ``family`` at 0-based ``level`` of ``schedule``: heights [n, n],
    n = tile_size / resolution. ``variant`` None -> the family's first variant."""
    check_family(family)
    lv = get_level(family, level, schedule)
    mod = FAMILIES[family]
    variant = mod.VARIANTS[0] if variant is None else variant
    if variant not in mod.VARIANTS:
        raise ValueError(f"unknown variant {variant!r} for {family!r}; known variants: "
                         f"{', '.join(mod.VARIANTS)}")
    level = int(level)
    if hasattr(mod, "make"):
        tile = mod.make(lv, level, variant, resolution, tile_size)
    else:
        lay, how = mod.layout(lv, variant)
        tile = build_tile(lay, how, family, level, variant, resolution, tile_size)
    tile.spec["schedule"] = schedule
    return tile
