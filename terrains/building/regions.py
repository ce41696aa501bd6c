"""The pieces a staircase is painted from: tread heights with their errors, and the regions of a
straight flight, a spiral sector and a winder square.

A region is a function (X, Y) -> (mask, heights) over grid coordinates (metres, the layout's
canonical frame), as ``families.common.build_tile`` paints them. Heights are multiples of
HEIGHT_QUANTUM: landings exact multiples of the riser, the treads between them carrying whole-mm
errors (|e| <= height_error), so every flight starts and ends level.
"""

from __future__ import annotations

import numpy as np

from ..families.common import EPS
from ..tile import HEIGHT_QUANTUM
from .staircase import Staircase


def tread_heights(s: Staircase) -> list[np.ndarray]:
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


def snap(z: float) -> float:
    """``z`` rounded to a whole HEIGHT_QUANTUM."""
    return float(np.round(z / HEIGHT_QUANTUM) * HEIGHT_QUANTUM)


def flight(axis: int, u0: float, heights: np.ndarray, tread: float, c0: float, c1: float,
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


def sector(centre, r0: float, r1: float, th0: float, th1: float, heights, extra=None):
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


def winders(corner, w: float, heights):
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
