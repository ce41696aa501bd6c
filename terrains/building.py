"""Building staircases: real indoor stairs described by a parameter record, sampled per tile.

A ``Staircase`` is one staircase: its shape (straight, L, U, three-flight switchback, spiral,
winder), turn (left / right; a spiral "left" climbs counter-clockwise), riser, tread, clear width,
risers per flight, landing depth, spiral core and turn, winder count, an open side (a drop-off to
the floor instead of a wall) and random tread height errors. ``layout`` turns it into a
``families.common.Layout`` (canonical frame: left turn, first flight climbing +x), which
``families.common.build_tile`` centres in a tile, mirrors for right turns and paints; everything
that is not start floor, flight, landing, top landing or the floor beside an open side is wall.
``sample_staircase`` draws one inside a ``levels.BuildingLevel``; ``difficulty`` is the index the
level schedule is ordered by (riser first, then width, landing depth, curvature, open side).

Frame and heights as every tile: x forward, y left, z up, metres, multiples of 1 mm. The start
floor is at 0; landings and the top landing are exact multiples of the riser; only the treads
between them carry the height errors (whole mm, |e| <= height_error), so every flight starts and
ends level and the riser measured on the grid is riser + e_k - e_(k-1).

Shapes and what they mean here (canonical, left turn):
  straight    start floor, one flight, top landing.
  l           flight 1 along +x, a landing max(landing, width) deep at the 90 degree turn,
              flight 2 along +y, top landing.
  winder      as l, the landing replaced by ``winders`` steps radiating from the inner corner
              (each rises one riser; tread measured on the walking line, width/2 from it).
  u           flight 1 along +x, a landing spanning both flights, flight 2 back along -x beside
              it behind a 0.2 m dividing wall, top landing; flights may differ in length.
  switchback  three flights side by side (+x, -x, +x) joined by two landings spanning two
              flights each, 0.2 m dividing walls.
  spiral      an annulus around a solid core (inner_radius); the walker enters along a straight
              corridor pointing at the core, walks the annulus counter-clockwise through a flat
              entry sector, the flight and a flat exit sector, and leaves along a corridor
              pointing away from the core at ``turns`` (quarter turns, up to one full turn) from
              the entry; a 0.2 m wall separates exit from entry. The tread is measured on the
              walking line r = inner_radius + width / 2. A heightfield cannot hold a landing above
              the start, so a full turn is the walking line's turn from entry to exit.
Open side: a strip OPEN_WIDTH wide at floor height along the right side of the first flight and
the landing after it (outside the annulus for a spiral), walled beyond: a drop-off as on a site
before the railings go in.
"""

from __future__ import annotations

import zlib
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from .families.common import (
    EPS,
    MIN_WALL,
    START_LENGTH,
    TOP_LENGTH,
    Layout,
    arc,
    build_tile,
    footprint,
    line,
    rect,
)
from .levels import BuildingLevel
from .tile import DEFAULT_RESOLUTION, HEIGHT_QUANTUM, Tile

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
DIVIDER = MIN_WALL   # m, wall between side-by-side flights and between a spiral's exit and entry
OPEN_WIDTH = 0.8     # m, floor strip beside an open side before the wall
TILE_STEP = 1.0      # m, automatic tile sizes are whole multiples of it


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


# ------------------------------------------------------------------ regions with given heights
def _tread_heights(s: Staircase) -> list[np.ndarray]:
    """Per flight, the heights of its n-1 treads (and, for a winder, of the winders as a third
    entry), with the errors drawn from s.seed; landings stay exact."""
    rng = np.random.default_rng(s.seed)
    q = HEIGHT_QUANTUM
    amp = int(np.floor(s.height_error / q + 1e-9))
    if s.shape == "winder":   # flight 1, winders 2..m (winder 1 is level with flight 1's top)
        n1, n2 = s.flights
        counts, bases = [n1, s.winders, n2], [0, n1, n1 + s.winders - 1]
    else:
        counts = list(s.flights)
        bases = [int(v) for v in np.cumsum([0] + counts[:-1])]
    out = []
    for n, base in zip(counts, bases, strict=True):
        k = np.arange(1, n)
        err = rng.integers(-amp, amp + 1, size=n - 1) if amp else np.zeros(n - 1, int)
        out.append(np.round((base + k) * s.riser / q) * q + err * q)
    return out


