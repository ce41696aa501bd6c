"""Building staircases: every shape and option measured on the grid, both directions; sampling,
difficulty order, tile sizes, the atlas with directions."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import terrains
from terrains import HEIGHT_QUANTUM as Q
from terrains.building import (
    OPEN_WIDTH,
    SHAPES,
    VARIANTS,
    Staircase,
    difficulty,
    fit,
    sample_staircase,
    staircase_tile,
    tile_size_for,
)
from terrains.mesh_import import chamfer_distance
from terrains.suites import load_suite
from terrains.tile import GOAL_FLAT_RADIUS, SPAWN_MARGIN

from .measure import jumps, nearest, straight_flight_profile

RES = 0.025
ERR = 0.005

# every shape, both turns, walled and open, with tread height errors; unequal flights
_BASE = dict(riser=0.17, tread=0.28, width=1.1, landing=1.2, height_error=ERR, seed=3)
_FLIGHTS = {"straight": (9,), "l": (6, 8), "winder": (5, 6), "u": (7, 5), "switchback": (4, 6, 5),
            "spiral": (12,)}
_EXTRA = {"spiral": dict(inner_radius=0.4, turns=1.0), "winder": dict(winders=3)}
STAIRS = [Staircase(shape, flights=_FLIGHTS[shape], turn=turn, open_side=op,
                    name=f"{shape}_{turn}_{'open' if op else 'walled'}",
                    **_BASE, **_EXTRA.get(shape, {}))
          for shape in SHAPES for turn in ("left", "right") for op in (False, True)
          if not (shape == "straight" and turn == "right")]
# extremes of the ranges: 2 cm and 21 cm risers, narrowest and widest, small and large cores
STAIRS += [
    Staircase("u", 0.02, 0.35, 2.0, (3, 3), landing=1.8, name="u_low_wide"),
    Staircase("switchback", 0.21, 0.24, 0.8, (5, 5, 5), landing=0.9, open_side=True,
              height_error=ERR, name="switchback_steep_narrow"),
    Staircase("spiral", 0.21, 0.24, 0.8, (12,), turns=1.0, inner_radius=0.3, height_error=ERR,
              name="spiral_tight"),
    Staircase("spiral", 0.05, 0.3, 2.0, (8,), "right", turns=0.75, inner_radius=1.0,
              name="spiral_wide"),
    Staircase("winder", 0.19, 0.25, 0.9, (8, 8), "right", winders=2, name="winder_2"),
    Staircase("l", 0.12, 0.3, 0.8, (18, 18), landing=0.9, name="l_long"),
]
STAIRS += [c.staircase for c in load_suite("code") if c.direction == "up"]


def _ids(s):
    return s.name


@pytest.fixture(scope="module")
def tiles():
    """name -> (up tile, down tile) at 2.5 cm."""
    out = {}
    for s in STAIRS:
        up = staircase_tile(s, RES)
        out[s.name] = (up, staircase_tile(s, RES, direction="down"))
    return out


def _dense(c: np.ndarray, step: float) -> np.ndarray:
    out = [c[:1]]
    for a, b in zip(c[:-1], c[1:], strict=True):
        m = max(int(np.ceil(np.hypot(*(b - a)) / step)), 1)
        out.append(a + (b - a) * (np.arange(1, m + 1) / m)[:, None])
    return np.concatenate(out)


@pytest.mark.parametrize("s", STAIRS, ids=_ids)
def test_risers_and_treads_of_straight_flights(s, tiles):
    """Along every straight flight: n risers, each its recorded height step (riser + errors, to
    a quantum), one tread apart (to a cell); the flight starts and ends level."""
    t, _ = tiles[s.name]
    for fl in t.spec["flights"]:
        if fl["kind"] != "straight":
            continue
        prof, step = straight_flight_profile(t, fl, pad=0.1)   # winders begin beside a flight
        idx, size = jumps(prof)
        expect = np.diff([fl["base"], *fl["heights"], fl["top"]])
        assert len(idx) == fl["n"], (len(idx), fl["n"])
        assert np.all(np.abs(size - expect) <= Q + 1e-6), (size, expect)
        assert np.all(np.abs(np.diff(idx) * step - s.tread) <= step + 1e-6)
        assert np.all(np.abs(expect - s.riser) <= 2 * s.height_error + Q + 1e-6)
        # the tread height errors are whole quanta, at most height_error (+ the winder's)
        err = np.asarray(fl["heights"]) - (fl["top"] - s.riser * np.arange(fl["n"] - 1, 0, -1))
        assert np.all(np.abs(err) <= 2 * s.height_error + Q / 2 + 1e-6)
        assert np.allclose(np.asarray(fl["heights"]) / Q, np.round(np.asarray(fl["heights"]) / Q),
                           atol=1e-3)


@pytest.mark.parametrize("s", STAIRS, ids=_ids)
def test_width_across_every_flight(s, tiles):
    """Across the middle tread of each straight flight, the run of points at that tread's height
    is the clear width (to a cell)."""
    t, _ = tiles[s.name]
    h = t.heights
    for fl in t.spec["flights"]:
        if fl["kind"] != "straight":
            continue
        d = ((fl["n"] - 1) // 2 + 0.5) * s.tread
        x = fl["start"][0] + fl["dir"][0] * d
        y = fl["start"][1] + fl["dir"][1] * d
        ix, iy = int(round(x / RES)), int(round(y / RES))
        line, i = (h[:, ix], iy) if fl["dir"][0] != 0 else (h[iy, :], ix)
        same = np.abs(line - line[i]) <= Q / 2
        lo = i
        while lo > 0 and same[lo - 1]:
            lo -= 1
        hi = i
        while hi < len(line) - 1 and same[hi + 1]:
            hi += 1
        assert abs((hi - lo + 1) * RES - s.width) <= RES + 1e-6, ((hi - lo + 1) * RES, s.width)


@pytest.mark.parametrize("s", [s for s in STAIRS if s.shape in ("l", "u", "switchback")],
                         ids=_ids)
def test_landings_flat_and_deep(s, tiles):
    """After every flight but the last, the landing is flat at base + n risers and as deep as
    specified along the flight's direction (l: at least the width)."""
    t, _ = tiles[s.name]
    fls = t.spec["flights"]
    depth = max(s.landing, s.width) if s.shape == "l" else s.landing
    for fl in fls[:-1]:
        (sx, sy), (dx, dy) = fl["start"], fl["dir"]
        d0 = (fl["n"] - 1) * s.tread
        u = np.arange(d0 + RES / 2, d0 + depth + 0.1, RES / 4)
        prof = nearest(t, sx + dx * u, sy + dy * u)
        level = fl["top"]
        flat = np.abs(prof - level) <= Q
        run = np.argmin(flat) if not flat.all() else len(flat)
        assert abs(run * RES / 4 + RES / 2 - depth) <= RES + 1e-6, (run * RES / 4, depth)
        assert t.walls[np.round((sy + dy * u[-1]) / RES).astype(int),
                       np.round((sx + dx * u[-1]) / RES).astype(int)]  # wall behind it


