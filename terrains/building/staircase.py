"""The staircase record: one real indoor staircase as a frozen parameter set, its check, and the
difficulty index the building level schedule is ordered by.

A ``Staircase`` is one staircase: its shape (straight, L, U, three-flight switchback, spiral,
winder), turn (left / right; a spiral "left" climbs counter-clockwise), riser, tread, clear width,
risers per flight, landing depth, spiral core and turn, winder count, an open side (a drop-off to
the floor instead of a wall) and random tread height errors. ``difficulty`` orders staircases
riser first, then width, landing depth, curvature, open side.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..tile import HEIGHT_QUANTUM

SHAPES = ("straight", "l", "u", "switchback", "spiral", "winder")
FLIGHTS = {"straight": 1, "l": 2, "winder": 2, "u": 2, "switchback": 3, "spiral": 1}
# variant name -> (shape, turn); the family "building"'s variants, in this order
VARIANTS: dict[str, tuple[str, str]] = {
    "straight": ("straight", "left"),
    "l_left": ("l", "left"), "l_right": ("l", "right"),
    "u_left": ("u", "left"), "u_right": ("u", "right"),
    "switchback_left": ("switchback", "left"), "switchback_right": ("switchback", "right"),
    "spiral_ccw": ("spiral", "left"), "spiral_cw": ("spiral", "right"),
    "winder_left": ("winder", "left"), "winder_right": ("winder", "right"),
}


@dataclass(frozen=True)
class Staircase:
    """One staircase (metres). ``flights``: risers per flight (spiral: one flight; winder: the
    two straight flights, the winders come on top). ``landing``: depth of the landings
    (l: at least the width; ignored by straight, spiral and winder). ``inner_radius`` and
    ``turns`` (a multiple of 0.25, at most 1) only for spirals, ``winders`` only for winders.
    ``open_side``: the right side of the first flight is a drop-off. ``height_error``: amplitude
    of the tread height errors drawn from ``seed``."""

    shape: str
    riser: float
    tread: float
    width: float
    flights: tuple[int, ...]
    turn: str = "left"
    landing: float = 1.2
    inner_radius: float = 0.5
    turns: float = 0.75
    winders: int = 3
    open_side: bool = False
    height_error: float = 0.0
    seed: int = 0
    name: str = field(default="", compare=False)

    def __post_init__(self):
        object.__setattr__(self, "flights", tuple(int(n) for n in self.flights))
        check(self)

    @property
    def risers(self) -> int:
        """Risers from the start floor to the top landing."""
        return sum(self.flights) + (self.winders - 1 if self.shape == "winder" else 0)

    @property
    def total_rise(self) -> float:
        return float(np.round(self.risers * self.riser / HEIGHT_QUANTUM) * HEIGHT_QUANTUM)


def check(s: Staircase) -> None:
    """ValueError (one line) for a staircase that cannot be drawn."""
    if s.shape not in SHAPES:
        raise ValueError(f"unknown staircase shape {s.shape!r}; known: {', '.join(SHAPES)}")
    if s.turn not in ("left", "right"):
        raise ValueError(f"turn must be 'left' or 'right', got {s.turn!r}")
    if len(s.flights) != FLIGHTS[s.shape]:
        raise ValueError(f"a {s.shape} staircase has {FLIGHTS[s.shape]} flight(s), got "
                         f"{len(s.flights)}: {s.flights}")
    if min(s.flights) < 2:
        raise ValueError(f"every flight needs at least 2 risers, got {s.flights}")
    for name, lo in (("riser", 0.0), ("tread", 0.05), ("width", 0.7), ("landing", 0.5)):
        if not getattr(s, name) > lo:
            raise ValueError(f"{name} must be > {lo} m, got {getattr(s, name)}")
    if not 0 <= s.height_error < s.riser / 2:
        raise ValueError(f"height_error must be in [0, riser/2), got {s.height_error}")
    if s.shape == "spiral":
        if not (0.1 <= s.inner_radius and 0 < s.turns <= 1 and abs(s.turns * 4 - round(
                s.turns * 4)) < 1e-9):
            raise ValueError(f"spiral needs inner_radius >= 0.1 m and turns a multiple of 0.25 "
                             f"in (0, 1], got {s.inner_radius}, {s.turns}")
    if s.shape == "winder" and not 2 <= s.winders <= 6:
        raise ValueError(f"winders must be 2..6, got {s.winders}")


def difficulty(s: Staircase) -> float:
    """Difficulty index: riser first, then width, landing depth, curvature, open side.
    Each key is normalised to [0, 1] over the generator's ranges and weighted 1, 0.1, 0.01,
    0.001, 0.0001: the riser dominates (risers more than 2.2 cm apart, more than a train level's
    band, are always in riser order), then each key breaks the near-ties of the one before."""
    keys = difficulty_key(s)
    return float(sum(k * 10.0 ** -i for i, k in enumerate(keys)))


def difficulty_key(s: Staircase) -> tuple[float, float, float, float, float]:
    """(riser, narrowness, landing shallowness, curvature, open side), each in [0, 1]."""
    riser = np.clip((s.riser - 0.02) / 0.19, 0, 1)
    width = np.clip((2.0 - s.width) / 1.2, 0, 1)
    landing = np.clip((1.8 - s.landing) / 0.9, 0, 1) if s.shape in ("l", "u", "switchback") else 0
    if s.shape == "spiral":
        curv = 0.5 + 0.5 * np.clip((1.0 - s.inner_radius) / 0.7, 0, 1)
    elif s.shape == "winder":
        curv = 0.5 * np.clip((s.winders - 1) / 3, 0, 1)
    else:
        curv = 0.0
    return (float(riser), float(width), float(landing), float(curv), float(s.open_side))