def _level(z: float) -> float:
    return float(np.round(z / HEIGHT_QUANTUM) * HEIGHT_QUANTUM)


def _flight(axis: int, u0: float, heights: np.ndarray, tread: float, c0: float, c1: float,
            climb: int):
    """Treads of a straight flight covering [u0, u0 + (n-1) tread) along ``axis`` (0: x, 1: y)
    and [c0, c1) across; climb +1: tread j has heights[j] (climbs toward +axis), -1: heights
    reversed (climbs toward -axis)."""
    m = len(heights)
    u1 = u0 + m * tread
    h = np.asarray(heights, float) if climb > 0 else np.asarray(heights, float)[::-1]

    def region(X, Y):
        u, v = (X, Y) if axis == 0 else (Y, X)
        mask = (u >= u0 - EPS) & (u < u1 - EPS) & (v >= c0 - EPS) & (v < c1 - EPS)
        j = np.clip(np.floor((u - u0) / tread + 1e-6), 0, m - 1).astype(int)
        return mask, h[j]
    return region


def _angle(X, Y, centre):
    """Angle of (X, Y) about ``centre`` in [0, 2 pi)."""
    return np.mod(np.arctan2(Y - centre[1], X - centre[0]), 2 * np.pi)


def _sector(centre, r0: float, r1: float, th0: float, th1: float, heights, extra=None):
    """Annulus r0 <= r < r1 between angles th0 <= theta < th1 (in [0, 2 pi), counter-clockwise)
    split into len(heights) equal angular steps of the given heights; ``extra`` (X, Y) -> mask
    further restricts it."""
    h = np.asarray(heights, float)
    m = len(h)

    def region(X, Y):
        r = np.hypot(X - centre[0], Y - centre[1])
        th = _angle(X, Y, centre)
        mask = (r >= r0 - EPS) & (r < r1 - EPS) & (th >= th0 - 1e-9) & (th < th1 - 1e-9)
        if extra is not None:
            mask &= extra(X, Y)
        j = np.clip(np.floor((th - th0) / ((th1 - th0) / m) + 1e-9), 0, m - 1).astype(int)
        return mask, h[j]
    return region


def _winders(corner, w: float, heights):
    """The w x w square below-right of the inner corner (x >= cx, y < cy), split by rays from
    the corner into len(heights) equal angles from -90 deg (leaving flight 1) to 0 deg."""
    h = np.asarray(heights, float)
    m = len(h)
    cx, cy = corner

    def region(X, Y):
        mask = (X >= cx - EPS) & (X < cx + w - EPS) & (Y >= cy - w - EPS) & (Y < cy - EPS)
        phi = np.arctan2(Y - cy, X - cx) + np.pi / 2     # 0 .. pi/2 across the square
        j = np.clip(np.floor(phi / (np.pi / 2 / m) + 1e-9), 0, m - 1).astype(int)
        return mask, h[j]
    return region


# ------------------------------------------------------------------ layouts
def layout(s: Staircase) -> tuple[Layout, str]:
    """The staircase in its canonical frame (left turn) and the variant transform ("" or
    "mirror" for a right turn)."""
    make = {"straight": _zigzag, "u": _zigzag, "switchback": _zigzag, "l": _l_turn,
            "winder": _l_turn, "spiral": _spiral}[s.shape]
    lay = make(s)
    lay.spec.update(shape=s.shape, turn=s.turn, riser=s.riser, tread=s.tread, width=s.width,
                    steps=max(s.flights), flights_risers=list(s.flights), risers=s.risers,
                    total_rise=s.total_rise, open_side=s.open_side,
                    height_error=s.height_error, difficulty=difficulty(s),
                    staircase=asdict(s))
    return lay, "" if s.turn == "left" else "mirror"