@pytest.mark.parametrize("s", STAIRS, ids=_ids)
def test_spawn_and_goal_areas_flat_both_directions(s, tiles):
    for t in tiles[s.name]:
        g = np.arange(t.heights.shape[0]) * RES
        X, Y = np.meshgrid(g, g)
        x, y, z, hx, hy = t.spawn[:5]
        assert hx > 0 and hy > 0 and abs(z - t.floor_height) < 1e-6
        box = ((np.abs(X - x) < hx + SPAWN_MARGIN - 1e-6)
               & (np.abs(Y - y) < hy + SPAWN_MARGIN - 1e-6))
        assert np.all(np.abs(t.heights[box] - t.floor_height) <= Q / 2)
        assert not t.walls[box].any()
        disk = np.hypot(X - t.goal[0], Y - t.goal[1]) <= GOAL_FLAT_RADIUS
        assert np.all(np.abs(t.heights[disk] - t.goal_height) <= Q / 2)
        assert not t.walls[disk].any()
    up, down = tiles[s.name]
    assert up.floor_height == 0 and abs(up.goal_height - s.total_rise) <= Q


@pytest.mark.parametrize("s", STAIRS, ids=_ids)
def test_route_climbs_every_riser_in_order_on_walkable_points_away_from_walls(s, tiles):
    """Along the centre-line (walking line of spirals and winders) the height never falls going
    up (never rises going down), changes by one riser at a time, s.risers times in all; every
    point is walkable and at least min(0.35, width/2) - a cell from any wall."""
    up, down = tiles[s.name]
    away = chamfer_distance(up.walls, RES, 1.0)
    for t, sign in ((up, 1), (down, -1)):
        pts = _dense(t.centreline[:, :2].astype(np.float64), RES / 4)
        prof = nearest(t, pts[:, 0], pts[:, 1])
        assert np.all(sign * np.diff(prof) >= -1e-6), "not monotonic along the route"
        idx, size = jumps(prof)
        assert len(idx) == s.risers, (len(idx), s.risers)
        assert np.all(np.abs(np.abs(size) - s.riser) <= 2 * s.height_error + Q + 1e-6)
        ij = np.round(pts[:, ::-1] / RES).astype(int)
        assert not t.walls[ij[:, 0], ij[:, 1]].any()
        assert away[ij[:, 0], ij[:, 1]].min() >= min(0.35, s.width / 2) - RES - 1e-6


