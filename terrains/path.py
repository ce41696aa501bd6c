"""Centre-line paths: chains of straight and circular segments, resampled to K points.

A path is a list of segments in the plane:
    Line(p0, p1)                         straight from p0 to p1 ([2] each)
    Arc(centre, radius, theta0, theta1)  circle arc, angle from +x, counter-clockwise if
                                         theta1 > theta0, clockwise otherwise
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Line:
    p0: tuple[float, float]
    p1: tuple[float, float]

    @property
    def length(self) -> float:
        return float(np.hypot(self.p1[0] - self.p0[0], self.p1[1] - self.p0[1]))

    def at(self, s: np.ndarray) -> np.ndarray:
        """[m] arc lengths from p0 -> [m, 2] points."""
        p0, p1 = np.asarray(self.p0, float), np.asarray(self.p1, float)
        f = np.asarray(s, float)[:, None] / max(self.length, 1e-12)
        return p0 + f * (p1 - p0)


@dataclass(frozen=True)
class Arc:
    centre: tuple[float, float]
    radius: float
    theta0: float
    theta1: float

    @property
    def length(self) -> float:
        return abs(self.theta1 - self.theta0) * self.radius

    def at(self, s: np.ndarray) -> np.ndarray:
        """[m] arc lengths from theta0 -> [m, 2] points."""
        sign = 1.0 if self.theta1 >= self.theta0 else -1.0
        th = self.theta0 + sign * np.asarray(s, float) / self.radius
        c = np.asarray(self.centre, float)
        return c + self.radius * np.stack([np.cos(th), np.sin(th)], -1)


Segment = Line | Arc


def resample(path: list[Segment], k: int) -> np.ndarray:
    """Exactly ``k`` points [k, 2] along ``path``: every segment end is kept, the remaining
    points are spread over the segments in proportion to their length, evenly within each.
    Zero-length segments are dropped; a path shorter than k points is padded with its end."""
    segs = [s for s in path if s.length > 1e-9]
    if not segs:
        raise ValueError("centre-line path has zero length")
    lengths = np.array([s.length for s in segs])
    spare = k - (len(segs) + 1)
    if spare < 0:
        raise ValueError(f"path has {len(segs)} segments, more than {k - 1}")
    share = lengths / lengths.sum() * spare
    extra = np.floor(share).astype(int)
    for i in np.argsort(-(share - extra))[: spare - extra.sum()]:
        extra[i] += 1
    pts = [np.asarray(segs[0].at(np.array([0.0])))]
    for seg, m in zip(segs, extra, strict=True):
        s = np.linspace(0.0, seg.length, m + 2)[1:]
        pts.append(seg.at(s))
    out = np.concatenate(pts, 0)
    assert out.shape == (k, 2), out.shape
    return out
