"""Spiral stairs around a solid core of radius 0.75 m: a start floor tangent to the first riser,
one flight of n risers sweeping (n-1) tread / R_walk radians (0.2-0.5 turns), a tangent top
landing; walls all round. The walking line is the middle of the width, R_walk = 0.75 + width/2;
the tread is measured on it.

Variants: "ccw" (climbs counter-clockwise seen from above), "cw" (mirror image).
"""

from __future__ import annotations

import numpy as np

from ..levels import Level
from .common import (
    START_LENGTH,
    TOP_LENGTH,
    Layout,
    arc,
    line,
    rect,
    rotated_rect,
    sector_flight,
)

VARIANTS = ("ccw", "cw")
INNER_RADIUS = 0.75
MAX_TURNS = 0.5


def layout(lv: Level, variant: str) -> tuple[Layout, str]:
    """Canonical frame (ccw): core centred at the origin, first riser on the +x axis, start floor
    at y in [-START_LENGTH, 0)."""
    w, n, r, t = lv.width, lv.steps, lv.riser, lv.tread
    r_in, r_out = INNER_RADIUS, INNER_RADIUS + w
    rw = INNER_RADIUS + w / 2
    dth = t / rw
    sweep = (n - 1) * dth
    turns = sweep / (2 * np.pi)
    if turns > MAX_TURNS + 1e-9:
        raise ValueError(f"spiral with {n} steps of {t} m at radius {rw:.2f} m sweeps "
                         f"{turns:.2f} turns, more than {MAX_TURNS}")
    top = n * r
    radial = (np.cos(sweep), np.sin(sweep))
    tangent = (-radial[1], radial[0])
    regions = [
        rect(r_in, r_out, -START_LENGTH, 0, 0.0),
        sector_flight((0.0, 0.0), r_in, r_out, n, r, dth, 0.0),
        rotated_rect((0.0, 0.0), radial, r_in, r_out, -1e-6, TOP_LENGTH, top),
    ]
    end = np.array(radial) * rw
    gxy = end + np.array(tangent) * TOP_LENGTH / 2
    goal = (gxy[0], gxy[1], float(np.arctan2(tangent[1], tangent[0])))
    th = np.linspace(0, sweep, 181)
    ring = np.concatenate([np.stack([np.cos(th), np.sin(th)], -1) * rr for rr in (r_in, r_out)])
    land = [np.array(radial) * rr + np.array(tangent) * TOP_LENGTH for rr in (r_in, r_out)]
    outline = np.concatenate([ring, [[r_in, -START_LENGTH], [r_out, -START_LENGTH]], land])
    lay = Layout(
        regions=regions, outline=outline,
        spawn_rect=(r_in, r_out, -START_LENGTH, 0), spawn_yaw=np.pi / 2, goal=goal,
        path=[line((rw, -START_LENGTH / 2), (rw, 0.0)), arc((0.0, 0.0), rw, 0.0, sweep),
              line(end, gxy)],
        floor_height=0.0, goal_height=top,
        flights=[dict(kind="arc", centre=[0.0, 0.0], radius=rw, r_in=r_in, r_out=r_out,
                      theta0=0.0, sweep=float(sweep), n=n, base=0.0, width=w)],
        spec=dict(riser=r, tread=t, width=w, steps=n, inner_radius=r_in, walk_radius=rw,
                  turns=float(turns), total_rise=top))
    return lay, "" if variant == "ccw" else "mirror"