@pytest.mark.parametrize("s", STAIRS, ids=_ids)
def test_descending_is_ascending_with_spawn_and_goal_swapped(s, tiles):
    up, down = tiles[s.name]
    assert (up.direction, down.direction) == ("up", "down")
    assert np.array_equal(up.heights, down.heights) and np.array_equal(up.walls, down.walls)
    np.testing.assert_allclose(down.spawn[:2], up.goal[:2], atol=1e-5)
    np.testing.assert_allclose(down.goal[:2], up.spawn[:2], atol=1e-5)
    assert down.spawn[2] == pytest.approx(up.goal_height) and down.goal[2] == up.floor_height
    assert (down.floor_height, down.goal_height) == (up.goal_height, up.floor_height)
    np.testing.assert_allclose(down.centreline, up.centreline[::-1], atol=1e-6)
    # facing down the stairs: the reverse of the heading on arriving at the top, and back
    assert np.cos(down.spawn[5] - up.goal[3]) == pytest.approx(-1, abs=1e-6)
    assert np.cos(down.goal[3] - up.spawn[5]) == pytest.approx(-1, abs=1e-6)
    back = down.reversed()
    for k in ("spawn", "goal", "centreline"):
        np.testing.assert_allclose(np.cos(getattr(back, k)), np.cos(getattr(up, k)), atol=1e-5)
        np.testing.assert_allclose(getattr(back, k)[..., :2], getattr(up, k)[..., :2],
                                   atol=1e-5)


@pytest.mark.parametrize("s", [s for s in STAIRS if s.shape in ("spiral", "winder")], ids=_ids)
def test_spiral_and_winder_steps_rise_along_the_walking_line(s, tiles):
    """On the walking line (spiral: r_in + width/2 about the core; winder: width/2 about the
    inner corner) the curved steps rise monotonically, one riser each, tread as specified."""
    t, _ = tiles[s.name]
    fl = next(f for f in t.spec["flights"] if f["kind"] in ("arc", "winder"))
    (cx, cy), rw = fl["centre"], fl["radius"]
    if fl["kind"] == "arc":
        a0, a1 = fl["walk"]
    else:   # inside the corner square, clear of the risers that bound it
        sign = np.sign(fl["sweep"])
        a0, a1 = fl["theta0"] + 0.1 * sign, fl["theta0"] + fl["sweep"] - 0.1 * sign
    th = np.linspace(a0, a1, int(abs(a1 - a0) * rw / (RES / 4)) + 2)
    prof = nearest(t, cx + rw * np.cos(th), cy + rw * np.sin(th))
    assert np.all(np.diff(prof) >= -1e-6)
    idx, size = jumps(prof)
    n = fl["n"] if fl["kind"] == "arc" else s.winders - 1   # winder 1 is level with flight 1
    assert len(idx) == n, (len(idx), n)
    assert np.all(np.abs(size - s.riser) <= 2 * s.height_error + Q + 1e-6)
    if fl["kind"] == "arc":
        assert abs(rw - (s.inner_radius + s.width / 2)) < 1e-9
        treads = np.diff(idx) * abs(th[1] - th[0]) * rw
        assert np.all(np.abs(treads - s.tread) <= np.sqrt(2) * RES), treads
        turn = abs(a1 - a0) + 2 * np.arctan2((s.width + 0.2) / 2, np.sqrt(rw ** 2 - (
            (s.width + 0.2) / 2) ** 2))
        assert turn / (2 * np.pi) == pytest.approx(s.turns, abs=1e-6)