def _zigzag(s: Staircase) -> Layout:
    """straight (1 flight), u (2), switchback (3): flights in side-by-side columns of width w,
    alternately climbing +x and -x, joined by landings spanning two columns."""
    w, t, d = s.width, s.tread, s.landing
    heights = _tread_heights(s)
    col = [k * (w + DIVIDER) for k in range(len(s.flights))]     # column k: y in [col, col + w)
    regions, path, flights = [], [], []
    a = START_LENGTH                         # first riser of flight 1
    regions.append(rect(0, a, 0, w, 0.0))
    path.append((a / 2, w / 2))
    base, x, lo_x, hi_x = 0, a, 0.0, a
    top_rect = None
    for k, n in enumerate(s.flights):
        climb = 1 if k % 2 == 0 else -1
        yc = col[k] + w / 2
        run = (n - 1) * t
        u0 = x if climb > 0 else x - run
        regions.append(_flight(0, u0, heights[k], t, col[k], col[k] + w, climb))
        base += n
        z = _level(base * s.riser)
        flights.append(dict(kind="straight", start=[x, yc], dir=[float(climb), 0.0], n=n,
                            base=_level((base - n) * s.riser), top=z, width=w,
                            heights=[float(v) for v in heights[k]]))
        end = x + climb * run                  # last riser
        last = k == len(s.flights) - 1
        depth = TOP_LENGTH if last else d
        l0, l1 = (end, end + depth) if climb > 0 else (end - depth, end)
        ys = (col[k], col[k] + w) if last else (col[k], col[k + 1] + w)
        regions.append(rect(l0, l1, *ys, z))
        lo_x, hi_x = min(lo_x, l0), max(hi_x, l1)
        xm = (l0 + l1) / 2
        if last:
            path.append((xm, yc))
            goal = (xm, yc, 0.0 if climb > 0 else np.pi)
            top_rect = (l0, l1, col[k], col[k] + w)
        else:
            path += [(xm, yc), (xm, col[k + 1] + w / 2)]
        x = end
    y_hi = col[-1] + w
    outline = [[lo_x, 0.0], [hi_x, y_hi]]
    if s.open_side:   # floor strip right of flight 1 and its landing (y < 0)
        x_end = START_LENGTH + (s.flights[0] - 1) * t + (d if len(s.flights) > 1 else TOP_LENGTH)
        regions.insert(0, rect(0, x_end, -OPEN_WIDTH, 0, 0.0))
        outline.append([0.0, -OPEN_WIDTH])
        flights[0]["open_dir"] = [0.0, -1.0]
    return Layout(
        regions=regions, outline=np.array(outline), spawn_rect=(0, a, 0, w), spawn_yaw=0.0,
        goal=goal, path=[line(p, q) for p, q in zip(path[:-1], path[1:], strict=True)],
        floor_height=0.0, goal_height=s.total_rise, flights=flights, top_rect=top_rect,
        spec=dict(landing=d if len(s.flights) > 1 else 0.0, divider=DIVIDER))


