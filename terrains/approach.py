"""The importer's route where it steps from a flat floor onto a flight: along the flight's axis.

Centring a route on a flat floor takes the floor's middle. Where an open side widens the floor at
a flight's foot (a strip at floor height beside the flight joins the start floor, or the floor
ring round an open spiral), that middle lies off the stairs, and the route comes to the first
riser askew. The flight itself says where its corridor runs: each riser is a straight line across
the flight's width, its middle on the flight's axis. ``approach`` takes the flight's second and
third risers (the first, from the floor, also runs along an open side) and the axis through their
middles: a line, or the circle a curved flight turns on. At the flight's foot it prolongs that
axis onto the floor, straight on or on round its circle, whichever keeps the flight's
cross-section, swept back along it, against the floor's edges the longer (a spiral's floor sector
still curves round its core; a rectangular floor in front of a curved flight runs straight), and
as far as the cross-section still fits on the floor. The route reaches the flight along that
prolonged axis. From the start it joins it with one straight stretch, to the point farthest back
along the axis that the stretch reaches without heading against the axis and keeping 0.9 of the
flight's half-width from walls (beyond the start's own distance from them): a start in the
flight's corridor joins it at once; from a corridor meeting the prolonged axis from the side the
stretch runs near that corridor's middle.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

TURN_MIN = np.radians(3.0)  # a smaller turn from one riser to the next is a straight flight
STRAIGHT = 0.5              # rms bulge (grid steps) above which a riser is not a straight line
FOOT_REACH = 1.0            # m, the foot lies at most this far behind the second riser
JOIN_CLEAR = 0.9            # the join keeps this fraction of the flight's half-width from walls


def grow(seed: tuple[int, int], ok: np.ndarray) -> np.ndarray:
    """[ny, nx] bool: the 4-connected region of ``ok`` holding ``seed``."""
    m = np.zeros(ok.shape, bool)
    m[seed] = True
    while True:
        g = m.copy()
        g[1:] |= m[:-1]
        g[:-1] |= m[1:]
        g[:, 1:] |= m[:, :-1]
        g[:, :-1] |= m[:, 1:]
        g &= ok
        if np.array_equal(g, m):
            return m
        m = g


def min_on(piece: np.ndarray, field: np.ndarray, resolution: float) -> float:
    """Smallest value of ``field`` at the grid points nearest the polyline [k, 2] (xy)."""
    pts = []
    for a, b in zip(piece[:-1], piece[1:], strict=True):
        n = max(int(np.ceil(np.hypot(*(b - a)) / (resolution / 2))), 1)
        pts.append(a + (b - a) * (np.arange(n + 1) / n)[:, None])
    ij = np.round(np.concatenate(pts)[:, ::-1] / resolution).astype(int)
    return float(field[ij[:, 0], ij[:, 1]].min())


def _shift(m: np.ndarray, d: tuple[int, int]) -> np.ndarray:
    """out[i, j] = m[i + d0, j + d1], False beyond the grid."""
    out = np.zeros_like(m)
    ny, nx = m.shape
    di, dj = d
    out[max(-di, 0):ny - max(di, 0), max(-dj, 0):nx - max(dj, 0)] = \
        m[max(di, 0):ny + min(di, 0), max(dj, 0):nx + min(dj, 0)]
    return out


@dataclass(frozen=True)
class Riser:
    mid: np.ndarray      # [2] xy of its middle
    along: np.ndarray    # [2] unit vector along it
    normal: np.ndarray   # [2] unit vector across it, toward the second region
    half: float          # half its length


def riser(h: np.ndarray, a: tuple[int, int], b: tuple[int, int], resolution: float):
    """The edge between the equal-height region holding grid point ``a`` and the one holding
    ``b`` (xy metres, grid frame) as a Riser, or None where it is not a straight line."""
    ra, rb = grow(a, h == h[a]), grow(b, h == h[b])
    pts, steps = [], []
    for d in ((0, 1), (1, 0), (0, -1), (-1, 0)):
        ij = np.argwhere(ra & _shift(rb, d))
        pts.append(ij + 0.5 * np.array(d))
        steps.append(np.tile(np.array(d, float), (len(ij), 1)))
    p = np.concatenate(pts)[:, ::-1] * resolution
    if len(p) < 3:
        return None
    mid = p.mean(0)
    along = np.linalg.svd(p - mid, full_matrices=False)[2][0]
    normal = np.array([-along[1], along[0]])
    if normal @ np.concatenate(steps)[:, ::-1].mean(0) < 0:
        normal = -normal
    if np.sqrt(np.mean(((p - mid) @ normal) ** 2)) > STRAIGHT * resolution:
        return None
    return Riser(mid, along, normal, float(np.ptp((p - mid) @ along) / 2 + resolution / 2))


def _rot(v: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """[m, 2]: the vector v [2] turned by the angles phi [m] (counter-clockwise)."""
    c, s = np.cos(phi)[:, None], np.sin(phi)[:, None]
    return np.concatenate([c * v[0] - s * v[1], s * v[0] + c * v[1]], 1)


@dataclass(frozen=True)
class Axis:
    """The line or circle through ``origin`` heading ``tangent`` that turns ``kappa`` rad/m
    (counter-clockwise positive); arc length u from origin, negative behind it."""

    origin: np.ndarray
    tangent: np.ndarray
    kappa: float

    @classmethod
    def through(cls, r0: Riser, r1: Riser) -> Axis:
        """The axis through r0's middle across r0, turning as the flight does from r0 to r1."""
        turn = float(np.arctan2(r0.normal[0] * r1.normal[1] - r0.normal[1] * r1.normal[0],
                                r0.normal @ r1.normal))
        chord = float(np.hypot(*(r1.mid - r0.mid)))
        if abs(turn) < TURN_MIN or chord <= 0:
            return cls(r0.mid, r0.normal, 0.0)
        return cls(r0.mid, r0.normal, turn / (chord * (turn / 2) / np.sin(turn / 2)))

    def _centre(self) -> np.ndarray:
        return self.origin + np.array([-self.tangent[1], self.tangent[0]]) / self.kappa

    def at(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(points [m, 2], headings [m, 2]) at arc lengths u [m]."""
        u = np.asarray(u, float)
        if self.kappa == 0:
            return self.origin + u[:, None] * self.tangent, np.tile(self.tangent, (len(u), 1))
        c = self._centre()
        return c + _rot(self.origin - c, self.kappa * u), _rot(self.tangent, self.kappa * u)

    def project(self, p: np.ndarray) -> tuple[float, float]:
        """(arc length of the axis point nearest p, distance from p to the axis)."""
        if self.kappa == 0:
            d = p - self.origin
            return float(d @ self.tangent), float(abs(d[0] * self.tangent[1]
                                                      - d[1] * self.tangent[0]))
        c = self._centre()
        a, b = self.origin - c, p - c
        phi = np.arctan2(a[0] * b[1] - a[1] * b[0], a @ b)
        return float(phi / self.kappa), float(abs(np.hypot(*b) - 1 / abs(self.kappa)))


def approach(cells: np.ndarray, h: np.ndarray, large: np.ndarray, clear: np.ndarray,
             resolution: float, start: np.ndarray) -> tuple[np.ndarray, int] | None:
    """The route's start along the first flight's axis (see the module docstring).

    cells [m, 2] (iy, ix): the searched route from the start; h, large, clear: the heights, the
    large flat patches and the clearance field (mesh_import); start [2] xy (grid frame). Returns
    (points [k, 2] xy from the start, j): the route is the points, then cells[j:]. None where the
    start is not on a large flat patch, the route does not climb two risers off it without
    landing, or those risers are not straight lines, or no join keeps clear."""
    first = tuple(cells[0])
    if not large[first]:
        return None
    floor = grow(first, large & (h == h[first]))
    off = ~floor[cells[:, 0], cells[:, 1]]
    i = int(np.argmax(off))
    z = h[cells[:, 0], cells[:, 1]]
    ks = np.nonzero(z[i + 1:] != z[i:-1])[0][:2] + i
    if not off[i] or len(ks) < 2 or large[cells[i:ks[1] + 1, 0], cells[i:ks[1] + 1, 1]].any():
        return None
    r2, r3 = (riser(h, tuple(cells[k]), tuple(cells[k + 1]), resolution) for k in ks)
    if r2 is None or r3 is None:
        return None
    axis = Axis.through(r2, r3)
    foot = _foot(axis, floor, resolution)
    if foot is None:
        return None
    p, head = (a[0] for a in axis.at(np.array([foot])))
    across = _rot(r2.along, np.array([axis.kappa * foot]))[0]
    ways = [Axis(p, head, k) for k in ([0.0, axis.kappa] if axis.kappa else [0.0])]
    sweeps = [_sweep(w, across, r2.half, floor, resolution) for w in ways]
    k = max(range(len(ways)), key=lambda k: (sweeps[k][1], -abs(ways[k].kappa)))
    back, way = sweeps[k][0], ways[k]
    u0 = None if back is None else _join(way, back, clear, start, resolution,
                                         JOIN_CLEAR * r2.half)
    if u0 is None:
        return None
    j, u1 = _rejoin(axis, cells, large, int(ks[0]), resolution)
    return np.concatenate([[start], way.at(np.arange(u0, 0.0, resolution / 2))[0],
                           axis.at(np.arange(foot, u1, resolution / 2))[0]]), j


def _foot(axis: Axis, floor: np.ndarray, resolution: float) -> float | None:
    """The arc length (<= 0) where the axis, followed back from its origin, first reaches
    ``floor``; None if not within FOOT_REACH."""
    u = -np.arange(0.0, FOOT_REACH, resolution / 2)
    ij = np.round(axis.at(u)[0][:, ::-1] / resolution).astype(int)
    ok = (ij >= 0).all(1) & (ij[:, 0] < floor.shape[0]) & (ij[:, 1] < floor.shape[1])
    ij = np.where(ok[:, None], ij, 0)
    on = ok & floor[ij[:, 0], ij[:, 1]]
    return float(u[np.argmax(on)]) if on.any() else None


def _sweep(way: Axis, across: np.ndarray, half: float, floor: np.ndarray,
           resolution: float) -> tuple[np.ndarray | None, float]:
    """The flight's cross-section (``across`` [2] at the origin, ``half`` its half-width) swept
    back along ``way``: (arc lengths u <= 0 over which it lies on ``floor``, its ends a grid
    step in, or None; the length (m, both ends summed) over which its ends keep against the
    floor's edge from the foot back)."""
    reach = np.hypot(*floor.shape) * resolution
    if way.kappa:
        reach = min(reach, np.pi / abs(way.kappa))
    u = -np.arange(0.0, reach, resolution / 2)
    c, _ = way.at(u)
    a = _rot(across, way.kappa * u)

    def on(v: np.ndarray) -> np.ndarray:               # [len(u), len(v)]: floor at c + v a
        ij = np.round((c[:, None, :] + v[None, :, None] * a[:, None, :])[..., ::-1]
                      / resolution).astype(int)
        inside = (ij >= 0).all(-1) & (ij[..., 0] < floor.shape[0]) & \
            (ij[..., 1] < floor.shape[1])
        ij = np.where(inside[..., None], ij, 0)
        return inside & floor[ij[..., 0], ij[..., 1]]

    full = on(np.linspace(-(half - resolution), half - resolution,
                          max(int(np.ceil(4 * half / resolution)), 2))).all(1)
    if not full.any():
        return None, 0.0
    k0 = int(np.argmax(full))
    k1 = k0 + (int(np.argmin(full[k0:])) if not full[k0:].all() else len(u) - k0)
    edge = ~on(np.array([-half - resolution, half + resolution]))[k0:k1]
    run = np.where(edge.all(0), k1 - k0, np.argmin(edge, axis=0))
    return u[k0:k1], float(run.sum() * resolution / 2)


def _join(axis: Axis, u: np.ndarray, clear: np.ndarray, start: np.ndarray, resolution: float,
          need: float) -> float | None:
    """The arc length, farthest back among u, of the axis point reached from ``start`` by a
    straight that does not head against the axis there and keeps ``need`` from walls once
    farther from the start than the start is from them."""
    ij = np.round(np.asarray(start)[::-1] / resolution).astype(int)
    near = clear[ij[0], ij[1]]
    pts, heads = axis.at(u)
    for k in range(len(u) - 1, -1, -1):
        d = pts[k] - start
        if d @ heads[k] < 0:
            continue
        n = int(np.ceil(np.hypot(*d) / (resolution / 2)))
        q = start + d * (np.arange(n + 1) / max(n, 1))[:, None]
        q = q[np.hypot(*(q - start).T) >= near]
        if not len(q):
            return float(u[k])
        qi = np.round(q[:, ::-1] / resolution).astype(int)
        if clear[qi[:, 0], qi[:, 1]].min() >= need:
            return float(u[k])
    return None


def _rejoin(axis: Axis, cells: np.ndarray, large: np.ndarray, k: int,
            resolution: float) -> tuple[int, float]:
    """(j, u): the first route point cells[j] past index k within a grid step of the axis (or
    the first on a large flat patch, or the last), and the arc length nearest it."""
    xy = cells[:, ::-1] * resolution
    j = k + 1
    while j < len(cells) - 1 and not large[tuple(cells[j])] and \
            axis.project(xy[j])[1] > resolution:
        j += 1
    return j, axis.project(xy[j])[0]
