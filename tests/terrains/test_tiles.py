"""Geometry of every family at every train, test and extended level, measured on the grid."""

from __future__ import annotations

import numpy as np
import pytest

import terrains
from terrains import HEIGHT_QUANTUM as Q
from terrains.tile import CENTRELINE_POINTS, GOAL_FLAT_RADIUS, SPAWN_MARGIN

from .measure import (
    WALL_MIN_RISE,
    flood,
    jumps,
    nearest,
    run_length_through,
    straight_flight_profile,
    walkable,
)

CASES = [(f, s, i, v) for f in terrains.PAPER_FAMILIES for s in ("train", "test", "extended")
         for i in range(len(terrains.levels(f, s))) for v in terrains.variants(f)]
STAIRS = [c for c in CASES if c[0] != "pyramid"]


def ids(case):
    return f"{case[0]}-{case[1]}{case[2] + 1}-{case[3]}"


_cache: dict = {}


def tile_of(case, resolution=0.025):
    key = (case, resolution)
    if key not in _cache:
        f, s, i, v = case
        _cache[key] = terrains.make_tile(f, i, v, schedule=s, resolution=resolution)
    return _cache[key]


@pytest.mark.parametrize("case", CASES, ids=ids)
def test_shapes_and_types(case):
    t = tile_of(case)
    n = int(round(10.0 / 0.025))
    assert t.heights.shape == (n, n) and t.heights.dtype == np.float32
    assert t.spawn.shape == (7,) and t.goal.shape == (4,)
    assert t.centreline.shape == (CENTRELINE_POINTS, 3) and t.centreline.dtype == np.float32
    assert t.family == case[0] and t.level == case[2] and t.variant == case[3]
    assert np.all(t.heights >= 0)
    # every height is a multiple of the quantum
    k = t.heights.astype(np.float64) / Q
    assert np.abs(k - np.round(k)).max() < 1e-3


@pytest.mark.parametrize("case", CASES, ids=ids)
def test_risers_and_treads(case):
    """Along every flight: n jumps, each the level's riser (+- one quantum), one tread apart
    (+- one grid step); the flight ends at base + n risers."""
    t = tile_of(case)
    lv = terrains.get_level(case[0], case[2], case[1])
    for fl in t.spec["flights"]:
        if fl["kind"] == "arc":
            continue  # spiral: test_spiral_walking_line
        prof, step = straight_flight_profile(t, fl)
        idx, size = jumps(prof)
        if lv.riser == 0:
            assert len(idx) == 0
            continue
        assert len(idx) == fl["n"], f"{len(idx)} risers measured, {fl['n']} expected"
        assert np.all(np.abs(size - lv.riser) <= Q + 1e-6), size
        treads = np.diff(idx) * step
        assert np.all(np.abs(treads - lv.tread) <= step + 1e-6), treads
        assert abs(prof[-1] - (fl["base"] + fl["n"] * lv.riser)) <= Q