def _l_turn(s: Staircase) -> Layout:
    """l and winder: flight 1 along +x in y [0, w), the turn, flight 2 along +y."""
    w, t = s.width, s.tread
    heights = _tread_heights(s)
    n1, n2 = s.flights
    a = START_LENGTH
    xl = a + (n1 - 1) * t                  # last riser of flight 1
    winder = s.shape == "winder"
    depth = w if winder else max(s.landing, w)
    x2 = xl + depth - w                    # flight 2: x in [x2, x2 + w)
    yt = w + (n2 - 1) * t                  # last riser of flight 2
    mid = _level(n1 * s.riser)
    base2 = n1 + (s.winders - 1 if winder else 0)
    top = s.total_rise
    regions = [rect(0, a, 0, w, 0.0), _flight(0, a, heights[0], t, 0, w, 1)]
    flights = [dict(kind="straight", start=[a, w / 2], dir=[1.0, 0.0], n=n1, base=0.0, top=mid,
                    width=w, heights=[float(v) for v in heights[0]])]
    goal = (x2 + w / 2, yt + TOP_LENGTH / 2, np.pi / 2)
    if winder:
        wh = np.concatenate([[mid], heights[1]])      # winder 1 at the top of flight 1
        regions.append(_winders((xl, w), w, wh))
        flights.append(dict(kind="winder", centre=[xl, w], radius=w / 2, theta0=-np.pi / 2,
                            sweep=np.pi / 2, n=s.winders, base=mid, top=float(wh[-1]), width=w,
                            heights=[float(v) for v in wh]))
        path = [line((a / 2, w / 2), (xl, w / 2)), arc((xl, w), w / 2, -np.pi / 2, 0.0),
                line((xl + w / 2, w), goal[:2])]
    else:
        regions.append(rect(xl, xl + depth, 0, w, mid))
        corner = (x2 + w / 2, w / 2)
        path = [line((a / 2, w / 2), corner), line(corner, goal[:2])]
    b2 = float(wh[-1]) if winder else _level(base2 * s.riser)   # the last winder (with its error)
    regions += [_flight(1, w, heights[-1], t, x2, x2 + w, 1),
                rect(x2, x2 + w, yt, yt + TOP_LENGTH, top)]
    flights.append(dict(kind="straight", start=[x2 + w / 2, w], dir=[0.0, 1.0], n=n2, base=b2,
                        top=top, width=w, heights=[float(v) for v in heights[-1]]))
    outline = [[0, 0], [xl + depth, yt + TOP_LENGTH]]
    if s.open_side:
        regions.insert(0, rect(0, xl + depth, -OPEN_WIDTH, 0, 0.0))
        outline.append([0.0, -OPEN_WIDTH])
        flights[0]["open_dir"] = [0.0, -1.0]
    return Layout(
        regions=regions, outline=np.array(outline), spawn_rect=(0, a, 0, w), spawn_yaw=0.0,
        goal=goal, path=path, floor_height=0.0, goal_height=top, flights=flights,
        top_rect=(x2, x2 + w, yt, yt + TOP_LENGTH),
        spec=dict(landing=0.0 if winder else depth, winders=s.winders if winder else 0))


def spiral_angles(s: Staircase) -> tuple[float, float, float, float]:
    """(entry, first riser, last riser, exit) angles of a spiral, radians counter-clockwise from
    the entry corridor's wall line; ValueError if the flight does not fit the turn."""
    c, rw = s.width, s.inner_radius + s.width / 2
    th_flat = float(np.arctan2(DIVIDER / 2 + c, s.inner_radius))   # corridor's angular reach
    th_end = 2 * np.pi * s.turns
    th1 = th_flat + (s.flights[0] - 1) * s.tread / rw
    if th1 + th_flat > th_end + 1e-9:
        room = int(np.floor((th_end - 2 * th_flat) * rw / s.tread + 1e-9)) + 1
        raise ValueError(f"spiral of {s.flights[0]} risers does not fit {s.turns} turns at "
                         f"inner radius {s.inner_radius} m, width {s.width} m, tread {s.tread} m "
                         f"(at most {max(room, 0)} risers)")
    return 0.0, th_flat, th1, th_end


def spiral_max_risers(s: Staircase) -> int:
    """Most risers that fit the spiral's turn (0 if none)."""
    rw = s.inner_radius + s.width / 2
    th_flat = float(np.arctan2(DIVIDER / 2 + s.width, s.inner_radius))
    return max(int(np.floor((2 * np.pi * s.turns - 2 * th_flat) * rw / s.tread + 1e-9)) + 1, 0)