@pytest.mark.parametrize("s", [s for s in STAIRS if s.open_side], ids=_ids)
def test_open_sides_really_drop(s, tiles):
    """0.1 m beyond the open edge of the first flight's middle tread is floor (not wall), a drop
    of the tread's full height; 0.1 m beyond the other edge is wall."""
    t, _ = tiles[s.name]
    fl = t.spec["flights"][0]
    if fl["kind"] == "arc":
        (cx, cy) = fl["centre"]
        mid = fl["theta0"] + fl["sweep"] / 2
        r = np.array([fl["r_out"] + 0.1, fl["r_in"] - 0.1, fl["radius"]])
        x, y = cx + r * np.cos(mid), cy + r * np.sin(mid)
    else:
        d = ((fl["n"] - 1) // 2 + 0.5) * s.tread
        (sx, sy), (dx, dy), (ox, oy) = fl["start"], fl["dir"], fl["open_dir"]
        off = np.array([s.width / 2 + 0.1, -(s.width / 2 + 0.1), 0.0])
        x, y = sx + dx * d + ox * off, sy + dy * d + oy * off
        assert abs(dx * ox + dy * oy) < 1e-9      # sideways
    ij = np.round(np.stack([y, x], -1) / RES).astype(int)
    h = t.heights[ij[:, 0], ij[:, 1]]
    walls = t.walls[ij[:, 0], ij[:, 1]]
    assert not walls[0] and walls[1] and not walls[2]
    assert h[0] == 0.0 and h[2] - h[0] >= s.riser * ((fl["n"] - 1) // 2) - s.height_error
    # the strip is OPEN_WIDTH wide, walled beyond
    far = np.array([x[0], y[0]]) + (np.array([x[0], y[0]]) - np.array([x[2], y[2]])) / np.hypot(
        x[0] - x[2], y[0] - y[2]) * OPEN_WIDTH
    assert t.walls[int(round(far[1] / RES)), int(round(far[0] / RES))]


@pytest.mark.parametrize("s", [s for s in STAIRS if not s.open_side and s.height_error == 0
                               and s.shape != "spiral"][:3], ids=_ids)
def test_walled_sides_and_exact_risers_without_errors(s, tiles):
    t, _ = tiles[s.name]
    for fl in t.spec["flights"]:
        if fl["kind"] == "straight":
            prof, _ = straight_flight_profile(t, fl, pad=0.1)
            assert np.all(np.abs(jumps(prof)[1] - s.riser) <= Q + 1e-6)


def test_left_and_right_are_mirror_images():
    s = STAIRS[[x.name for x in STAIRS].index("u_left_open")]
    a = staircase_tile(s, 0.05, 10.0)
    b = staircase_tile(replace(s, turn="right"), 0.05, 10.0)
    assert np.array_equal(a.heights[1:], b.heights[::-1][:-1])


# ------------------------------------------------------------------ sampling and levels
@pytest.fixture(scope="module")
def samples():
    """[(level, variant, Staircase)] for every train level, variant and 3 seeds."""
    out = []
    lv_table = terrains.levels("building")
    for i, lv in enumerate(lv_table):
        for v in VARIANTS:
            for seed in range(3):
                rng = np.random.default_rng(1000 * i + 10 * seed + len(v))
                out.append((i, v, sample_staircase(lv, v, rng, max_size=10.0)))
    return out


def test_samples_cover_the_issue_ranges(samples):
    ss = [s for _, _, s in samples]
    assert min(s.riser for s in ss) >= 0.02 and max(s.riser for s in ss) <= 0.21
    assert min(s.riser for s in ss) < 0.025 and max(s.riser for s in ss) > 0.2
    assert all(0.24 <= s.tread <= 0.35 and 0.8 <= s.width <= 2.0 for s in ss)
    assert all(0.9 <= s.landing <= 1.8 for s in ss)
    assert all(3 <= n <= 18 for s in ss for n in s.flights)
    assert all(s.height_error <= 0.005 for s in ss)
    sp = [s for s in ss if s.shape == "spiral"]
    assert all(0.3 <= s.inner_radius <= 1.0 and 0 < s.turns <= 1.0 for s in sp)
    assert max(s.turns for s in sp) == 1.0 and {s.turn for s in sp} == {"left", "right"}
    assert any(s.open_side for s in ss) and not all(s.open_side for s in ss)
    assert any(len(set(s.flights)) > 1 for s in ss if s.shape == "u")
    assert {s.shape for s in ss} == set(SHAPES)
    assert all(tile_size_for(s) <= 10.0 for s in ss)


def test_levels_are_ordered_by_difficulty(samples):
    """Riser bands rise with the level and do not overlap; the other ranges only get harder;
    every sample of level i+1 is harder than every sample of level i by the difficulty index
    (whose first key is the riser)."""
    lv = terrains.levels("building")
    assert len(lv) == 10 and lv[0].riser[0] == 0.02 and lv[-1].riser[1] == 0.21
    for a, b in zip(lv[:-1], lv[1:], strict=True):
        assert a.riser[1] == b.riser[0]
        assert b.width[0] <= a.width[0] and b.landing[0] <= a.landing[0]
        assert b.inner_radius[0] <= a.inner_radius[0] and b.max_turns >= a.max_turns
        assert b.open_prob >= a.open_prob and b.steps[1] >= a.steps[1]
    d = {}
    for i, _, s in samples:
        d.setdefault(i, []).append(difficulty(s))
    for i in range(9):
        assert max(d[i]) <= min(d[i + 1]) + 0.1, i   # ties only within the riser quantum
        assert np.median(d[i]) < np.median(d[i + 1])
    # the riser dominates: risers more than 2.2 cm apart are always ordered by it
    ss = [s for _, _, s in samples]
    r = np.array([s.riser for s in ss])
    dd = np.array([difficulty(s) for s in ss])
    far = (r[:, None] - r[None, :]) > 0.022
    assert far.any() and np.all((dd[:, None] > dd[None, :])[far])
    ext = terrains.levels("building", "extended")
    assert ext[0].riser[0] == 0.17 and ext[-1].riser[1] == 0.21


def test_make_tile_building_family():
    assert terrains.variants("building") == tuple(VARIANTS)
    a = terrains.make_tile("building", 4, "u_left", resolution=0.05)
    b = terrains.make_tile("building", 4, "u_left", resolution=0.05)
    c = terrains.make_tile("building", 4, "u_left", resolution=0.05, seed=1)
    t = terrains.make_tile("building", 4, "u_left", schedule="test", resolution=0.05)
    assert np.array_equal(a.heights, b.heights)                     # reproducible
    assert a.spec["staircase"] != c.spec["staircase"] != t.spec["staircase"]
    lv = terrains.get_level("building", 4)
    assert lv.riser[0] <= a.spec["riser"] <= lv.riser[1]
    d = terrains.make_tile("building", 4, "u_left", resolution=0.05, direction="down")
    assert d.direction == "down" and np.array_equal(d.heights, a.heights)
    small = terrains.make_tile("building", 9, "l_left", resolution=0.05, tile_size=6.0)
    assert small.heights.shape == (120, 120)   # flights shortened to fit
    with pytest.raises(ValueError, match="direction"):
        terrains.make_tile("building", 0, direction="sideways")
    with pytest.raises(ValueError, match="'zigzag'.*u_left"):
        terrains.make_tile("building", 0, "zigzag")


def test_tile_size_from_the_footprint():
    s = Staircase("l", 0.15, 0.35, 2.0, (18, 18), landing=1.8, open_side=True)
    size = tile_size_for(s)
    assert size == int(size) and size > 10.0         # too big for the default tile: a bigger one
    t = staircase_tile(s, 0.1)
    assert t.heights.shape == (int(size / 0.1),) * 2
    with pytest.raises(ValueError, match="does not fit a 10.0 m tile"):
        staircase_tile(s, 0.1, tile_size=10.0)
    f = fit(s, 10.0)                                 # or fewer risers in a 10 m tile
    assert max(f.flights) < 18 and tile_size_for(f) <= 10.0
    with pytest.raises(ValueError, match="even with 3 risers"):
        fit(s, 3.0)


def test_bad_staircases():
    with pytest.raises(ValueError, match="unknown staircase shape 'ramp'"):
        Staircase("ramp", 0.1, 0.3, 1.0, (5,))
    with pytest.raises(ValueError, match="u staircase has 2 flight"):
        Staircase("u", 0.1, 0.3, 1.0, (5,))
    with pytest.raises(ValueError, match="does not fit 0.5 turns"):
        staircase_tile(Staircase("spiral", 0.1, 0.3, 1.0, (18,), turns=0.5, inner_radius=0.3))
    with pytest.raises(ValueError, match="turns a multiple of 0.25"):
        Staircase("spiral", 0.1, 0.3, 1.0, (5,), turns=0.6)


def test_atlas_with_building_tiles_both_directions():
    at = terrains.build_atlas(["building", "u_shaped"], levels=[0, 9], variants_per_family=12,
                              resolution=0.1, direction="both")
    assert (at.rows, at.cols) == (2, 2 * (12 + 12))
    assert list(at.direction[:4]) == [0, 1, 0, 1]
    assert list(at.variant[:4]) == [0, 0, 1, 1] and at.variant[22] == 0   # 12th: cycle again
    n = at.tile_points
    h = at.tile_heights
    assert np.array_equal(h(0), h(1)) and not np.array_equal(h(0), h(22))  # new seed
    o = at.origin
    np.testing.assert_allclose(at.spawn[1, :2] - o[1], at.goal[0, :2] - o[0], atol=1e-4)
    np.testing.assert_allclose(at.goal[1, :2] - o[1], at.spawn[0, :2] - o[0], atol=1e-4)
    assert at.floor_height[1] == at.goal_height[0]
    assert h(0).shape == (n, n)
    down = terrains.build_atlas(["building"], levels=[3], variants_per_family=2,
                                resolution=0.1, direction="down")
    assert list(down.direction) == [1, 1]


def test_building_landing_overrides_the_landing_of_every_level():
    """build_atlas(building_landing=) (issue 24): without it the levels' own landings, bit for
    bit; each level's own range as the override changes nothing; (0.9, 0.9) makes every U and
    switchback 0.9 m deep at levels 1 and 5, the other dimensions drawn as without it."""
    kw = dict(levels=[0, 4], variants_per_family=11, resolution=0.1)
    base = terrains.build_atlas(["building"], **kw)
    none = terrains.build_atlas(["building"], building_landing=None, **kw)
    assert np.array_equal(base.heights, none.heights)
    assert np.array_equal(base.spawn, none.spawn) and np.array_equal(base.goal, none.goal)
    for lvl in (0, 4):
        own = terrains.get_level("building", lvl).landing
        one = dict(kw, levels=[lvl])
        assert np.array_equal(terrains.build_atlas(["building"], **one).heights,
                              terrains.build_atlas(["building"], building_landing=own,
                                                   **one).heights)
    tight = terrains.build_atlas(["building"], building_landing=[0.9, 0.9], **kw)
    assert not np.array_equal(tight.heights, base.heights)
    same = ("riser", "tread", "width", "turn", "open_side")
    for lvl in (0, 4):
        lv = terrains.get_level("building", lvl)
        for v in ("u_left", "u_right", "switchback_left", "switchback_right"):
            for seed in (0, 1):
                d = terrains.make_tile("building", lvl, v, resolution=0.1, seed=seed)
                t = terrains.make_tile("building", lvl, v, resolution=0.1, seed=seed,
                                       building_landing=(0.9, 0.9))
                assert t.spec["landing"] == 0.9, (lvl, v, seed)
                assert lv.landing[0] <= d.spec["landing"] <= lv.landing[1], (lvl, v, seed)
                assert all(t.spec["staircase"][k] == d.spec["staircase"][k] for k in same)
    u = terrains.make_tile("u_shaped", 4, building_landing=(0.9, 0.9), resolution=0.1)
    assert u.spec["landing"] == terrains.get_level("u_shaped", 4).landing   # paper: fixed


@pytest.mark.parametrize("bad", [[0.9], [1.5, 1.0], [-0.9, 1.8], [0.9, 3.5], "wide", 1.0])
def test_bad_building_landing_is_one_line_naming_it(bad):
    with pytest.raises(ValueError, match="building_landing") as e:
        terrains.build_atlas(["building"], levels=[0], resolution=0.1, building_landing=bad)
    assert len(str(e.value).splitlines()) == 1

