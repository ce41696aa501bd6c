"""A staircase as a ``families.common.Layout`` in its canonical frame (left turn, first flight
climbing +x), which ``families.common.build_tile`` centres in a tile, mirrors for right turns and
paints; everything that is not start floor, flight, landing, top landing or the floor beside an
open side is wall.

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

from dataclasses import asdict

import numpy as np

from ..families.common import (
    EPS,
    MIN_WALL,
    START_LENGTH,
    TOP_LENGTH,
    Layout,
    arc,
    line,
    rect,
)
from .regions import flight, sector, snap, tread_heights, winders
from .staircase import Staircase, difficulty

DIVIDER = MIN_WALL   # m, wall between side-by-side flights and between a spiral's exit and entry
OPEN_WIDTH = 0.8     # m, floor strip beside an open side before the wall


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
    heights = tread_heights(s)
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
        regions.append(flight(0, u0, heights[k], t, col[k], col[k] + w, climb))
        base += n
        z = snap(base * s.riser)
        flights.append(dict(kind="straight", start=[x, yc], dir=[float(climb), 0.0], n=n,
                            base=snap((base - n) * s.riser), top=z, width=w,
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
    heights = tread_heights(s)
    n1, n2 = s.flights
    a = START_LENGTH
    xl = a + (n1 - 1) * t                  # last riser of flight 1
    winder = s.shape == "winder"
    depth = w if winder else max(s.landing, w)
    x2 = xl + depth - w                    # flight 2: x in [x2, x2 + w)
    yt = w + (n2 - 1) * t                  # last riser of flight 2
    mid = snap(n1 * s.riser)
    base2 = n1 + (s.winders - 1 if winder else 0)
    top = s.total_rise
    regions = [rect(0, a, 0, w, 0.0), flight(0, a, heights[0], t, 0, w, 1)]
    flights = [dict(kind="straight", start=[a, w / 2], dir=[1.0, 0.0], n=n1, base=0.0, top=mid,
                    width=w, heights=[float(v) for v in heights[0]])]
    goal = (x2 + w / 2, yt + TOP_LENGTH / 2, np.pi / 2)
    if winder:
        wh = np.concatenate([[mid], heights[1]])      # winder 1 at the top of flight 1
        regions.append(winders((xl, w), w, wh))
        flights.append(dict(kind="winder", centre=[xl, w], radius=w / 2, theta0=-np.pi / 2,
                            sweep=np.pi / 2, n=s.winders, base=mid, top=float(wh[-1]), width=w,
                            heights=[float(v) for v in wh]))
        path = [line((a / 2, w / 2), (xl, w / 2)), arc((xl, w), w / 2, -np.pi / 2, 0.0),
                line((xl + w / 2, w), goal[:2])]
    else:
        regions.append(rect(xl, xl + depth, 0, w, mid))
        corner = (x2 + w / 2, w / 2)
        path = [line((a / 2, w / 2), corner), line(corner, goal[:2])]
    b2 = float(wh[-1]) if winder else snap(base2 * s.riser)   # the last winder (with its error)
    regions += [flight(1, w, heights[-1], t, x2, x2 + w, 1),
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
    heights = tread_heights(s)[0]
    top = s.total_rise
    L = START_LENGTH
    u = np.array([np.cos(th_end), np.sin(th_end)])       # exit direction (radial)
    v = np.array([-u[1], u[0]])
    # exit corridor: radial a in [r_in, r_out + L], b in [-(g/2 + c), -g/2]; axis-aligned since
    # the turn is a multiple of a quarter
    corners = np.array([a * u + b * v for a in (r_in, r_out + L) for b in (-g / 2 - c, -g / 2)])
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
    arc_flight = dict(kind="arc", centre=[0.0, 0.0], radius=rw, r_in=r_in, r_out=r_out,
                      theta0=th0, sweep=th1 - th0, n=n, base=0.0, top=top, width=w,
                      heights=[float(h) for h in heights], walk=[phi, th_end - phi])
    if s.open_side:
        arc_flight["open"] = "outer"
    return Layout(
        regions=_spiral_regions(s, heights, u, corners),
        outline=outline, spawn_rect=(r_out, r_out + L, g / 2, g / 2 + c),
        spawn_yaw=np.pi, goal=(gxy[0], gxy[1], float(np.arctan2(u[1], u[0]))),
        path=[line(spawn_xy, (xj, yc)), arc((0.0, 0.0), rw, phi, th_end - phi), line(end, gxy)],
        floor_height=0.0, goal_height=top, flights=[arc_flight],
        top_rect=_exit_rect(u, v, r_out, L, g, c),
        spec=dict(inner_radius=r_in, walk_radius=rw, turns=s.turns,
                  flight_turns=(th1 - th0) / (2 * np.pi), landing=0.0))


def _spiral_regions(s: Staircase, heights: np.ndarray, u: np.ndarray,
                    corners: np.ndarray) -> list:
    """The spiral's regions: the floor ring of an open side, entry corridor, entry sector, the
    flight, exit sector, exit corridor. ``u``: exit direction [2]; ``corners`` [4, 2]: the exit
    corridor's."""
    c, g = s.width, DIVIDER
    r_in, r_out = s.inner_radius, s.inner_radius + s.width
    _, th0, th1, th_end = spiral_angles(s)
    top = s.total_rise

    def past_entry(X, Y):
        return Y >= g / 2 - EPS

    def before_exit(X, Y):
        return (-X * u[1] + Y * u[0]) <= -g / 2 + EPS

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
        rect(r_in, r_out + START_LENGTH, g / 2, g / 2 + c, 0.0),               # entry corridor
        sector((0, 0), r_in, r_out, 0.0, th0, [0.0], past_entry),              # entry sector
        sector((0, 0), r_in, r_out, th0, th1, heights),                        # the flight
        sector((0, 0), r_in, r_out, th1, th_end, [top], before_exit),          # exit sector
        rect(round(ex0, 9), round(ex1, 9), round(ey0, 9), round(ey1, 9), top),  # exit corridor
    ]
    return regions


def _exit_rect(u, v, r_out, L, g, c):
    """The exit corridor's part outside the annulus (axis-aligned): x0, x1, y0, y1."""
    pts = np.array([a * u + b * v for a in (r_out, r_out + L) for b in (-g / 2 - c, -g / 2)])
    lo, hi = pts.min(0), pts.max(0)
    return (float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1]))
