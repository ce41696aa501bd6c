"""L-shaped stairs: flight 1 along +x, a landing at the 90 degree turn, flight 2 along +y (turning
left) or -y (turning right), top landing; walls all round.

The landing is max(level.landing, width) deep along x and one flight width wide.
Variants: "left", "right" (mirror image).
"""

from __future__ import annotations

import numpy as np

from ..levels import Level
from .common import START_LENGTH, TOP_LENGTH, Layout, flight, line, rect

VARIANTS = ("left", "right")


def layout(lv: Level, variant: str) -> tuple[Layout, str]:
    """Canonical frame (left turn): flight 1 in y [0, w), flight 2 climbs +y."""
    w, n, r, t = lv.width, lv.steps, lv.riser, lv.tread
    depth = max(lv.landing, w)
    xs = START_LENGTH
    xl = xs + (n - 1) * t                    # landing starts at flight 1's last riser
    x2 = xl + depth - w                      # flight 2 occupies x in [x2, x2 + w)
    yt = w + (n - 1) * t                     # flight 2's last riser = start of the top landing
    mid, top = n * r, 2 * n * r
    regions = [
        rect(0, xs, 0, w, 0.0),
        flight(0, xs, n, r, t, 0, w, 0.0),
        rect(xl, xl + depth, 0, w, mid),
        flight(1, w, n, r, t, x2, x2 + w, mid),
        rect(x2, x2 + w, yt, yt + TOP_LENGTH, top),
    ]
    corner = (x2 + w / 2, w / 2)
    goal = (x2 + w / 2, yt + TOP_LENGTH / 2, np.pi / 2)
    lay = Layout(
        regions=regions, outline=np.array([[0, 0], [xl + depth, yt + TOP_LENGTH]]),
        spawn_rect=(0, xs, 0, w), spawn_yaw=0.0, goal=goal,
        path=[line((xs / 2, w / 2), corner), line(corner, goal[:2])],
        floor_height=0.0, goal_height=top, top_rect=(x2, x2 + w, yt, yt + TOP_LENGTH),
        flights=[dict(kind="straight", start=[xs, w / 2], dir=[1.0, 0.0], n=n, base=0.0, width=w),
                 dict(kind="straight", start=[x2 + w / 2, w], dir=[0.0, 1.0], n=n, base=mid,
                      width=w)],
        spec=dict(riser=r, tread=t, width=w, steps=n, flights=2, landing=depth, total_rise=top))
    return lay, "" if variant == "left" else "mirror"