@pytest.mark.parametrize("case", [c for c in STAIRS if c[0] != "spiral"], ids=ids)
def test_stair_width(case):
    """Across the middle tread of every flight the walkable run is the level's width."""
    t = tile_of(case)
    lv = terrains.get_level(case[0], case[2], case[1])
    walk = walkable(t)
    res = t.resolution
    for fl in t.spec["flights"]:
        s = ((fl["n"] - 1) // 2 + 0.5) * lv.tread
        x = fl["start"][0] + fl["dir"][0] * s
        y = fl["start"][1] + fl["dir"][1] * s
        ix, iy = int(round(x / res)), int(round(y / res))
        line, i = (walk[:, ix], iy) if fl["dir"][0] != 0 else (walk[iy, :], ix)
        width = run_length_through(line, i) * res
        assert abs(width - lv.width) <= res + 1e-6, (width, lv.width)


@pytest.mark.parametrize("case", [c for c in STAIRS if c[0] == "spiral"], ids=ids)
def test_spiral_walking_line(case):
    """On the walking line (radius r_in + width/2) the heights rise monotonically by one riser per
    tread; the radial width is the level's width; 0.2-0.5 turns."""
    t = tile_of(case)
    lv = terrains.get_level(case[0], case[2], case[1])
    fl = t.spec["flights"][0]
    res = t.resolution
    (cx, cy), rw, sweep = fl["centre"], fl["radius"], fl["sweep"]
    assert abs(rw - (0.75 + lv.width / 2)) < 1e-9
    assert 0.2 - 0.02 <= abs(sweep) / (2 * np.pi) <= 0.5
    ds = res / 4 / rw
    th = fl["theta0"] + np.sign(sweep) * np.arange(-0.3 / rw, abs(sweep) + 0.3 / rw, ds)
    prof = nearest(t, cx + rw * np.cos(th), cy + rw * np.sin(th))
    assert np.all(np.diff(prof) >= -1e-6), "not monotonic along the walking line"
    idx, size = jumps(prof)
    assert len(idx) == lv.steps
    assert np.all(np.abs(size - lv.riser) <= Q + 1e-6)
    treads = np.diff(idx) * ds * rw
    # a radial riser rasterised on the grid moves by up to half a diagonal on each side
    assert np.all(np.abs(treads - lv.tread) <= np.sqrt(2) * res), treads
    mid = fl["theta0"] + sweep / 2
    r = np.arange(0.0, rw + lv.width, res / 4)
    radial = walkable(t)[np.round((cy + r * np.sin(mid)) / res).astype(int),
                         np.round((cx + r * np.cos(mid)) / res).astype(int)]
    width = radial.sum() * res / 4
    assert abs(width - lv.width) <= np.sqrt(2) * res, (width, lv.width)


@pytest.mark.parametrize("case", CASES, ids=ids)
def test_goal_at_total_rise_and_flat_areas(case):
    t = tile_of(case)
    lv = terrains.get_level(case[0], case[2], case[1])
    nflights = 2 if case[0] in ("l_shaped", "u_shaped") else 1
    steps = t.spec["steps"]
    assert abs(t.goal_height - nflights * steps * lv.riser) <= Q
    assert abs(t.goal[2] - t.goal_height) <= 1e-6
    res = t.resolution
    g = np.arange(t.heights.shape[0]) * res
    X, Y = np.meshgrid(g, g)
    # goal disk flat at the goal height
    disk = np.hypot(X - t.goal[0], Y - t.goal[1]) <= GOAL_FLAT_RADIUS
    assert disk.sum() > 10
    assert np.all(np.abs(t.heights[disk] - t.goal_height) <= Q / 2)
    # spawn rectangle, grown by the margin, flat at the floor height and clear of walls
    x, y, z, hx, hy = t.spawn[:5]
    assert hx > 0 and hy > 0 and z == t.floor_height
    box = (np.abs(X - x) < hx + SPAWN_MARGIN - 1e-6) & (np.abs(Y - y) < hy + SPAWN_MARGIN - 1e-6)
    assert np.all(np.abs(t.heights[box] - t.floor_height) <= Q / 2)
    assert not t.walls[box].any()


@pytest.mark.parametrize("case", CASES, ids=ids)
def test_centreline_joins_start_to_goal_without_crossing_walls(case):
    t = tile_of(case)
    c = t.centreline.astype(np.float64)
    assert np.allclose(c[0, :2], t.spawn[:2], atol=1e-4)
    assert np.allclose(c[-1, :2], t.goal[:2], atol=1e-4)
    riser = t.spec["riser"]
    seg = np.diff(c[:, :2], axis=0)
    pts = [c[:1, :2]]
    for p, d in zip(c[:-1, :2], seg, strict=True):
        m = max(int(np.ceil(np.hypot(*d) / (t.resolution / 4))), 1)
        pts.append(p + d * (np.arange(1, m + 1) / m)[:, None])
    pts = np.concatenate(pts)
    h = t.height_at(pts[:, 0], pts[:, 1])
    assert np.abs(np.diff(h)).max() <= riser + Q + 1e-6
    assert h.max() <= t.goal_height + Q
    assert h.min() >= t.floor_height - Q
    assert not t.walls[np.round(pts[:, 1] / t.resolution).astype(int),
                       np.round(pts[:, 0] / t.resolution).astype(int)].any()
    # z of the polyline is the terrain under it
    assert np.allclose(c[:, 2], t.height_at(c[:, 0], c[:, 1]), atol=1e-5)


@pytest.mark.parametrize("case", STAIRS, ids=ids)
def test_walls_too_high_to_step_and_thick(case):
    t = tile_of(case)
    h = t.heights.astype(np.float64)
    walk = walkable(t)
    assert walk.sum() > 100 and (~walk).sum() > 100
    assert np.array_equal(~walk, t.walls)
    for axis in (0, 1):
        a = np.moveaxis(h, axis, 0)
        w = np.moveaxis(walk, axis, 0)
        edge = w[1:] != w[:-1]                            # wall next to walkable
        diff = np.abs(a[1:] - a[:-1])[edge]
        assert diff.min() >= WALL_MIN_RISE
        # every wall run between two walkable points is at least 2 points thick
        for line in w.T:
            runs = np.diff(np.flatnonzero(line))
            assert np.all((runs == 1) | (runs >= 3)), "a wall one grid point thick"


@pytest.mark.parametrize("case", [c for c in CASES if c[3] == terrains.variants(c[0])[0]],
                         ids=ids)
def test_goal_reachable_by_steps_but_not_over_walls(case):
    """Stepping at most one riser between neighbours reaches the goal from the spawn; nothing
    reaches a wall top (coarse 5 cm grid)."""
    t = tile_of(case, resolution=0.05)
    riser = t.spec["riser"]
    seen = flood(t, riser + Q)
    gx, gy = np.round(t.goal[:2] / t.resolution).astype(int)
    assert seen[gy, gx]
    assert not (seen & t.walls).any()


def test_variants_are_mirror_images():
    a = terrains.make_tile("u_shaped", 3, "left", resolution=0.05)
    b = terrains.make_tile("u_shaped", 3, "right", resolution=0.05)
    # mirrored about y = tile/2: row iy of a is row n - iy of b (grid points at k * res)
    assert np.array_equal(a.heights[1:], b.heights[::-1][:-1])
    assert abs(a.goal[1] - (10.0 - b.goal[1])) < 1e-5
    s1 = terrains.make_tile("straight", 2, "+x", resolution=0.05)
    s2 = terrains.make_tile("straight", 2, "-x", resolution=0.05)
    assert np.array_equal(s1.heights[1:, 1:], s2.heights[::-1, ::-1][:-1, :-1])


def test_pyramid_climbs_out():
    t = terrains.make_tile("pyramid", 9, "+y")
    assert t.floor_height == 0 and t.goal_height > 0.9
    assert t.spawn[1] < t.goal[1]
    assert t.spawn[6] == pytest.approx(np.pi)
    assert not t.walls.any()
    # the border is the highest ring, the platform the lowest
    assert t.heights[0, 0] == t.heights.max() and t.heights[200, 200] == 0


def test_resolution_is_configurable():
    t = terrains.make_tile("spiral", 4, resolution=0.02, tile_size=9.0)
    assert t.heights.shape == (450, 450) and t.resolution == 0.02
