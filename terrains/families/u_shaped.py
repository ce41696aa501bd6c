"""U-shaped stairs: two flights side by side with a dividing wall, a landing spanning both flights
at the 180 degree turn, the top landing beside the start floor; walls all round.

Variants: "left" (flight 2 lies to the left of flight 1), "right" (mirror image).
"""

from __future__ import annotations

import numpy as np

from ..levels import Level
from .common import MIN_WALL, START_LENGTH, Layout, flight, line, rect

VARIANTS = ("left", "right")
DIVIDER = MIN_WALL  # m, thickness of the wall between the two flights


def layout(lv: Level, variant: str) -> tuple[Layout, str]:
    """Canonical frame (left): flight 1 climbs +x in y [0, w), flight 2 climbs -x in
    y [w + DIVIDER, 2 w + DIVIDER); the top landing is x in [0, START_LENGTH)."""
    w, n, r, t, depth = lv.width, lv.steps, lv.riser, lv.tread, lv.landing
    xs = START_LENGTH
    xl = xs + (n - 1) * t                  # landing: x in [xl, xl + depth)
    y2 = w + DIVIDER                       # flight 2: y in [y2, y2 + w)
    mid, top = n * r, 2 * n * r
    regions = [
        rect(0, xs, 0, w, 0.0),
        flight(0, xs, n, r, t, 0, w, 0.0),
        rect(xl, xl + depth, 0, y2 + w, mid),
        flight(0, xs, n, r, t, y2, y2 + w, mid, ascending=-1),
        rect(0, xs, y2, y2 + w, top),
    ]
    xm = xl + depth / 2
    goal = (xs / 2, y2 + w / 2, np.pi)
    pts = [(xs / 2, w / 2), (xm, w / 2), (xm, y2 + w / 2), goal[:2]]
    lay = Layout(
        regions=regions, outline=np.array([[0, 0], [xl + depth, y2 + w]]),
        spawn_rect=(0, xs, 0, w), spawn_yaw=0.0, goal=goal,
        path=[line(a, b) for a, b in zip(pts[:-1], pts[1:], strict=True)],
        floor_height=0.0, goal_height=top, top_rect=(0, xs, y2, y2 + w),
        flights=[dict(kind="straight", start=[xs, w / 2], dir=[1.0, 0.0], n=n, base=0.0, width=w),
                 dict(kind="straight", start=[xl, y2 + w / 2], dir=[-1.0, 0.0], n=n, base=mid,
                      width=w)],
        spec=dict(riser=r, tread=t, width=w, steps=n, flights=2, landing=depth,
                  divider=DIVIDER, total_rise=top))
    return lay, "" if variant == "left" else "mirror"
