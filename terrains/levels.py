"""Level schedules of every stair family, as data.

A level is a small frozen dataclass of the staircase's dimensions. Three schedules:

- ``train``: the 10 curriculum levels of the protocol (shared/reference/protocol.md), linear in
  riser and width from level 1 to level 10, rounded to 1 mm (riser) and 1 cm (width);
- ``test``: the 6 test levels of the paper (risers 4, 6, 8, 10, 12, 14 cm, width 2.0 m, landing
  1.4 m); for ``pyramid`` the test schedule is the train schedule;
- ``extended``: past the paper toward building-code stairs (risers up to 0.20 m, treads down to
  0.25 m, widths down to 0.9 m).

The ``building`` family (real indoor staircases, terrains/building/) has levels that are
RANGES (``BuildingLevel``): every tile samples its own staircase inside them. Its train levels
are ordered by the difficulty index (riser band first, then narrower width, shallower landings,
tighter curvature, open sides); ``test`` has the same bands (tiles use other seeds),
``extended`` the hardest, building-code corner of the space. Their landing-depth lower bound
falls with the level; ``build_atlas(building_landing=(lo, hi))`` gives every building level one
landing-depth range instead (``check_landing``).

Level indices are 0-based everywhere in code; file names and the CLI's ``--level`` are 1-based.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass

import numpy as np

SCHEDULES = ("train", "test", "extended")
BUILDING_LANDING = (0.6, 3.0)   # m: bounds of a landing-depth range that overrides the levels'


@dataclass(frozen=True)
class Level:
    """Dimensions of one staircase, metres.

    riser:   height of every step.
    tread:   depth of every step (spiral: measured on the walking line, the middle of the width).
    width:   clear width of a flight between its walls (pyramid: unused, 0).
    steps:   risers per flight (pyramid: 0 = as many as fit the tile).
    landing: depth of the landing at the turn (u_shaped; l_shaped uses max(landing, width)).
    """

    riser: float
    tread: float
    width: float
    steps: int
    landing: float = 0.0


@dataclass(frozen=True)
class BuildingLevel:
    """Ranges a ``building`` tile samples its staircase from (metres, (lo, hi) inclusive).

    riser, tread, width, landing: dimension ranges; steps: risers per flight;
    inner_radius: spiral core radius; max_turns: largest spiral turn (quarter turns);
    open_prob: probability that one side is open (a drop-off) instead of walled;
    height_error: amplitude of the random tread height errors (uniform +-, whole mm).
    """

    riser: tuple[float, float]
    tread: tuple[float, float] = (0.24, 0.35)
    width: tuple[float, float] = (0.8, 2.0)
    landing: tuple[float, float] = (0.9, 1.8)
    steps: tuple[int, int] = (3, 18)
    inner_radius: tuple[float, float] = (0.3, 1.0)
    max_turns: float = 1.0
    open_prob: float = 0.0
    height_error: float = 0.005


def _building(n: int, riser=(0.02, 0.21), width_lo=(1.88, 0.8), landing_lo=(1.71, 0.9),
              radius_lo=(0.93, 0.3), turns=(0.5, 1.0), open_prob=(0.0, 0.5),
              steps_hi=(8, 18), open_from: int = 5) -> tuple[BuildingLevel, ...]:
    """n levels: riser bands split [riser] evenly (the first key of the difficulty index); the
    most risers per flight grows, the lower bounds of width, landing depth and spiral radius
    fall, the spiral turn and the chance of an open side grow linearly from level 1 to level n
    (open sides from level open_from)."""
    edges = [round(riser[0] + (riser[1] - riser[0]) * i / n, 3) for i in range(n + 1)]
    out = []
    for i in range(n):
        f = i / max(n - 1, 1)

        def lerp(ab, f=f):
            return ab[0] + (ab[1] - ab[0]) * f
        turns_i = np.floor(lerp(turns) * 4 + 1e-9) / 4
        p_open = 0.0 if i + 1 < open_from else lerp(open_prob)
        out.append(BuildingLevel(
            riser=(edges[i], edges[i + 1]), width=(round(lerp(width_lo), 2), 2.0),
            landing=(round(lerp(landing_lo), 2), 1.8), steps=(3, int(round(lerp(steps_hi)))),
            inner_radius=(round(lerp(radius_lo), 2), 1.0), max_turns=float(turns_i),
            open_prob=round(p_open, 3)))
    return tuple(out)


def _table(rows: list[tuple], landing: float = 0.0) -> tuple[Level, ...]:
    """rows of (riser, tread, width, steps[, landing]) -> tuple of Level."""
    out = []
    for row in rows:
        riser, tread, width, steps = row[:4]
        out.append(Level(riser, tread, width, steps, row[4] if len(row) > 4 else landing))
    return tuple(out)


# ---------------------------------------------------------------- train (protocol, 10 levels)
# (riser, tread, width, steps)
_PYRAMID_TRAIN = _table([
    (0.000, 0.30, 0.0, 0), (0.017, 0.30, 0.0, 0), (0.033, 0.30, 0.0, 0), (0.050, 0.30, 0.0, 0),
    (0.067, 0.30, 0.0, 0), (0.083, 0.30, 0.0, 0), (0.100, 0.30, 0.0, 0), (0.117, 0.30, 0.0, 0),
    (0.133, 0.30, 0.0, 0), (0.150, 0.30, 0.0, 0),
])
# Stage 1 widened to the building codes' risers (issue 24's option): the pyramid's rings from flat
# to 21 cm risers, treads from 0.30 to 0.25 m, linear over the 10 levels (the commercial limit,
# 17.8 / 27.9 cm, lies between levels 8 and 9; the residential 19.7 / 25.4 cm at level 10)
_PYRAMID_TALL_TRAIN = _table([
    (round(0.21 * i / 9, 3), round(0.30 - 0.05 * i / 9, 3), 0.0, 0) for i in range(10)])
_STRAIGHT_TRAIN = _table([
    (0.040, 0.30, 3.00, 10), (0.051, 0.30, 2.83, 10), (0.062, 0.30, 2.67, 10),
    (0.073, 0.30, 2.50, 10), (0.084, 0.30, 2.33, 10), (0.096, 0.30, 2.17, 10),
    (0.107, 0.30, 2.00, 10), (0.118, 0.30, 1.83, 10), (0.129, 0.30, 1.67, 10),
    (0.140, 0.30, 1.50, 10),
])
_L_SHAPED_TRAIN = _table([
    (0.020, 0.26, 2.00, 8), (0.034, 0.26, 1.91, 8), (0.049, 0.26, 1.82, 8),
    (0.063, 0.26, 1.73, 8), (0.078, 0.26, 1.64, 8), (0.092, 0.26, 1.56, 8),
    (0.107, 0.26, 1.47, 8), (0.121, 0.26, 1.38, 8), (0.136, 0.26, 1.29, 8),
    (0.150, 0.26, 1.20, 8),
])
_U_SHAPED_TRAIN = _table([
    (0.020, 0.26, 2.00, 10), (0.031, 0.26, 1.93, 10), (0.042, 0.26, 1.87, 10),
    (0.053, 0.26, 1.80, 10), (0.064, 0.26, 1.73, 10), (0.076, 0.26, 1.67, 10),
    (0.087, 0.26, 1.60, 10), (0.098, 0.26, 1.53, 10), (0.109, 0.26, 1.47, 10),
    (0.120, 0.26, 1.40, 10),
], landing=1.2)
# spiral: steps grow so the sweep goes from ~0.2 to ~0.47 turns (turns = (steps-1)*tread/(2 pi R))
_SPIRAL_TRAIN = _table([
    (0.020, 0.26, 2.50, 11), (0.031, 0.26, 2.44, 12), (0.042, 0.26, 2.39, 13),
    (0.053, 0.26, 2.33, 14), (0.064, 0.26, 2.28, 15), (0.076, 0.26, 2.22, 17),
    (0.087, 0.26, 2.17, 18), (0.098, 0.26, 2.11, 19), (0.109, 0.26, 2.06, 20),
    (0.120, 0.26, 2.00, 21),
])

# ---------------------------------------------------------------- test (paper, 6 levels)
_TEST_RISERS = (0.04, 0.06, 0.08, 0.10, 0.12, 0.14)
_STRAIGHT_TEST = _table([(r, 0.30, 2.0, 10) for r in _TEST_RISERS], landing=1.4)
_L_SHAPED_TEST = _table([(r, 0.26, 2.0, 8) for r in _TEST_RISERS], landing=1.4)
_U_SHAPED_TEST = _table([(r, 0.26, 2.0, 10) for r in _TEST_RISERS], landing=1.4)
_SPIRAL_TEST = _table([(r, 0.26, 2.0, 18) for r in _TEST_RISERS], landing=1.4)  # ~0.40 turns

# ---------------------------------------------------------------- extended (building codes)
_PYRAMID_EXT = _table([
    (0.160, 0.30, 0.0, 0), (0.168, 0.29, 0.0, 0), (0.176, 0.28, 0.0, 0),
    (0.184, 0.27, 0.0, 0), (0.192, 0.26, 0.0, 0), (0.200, 0.25, 0.0, 0),
])
_STRAIGHT_EXT = _table([
    (0.150, 0.30, 1.40, 10), (0.160, 0.29, 1.30, 10), (0.170, 0.28, 1.20, 10),
    (0.180, 0.27, 1.10, 10), (0.190, 0.26, 1.00, 10), (0.200, 0.25, 0.90, 10),
])
_L_SHAPED_EXT = _table([
    (0.160, 0.260, 1.20, 8), (0.168, 0.258, 1.14, 8), (0.176, 0.256, 1.08, 8),
    (0.184, 0.254, 1.02, 8), (0.192, 0.252, 0.96, 8), (0.200, 0.250, 0.90, 8),
])
_U_SHAPED_EXT = _table([
    (0.130, 0.260, 1.40, 10), (0.144, 0.258, 1.30, 10), (0.158, 0.256, 1.20, 10),
    (0.172, 0.254, 1.10, 10), (0.186, 0.252, 1.00, 10), (0.200, 0.250, 0.90, 10),
], landing=1.2)
_SPIRAL_EXT = _table([
    (0.130, 0.260, 2.00, 20), (0.144, 0.258, 1.78, 19), (0.158, 0.256, 1.56, 18),
    (0.172, 0.254, 1.34, 17), (0.186, 0.252, 1.12, 16), (0.200, 0.250, 0.90, 15),
])

# building: risers 2-21 cm in 10 bands of 1.9 cm; extended: 6 bands of 17-21 cm, narrow, open
_BUILDING_TRAIN = _building(10)
_BUILDING_EXT = _building(6, riser=(0.17, 0.21), width_lo=(1.0, 0.8), landing_lo=(1.0, 0.9),
                          radius_lo=(0.5, 0.3), turns=(1.0, 1.0), open_prob=(0.3, 0.5),
                          steps_hi=(18, 18), open_from=1)

LEVELS: dict[str, dict[str, tuple]] = {
    "pyramid": {"train": _PYRAMID_TRAIN, "test": _PYRAMID_TRAIN, "extended": _PYRAMID_EXT},
    "straight": {"train": _STRAIGHT_TRAIN, "test": _STRAIGHT_TEST, "extended": _STRAIGHT_EXT},
    "l_shaped": {"train": _L_SHAPED_TRAIN, "test": _L_SHAPED_TEST, "extended": _L_SHAPED_EXT},
    "u_shaped": {"train": _U_SHAPED_TRAIN, "test": _U_SHAPED_TEST, "extended": _U_SHAPED_EXT},
    "spiral": {"train": _SPIRAL_TRAIN, "test": _SPIRAL_TEST, "extended": _SPIRAL_EXT},
    "building": {"train": _BUILDING_TRAIN, "test": _BUILDING_TRAIN, "extended": _BUILDING_EXT},
    "pyramid_tall": {"train": _PYRAMID_TALL_TRAIN, "test": _PYRAMID_TALL_TRAIN,
                     "extended": _PYRAMID_EXT},
}
PAPER_FAMILIES = ("pyramid", "straight", "l_shaped", "u_shaped", "spiral")


def check_family(family: str) -> None:
    """Raise ValueError naming ``family`` and the known families if it is unknown."""
    if family not in LEVELS:
        raise ValueError(f"unknown terrain family {family!r}; known families: {', '.join(LEVELS)}")


def check_schedule(schedule: str) -> None:
    """Raise ValueError naming ``schedule`` and the known schedules if it is unknown."""
    if schedule not in SCHEDULES:
        raise ValueError(f"unknown level schedule {schedule!r}; known schedules: "
                         f"{', '.join(SCHEDULES)}")


def levels(family: str, schedule: str = "train") -> tuple[Level, ...] | tuple[BuildingLevel, ...]:
    """The levels of ``family`` in ``schedule`` (0-based index = level)."""
    check_family(family)
    check_schedule(schedule)
    return LEVELS[family][schedule]


def get_level(family: str, level: int, schedule: str = "train") -> Level | BuildingLevel:
    """One level, 0-based; out of range -> ValueError."""
    table = levels(family, schedule)
    if (not isinstance(level, numbers.Integral) or isinstance(level, bool)
            or not 0 <= level < len(table)):
        raise ValueError(f"level {level!r} out of range for {family!r} schedule {schedule!r}: "
                         f"valid 0..{len(table) - 1} (0-based)")
    return table[int(level)]


def check_landing(landing, name: str = "building_landing") -> tuple[float, float]:
    """``landing`` as (lo, hi) metres: a landing-depth range that replaces the one of every
    building level. ValueError naming ``name`` unless it is two numbers with
    BUILDING_LANDING[0] <= lo <= hi <= BUILDING_LANDING[1]."""
    lo_b, hi_b = BUILDING_LANDING
    try:
        lo, hi = (float(x) for x in landing)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected two numbers [lo, hi] (m), got {landing!r}") from None
    if not lo_b <= lo <= hi <= hi_b:
        raise ValueError(f"{name}: expected {lo_b} <= lo <= hi <= {hi_b} m, got {[lo, hi]}")
    return lo, hi
