"""Straight stairs: start floor, one flight along +x, top landing; side walls.

Variants: "+x" (climbs toward +x) and "-x" (the same turned half a turn).
"""

from __future__ import annotations

import numpy as np

from ..levels import Level
from .common import START_LENGTH, TOP_LENGTH, Layout, flight, line, rect

VARIANTS = ("+x", "-x")


def layout(lv: Level, variant: str) -> tuple[Layout, str]:
    """Canonical frame: flight along +x, y in [0, width)."""
    w, n, r, t = lv.width, lv.steps, lv.riser, lv.tread
    xs = START_LENGTH                  # first riser
    xt = xs + (n - 1) * t              # last riser = start of the top landing
    top = n * r
    regions = [rect(0, xs, 0, w, 0.0), flight(0, xs, n, r, t, 0, w, 0.0),
               rect(xt, xt + TOP_LENGTH, 0, w, top)]
    goal = (xt + TOP_LENGTH / 2, w / 2, 0.0)
    lay = Layout(
        regions=regions, outline=np.array([[0, 0], [xt + TOP_LENGTH, w]]),
        spawn_rect=(0, xs, 0, w), spawn_yaw=0.0, goal=goal,
        path=[line((xs / 2, w / 2), goal[:2])], floor_height=0.0, goal_height=top,
        top_rect=(xt, xt + TOP_LENGTH, 0, w),
        flights=[dict(kind="straight", start=[xs, w / 2], dir=[1.0, 0.0], n=n, base=0.0,
                      width=w)],
        spec=dict(riser=r, tread=t, width=w, steps=n, total_rise=top))
    return lay, "" if variant == "+x" else "turn"
