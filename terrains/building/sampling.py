"""The building family's sampler: a staircase drawn inside a ``levels.BuildingLevel`` from a
seed fixed per tile, shortened until it fits a tile, and painted into a ``Tile``."""

from __future__ import annotations

import zlib
from dataclasses import replace

import numpy as np

from ..families.common import build_tile, footprint
from ..levels import BuildingLevel
from ..tile import DEFAULT_RESOLUTION, Tile
from .layouts import layout, spiral_max_risers
from .staircase import FLIGHTS, VARIANTS, Staircase

TILE_STEP = 1.0      # m, automatic tile sizes are whole multiples of it


def variant_seed(schedule: str, level: int, variant: str, seed: int) -> int:
    """A stable 32-bit seed for one tile."""
    return zlib.crc32(f"building/{schedule}/{level}/{variant}/{seed}".encode())


def _round(x: float, step: float) -> float:
    return round(float(np.round(x / step) * step), 6)


def sample_staircase(lv: BuildingLevel, variant: str, rng: np.random.Generator,
                     max_size: float | None = None,
                     resolution: float = DEFAULT_RESOLUTION) -> Staircase:
    """A staircase of shape/turn ``variant`` (a key of VARIANTS) drawn uniformly inside the
    level's ranges (riser to 1 mm, tread and widths to 1 cm). With ``max_size``, the longest
    flight loses risers (never below 3) until the staircase fits a tile of that side; the
    dimensions that make the level (riser, tread, width, landing) are kept."""
    if variant not in VARIANTS:
        raise ValueError(f"unknown building variant {variant!r}; known: {', '.join(VARIANTS)}")
    shape, turn = VARIANTS[variant]
    u = rng.uniform
    riser = _round(u(*lv.riser), 0.001)
    tread = _round(u(*lv.tread), 0.01)
    width = _round(u(*lv.width), 0.01)
    landing = _round(u(*lv.landing), 0.01)
    lo, hi = lv.steps
    flights = [int(rng.integers(lo, hi + 1)) for _ in range(FLIGHTS[shape])]
    if shape in ("l", "winder", "u", "switchback") and rng.uniform() < 0.5:
        flights = [flights[0]] * len(flights)          # half of them with equal flights
    extra: dict = {}
    if shape == "spiral":
        r_in = _round(u(*lv.inner_radius), 0.01)
        quarters = [q / 4 for q in range(1, int(round(lv.max_turns * 4)) + 1)]
        # the smallest quarter turn that holds at least 3 risers, then as many as drawn fit
        best = None
        for q in quarters:
            probe = Staircase("spiral", riser, tread, width, (3,), turn, inner_radius=r_in,
                              turns=q)
            if spiral_max_risers(probe) >= 3:
                best = q if best is None or rng.uniform() < 0.5 else best
        if best is None:
            r_in, best = 1.0, 1.0       # always fits: 1 m core, full turn
        extra = dict(inner_radius=r_in, turns=best)
        probe = Staircase("spiral", riser, tread, width, (3,), turn, **extra)
        flights = [max(min(spiral_max_risers(probe), hi, 18), 3)]   # fill the turn
    elif shape == "winder":
        extra = dict(winders=int(np.clip(round(np.pi / 4 * width / tread), 2, 4)))
    open_side = bool(rng.uniform() < lv.open_prob)
    err = _round(lv.height_error, 0.001)
    s = Staircase(shape, riser, tread, width, tuple(flights), turn, landing=landing,
                  open_side=open_side, height_error=min(err, riser / 2 - 0.001),
                  seed=int(rng.integers(2 ** 31)), **extra)
    if max_size is not None:
        s = fit(s, max_size, resolution)
    return s


def fit(s: Staircase, max_size: float, resolution: float = DEFAULT_RESOLUTION) -> Staircase:
    """``s`` with risers taken from its longest flights until it fits a tile of ``max_size``;
    ValueError if even 3 risers per flight do not fit."""
    while footprint(layout(s)[0], resolution) > max_size + 1e-9:
        k = int(np.argmax(s.flights))
        if s.flights[k] <= 3:
            raise ValueError(f"{s.shape} staircase (width {s.width} m) does not fit a "
                             f"{max_size} m tile even with 3 risers per flight")
        f = list(s.flights)
        f[k] -= 1
        s = replace(s, flights=tuple(f))
    return s


def tile_size_for(s: Staircase, resolution: float = DEFAULT_RESOLUTION) -> float:
    """The smallest tile side, a whole multiple of TILE_STEP (1 m), that holds ``s``."""
    need = footprint(layout(s)[0], resolution)
    return float(np.ceil(need / TILE_STEP - 1e-9) * TILE_STEP)


def staircase_tile(s: Staircase, resolution: float = DEFAULT_RESOLUTION,
                   tile_size: float | None = None, direction: str = "up",
                   family: str = "building", level: int = 0,
                   variant: str | None = None) -> Tile:
    """Paint ``s`` into a Tile walked ``direction``; ``tile_size`` None: tile_size_for(s)."""
    if tile_size is None:
        tile_size = tile_size_for(s, resolution)
    if variant is None:
        variant = s.name or _variant_of(s)
    lay, how = layout(s)
    tile = build_tile(lay, how, family, level, variant, resolution, tile_size)
    return tile.with_direction(direction)


def _variant_of(s: Staircase) -> str:
    for name, (shape, turn) in VARIANTS.items():
        if shape == s.shape and (turn == s.turn or shape == "straight"):
            return name
    return s.shape