def _spiral(s: Staircase) -> Layout:
    """Core centred at the origin; entry corridor along the +x axis (y in [g/2, g/2 + w]),
    counter-clockwise flight, exit corridor along the radial line at 2 pi turns."""
    w, c, g, n = s.width, s.width, DIVIDER, s.flights[0]
    r_in, r_out = s.inner_radius, s.inner_radius + s.width
    rw = r_in + w / 2
    _, th0, th1, th_end = spiral_angles(s)
    heights = _tread_heights(s)[0]
    top = s.total_rise
    L = START_LENGTH
    u = np.array([np.cos(th_end), np.sin(th_end)])       # exit direction (radial)
    v = np.array([-u[1], u[0]])

    def past_entry(X, Y):
        return Y >= g / 2 - EPS

    def before_exit(X, Y):
        return (-X * u[1] + Y * u[0]) <= -g / 2 + EPS

    # exit corridor: radial a in [r_in, r_out + L], b in [-(g/2 + c), -g/2]; axis-aligned since
    # the turn is a multiple of a quarter
    corners = np.array([a * u + b * v for a in (r_in, r_out + L) for b in (-g / 2 - c, -g / 2)])
    ex0, ey0 = corners.min(0)
    ex1, ey1 = corners.max(0)
    regions = []
    if s.open_side:  # floor ring outside the annulus
        ring = r_out + OPEN_WIDTH

        def annulus(X, Y):
            r = np.hypot(X, Y)
            return (r >= r_out - EPS) & (r < ring), np.zeros(X.shape)
        regions.append(annulus)
    regions += [
        rect(r_in, r_out + L, g / 2, g / 2 + c, 0.0),                          # entry corridor
        _sector((0, 0), r_in, r_out, 0.0, th0, [0.0], past_entry),              # entry sector
        _sector((0, 0), r_in, r_out, th0, th1, heights),                        # the flight
        _sector((0, 0), r_in, r_out, th1, th_end, [top], before_exit),          # exit sector
        rect(round(ex0, 9), round(ex1, 9), round(ey0, 9), round(ey1, 9), top),  # exit corridor
    ]
    yc = g / 2 + c / 2
    xj = float(np.sqrt(rw ** 2 - yc ** 2))
    phi = float(np.arctan2(yc, xj))
    gxy = (r_out + L / 2) * u - yc * v
    end = xj * u - yc * v
    spawn_xy = (r_out + L / 2, yc)
    circle = np.stack([np.cos(np.linspace(0, 2 * np.pi, 73)),
                       np.sin(np.linspace(0, 2 * np.pi, 73))], -1)
    outline = np.concatenate([circle * (r_out + (OPEN_WIDTH if s.open_side else 0.0)),
                              [[r_out + L, g / 2 + c]], corners])
    flight = dict(kind="arc", centre=[0.0, 0.0], radius=rw, r_in=r_in, r_out=r_out,
                  theta0=th0, sweep=th1 - th0, n=n, base=0.0, top=top, width=w,
                  heights=[float(h) for h in heights], walk=[phi, th_end - phi])
    if s.open_side:
        flight["open"] = "outer"
    return Layout(
        regions=regions, outline=outline, spawn_rect=(r_out, r_out + L, g / 2, g / 2 + c),
        spawn_yaw=np.pi, goal=(gxy[0], gxy[1], float(np.arctan2(u[1], u[0]))),
        path=[line(spawn_xy, (xj, yc)), arc((0.0, 0.0), rw, phi, th_end - phi), line(end, gxy)],
        floor_height=0.0, goal_height=top, flights=[flight],
        top_rect=_exit_rect(u, v, r_out, L, g, c),
        spec=dict(inner_radius=r_in, walk_radius=rw, turns=s.turns,
                  flight_turns=(th1 - th0) / (2 * np.pi), landing=0.0))


def _exit_rect(u, v, r_out, L, g, c):
    """The exit corridor's part outside the annulus (axis-aligned): x0, x1, y0, y1."""
    pts = np.array([a * u + b * v for a in (r_out, r_out + L) for b in (-g / 2 - c, -g / 2)])
    lo, hi = pts.min(0), pts.max(0)
    return (float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1]))


# ------------------------------------------------------------------ difficulty and sampling
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
