"""Perturbed routes (env.routes) and the elevation-map errors of the height map (env.perception):
pure functions on small arrays, no physics."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import terrains
from mjx_stairs.env import observation, perception, routes
from mjx_stairs.env.config import EnvConfig, NoiseConfig, RouteConfig
from mjx_stairs.env.tiles import TileTables

K = terrains.CENTRELINE_POINTS


def _polyline(*corners) -> jnp.ndarray:
    """[K, 3] the polyline through `corners` (x, y) at z 0, (K - 1) // legs points a leg, every
    corner a point of it (the end repeated to K points, as terrains pads centre-lines)."""
    c = np.asarray(corners, np.float64)
    n = (K - 1) // (len(c) - 1)
    legs = [a + np.linspace(0, 1, n, endpoint=False)[:, None] * (b - a)
            for a, b in zip(c[:-1], c[1:], strict=True)]
    xy = np.concatenate(legs + [np.repeat(c[-1:], K - n * (len(c) - 1), 0)])
    return jnp.asarray(np.concatenate([xy, np.zeros((K, 1))], 1), jnp.float32)


L_ROUTE = _polyline((0.0, 0.0), (4.0, 0.0), (4.0, 4.0))  # an L: 4 m along +x, then 4 m up +y


def _distance_to(points: np.ndarray, line: np.ndarray) -> np.ndarray:
    """[M] planar distance of each point [M, 2] to the polyline [K, 2]."""
    a, b = line[:-1], line[1:]
    ab = b - a
    t = np.clip(np.einsum("mkd,kd->mk", points[:, None] - a, ab)
                / np.maximum((ab * ab).sum(-1), 1e-12), 0, 1)
    return np.linalg.norm(points[:, None] - (a + t[..., None] * ab), axis=-1).min(1)


def test_a_coarse_route_is_a_polyline_through_points_of_the_route():
    cum = routes.arc_lengths(L_ROUTE)
    two = np.asarray(routes.coarse(L_ROUTE, cum, jnp.int32(2)))
    # two points: the chord from start to end, the corner cut entirely
    np.testing.assert_allclose(two[:, 0], two[:, 1], atol=1e-4)
    np.testing.assert_allclose(two[[0, -1], :2], [[0, 0], [4, 4]], atol=1e-4)
    three = np.asarray(routes.coarse(L_ROUTE, cum, jnp.int32(3)))
    # three points, evenly spaced by arc length: start, the corner, the end
    np.testing.assert_allclose(three[K // 2 - 1:K // 2 + 1, :2].mean(0), [4, 0], atol=0.2)
    assert _distance_to(three[:, :2], np.asarray(L_ROUTE)[:, :2]).max() < 1e-3


def test_cutting_corners_moves_the_corner_inside_and_keeps_the_ends():
    cut = np.asarray(routes.cut_corners(L_ROUTE, jnp.float32(1.0), jnp.float32(1.0)))
    np.testing.assert_allclose(cut[[0, -1]], np.asarray(L_ROUTE)[[0, -1]], atol=1e-5)
    corner = cut[np.argmin(np.linalg.norm(cut[:, :2] - [4, 0], axis=1))]
    # the corner moves halfway to the chord's midpoint (3.5, 0.5): inside the turn
    assert corner[0] < 3.7 and corner[1] > 0.3
    # straight parts more than a span from the corner stay where they were
    straight = np.abs(np.asarray(routes.arc_lengths(L_ROUTE)) - 4.0) > 1.1
    np.testing.assert_allclose(cut[straight], np.asarray(L_ROUTE)[straight], atol=1e-4)
    none = np.asarray(routes.cut_corners(L_ROUTE, jnp.float32(1.0), jnp.float32(0.0)))
    np.testing.assert_array_equal(none, np.asarray(L_ROUTE))


def test_shifting_sideways_moves_left_and_fades_out_at_the_goal():
    line = _polyline((0.0, 0.0), (6.0, 0.0))
    shifted = np.asarray(routes.shift_sideways(line, jnp.float32(0.3)))
    x = shifted[:, 0]
    np.testing.assert_allclose(x, np.asarray(line)[:, 0], atol=1e-5)
    far = x < 6.0 - routes.TAPER_M
    np.testing.assert_allclose(shifted[far, 1], 0.3, atol=1e-5)  # left of +x is +y
    np.testing.assert_allclose(shifted[-1, :2], [6.0, 0.0], atol=1e-5)
    right = np.asarray(routes.shift_sideways(line, jnp.float32(-0.3)))
    np.testing.assert_allclose(right[far, 1], -0.3, atol=1e-5)


def test_shifting_into_a_turn_never_runs_backwards():
    """A U-turn's centre-line (two 90-degree corners, evenly spaced points) shifted 0.67 m into
    the turn: no segment of the route runs against the centre-line (before the fix it looped
    back 0.5 m at each corner), its corners sit within a point spacing of the mitre, and the
    same shift to the outside is the plain pointwise shift."""
    u = _polyline((0.0, 0.0), (4.0, 0.0), (4.0, 2.2), (0.0, 2.2))
    spacing = 10.2 / ((K - 1) // 3)
    inside = np.asarray(routes.shift_sideways(u, jnp.float32(0.67)))
    heading = np.diff(np.asarray(u)[:, :2], axis=0)
    step = np.diff(inside[:, :2], axis=0)
    assert np.all(np.einsum("ij,ij->i", step, heading) >= -1e-6)  # never backwards
    for corner in ([3.33, 0.67], [3.33, 1.53]):  # the mitres of the two corners
        assert np.min(np.hypot(*(inside[:, :2] - corner).T)) < spacing
    assert np.all(inside[:, 0] < 3.33 + 1e-4)  # nothing beyond the inner line of the landing
    outside = np.asarray(routes.shift_sideways(u, jnp.float32(-0.67)))
    line = np.asarray(u)
    far = np.asarray(routes.arc_lengths(u)) < 10.2 - routes.TAPER_M
    np.testing.assert_allclose(np.hypot(*(outside - line)[far, :2].T), 0.67, atol=1e-4)


@pytest.fixture(scope="module")
def u_tiles():
    atlas = terrains.build_atlas(["building"], levels=[3], variants_per_family=5,
                                 resolution=0.05, border=1.0)
    return atlas, TileTables(atlas)


def test_perturbed_routes_stay_within_a_third_of_the_width(u_tiles):
    atlas, tiles = u_tiles
    rc = RouteConfig(perturb_prob=1.0, lateral=1 / 3, corner_cut_m=0.0, coarse_points=(64, 64))
    for tile in range(atlas.cols):
        width = float(atlas.width[tile])
        assert 0.7 < width < 2.1  # the building staircase's clear width, from the atlas
        line = np.asarray(tiles.line3[tile])
        perturb = jax.jit(lambda k, t=tile: routes.perturb(k, tiles.line3[t], tiles.line_cum[t],
                                                          tiles.width[t], rc))
        offsets = []
        for seed in range(8):
            route = np.asarray(perturb(jax.random.PRNGKey(seed)))
            d = _distance_to(route[:, :2], line[:, :2])
            assert d.max() <= width / 3 + 0.05, (tile, seed)
            np.testing.assert_allclose(route[-1, :2], line[-1, :2], atol=0.05)
            offsets.append(np.median(d))
        assert max(offsets) > width / 10  # routes are really moved


def test_routes_drawn_at_the_bound_are_shifted_by_the_whole_third(u_tiles):
    atlas, tiles = u_tiles
    line = np.asarray(tiles.line3[0])
    width = float(atlas.width[0])

    def medians(at_bound: float) -> np.ndarray:
        rc = RouteConfig(perturb_prob=1.0, lateral=1 / 3, corner_cut_m=0.0,
                         coarse_points=(64, 64), lateral_at_bound=at_bound)
        perturb = jax.jit(lambda k: routes.perturb(k, tiles.line3[0], tiles.line_cum[0],
                                                   tiles.width[0], rc))
        return np.array([np.median(_distance_to(np.asarray(perturb(jax.random.PRNGKey(s)))[:, :2],
                                                line[:, :2])) for s in range(12)])

    at = medians(1.0)
    np.testing.assert_allclose(at, width / 3, atol=0.05 * width)  # every one at the bound
    uniform = medians(0.0)
    assert uniform.min() < 0.6 * width / 3  # the default draws inside it


def test_an_episode_keeps_its_centreline_with_chance_one_minus_perturb_prob(u_tiles):
    _, tiles = u_tiles
    rc = RouteConfig(perturb_prob=0.5)
    same = [bool(jnp.array_equal(routes.perturb(jax.random.PRNGKey(s), tiles.line3[0],
                                                tiles.line_cum[0], tiles.width[0], rc),
                                 tiles.line3[0])) for s in range(40)]
    assert 8 <= sum(same) <= 32
    off = dataclasses.replace(EnvConfig(goal_mode="waypoint"), route=RouteConfig())
    assert routes.draw(jax.random.PRNGKey(0), tiles, jnp.int32(0), off) == {}


# ----------------------------------------------------------------------------- height map

S = 21
N = observation.N_VEC
QUIET = NoiseConfig(lin_vel=0.0, ang_vel=0.0, gravity=0.0, joint_pos=0.0, joint_vel=0.0,
                    height=0.0)


def _obs(step_at_col: int | None = None) -> dict:
    """Observations whose clean map is flat (0.1 m) or a 0.15 m step at a column."""
    m = np.full((S, S), 0.1, np.float32)
    if step_at_col is not None:
        m[:, step_at_col:] -= 0.15
    vec = np.arange(N, dtype=np.float32)
    clean = jnp.asarray(np.concatenate([vec, m.ravel()]))
    return {"state": clean + 0.01, "privileged_state": clean}


def _corrupt(noise: NoiseConfig, obs: dict, info: dict | None = None, seed: int = 0):
    cfg = EnvConfig(noise=noise)
    out = perception.corrupt(obs, info or {}, jax.random.PRNGKey(seed), cfg)
    np.testing.assert_array_equal(out["privileged_state"], obs["privileged_state"])
    np.testing.assert_array_equal(out["state"][:N], obs["state"][:N])
    return np.asarray(out["state"][N:])


def test_the_offset_moves_every_cell_of_the_actor_map_alone():
    noise = dataclasses.replace(QUIET, height_offset=0.05)
    info = perception.draw(jax.random.PRNGKey(3), EnvConfig(noise=noise))
    assert 0 < abs(float(info["height_offset"])) <= 0.05
    obs = _obs()
    got = _corrupt(noise, obs, info)
    np.testing.assert_allclose(got - np.asarray(obs["state"][N:]), info["height_offset"],
                               atol=1e-6)
    offsets = [float(perception.draw(jax.random.PRNGKey(s), EnvConfig(noise=noise))
                     ["height_offset"]) for s in range(10)]
    assert len(set(offsets)) == 10


def test_missing_cells_read_plus_clip_where_they_should():
    clip = EnvConfig().height_map.clip
    everywhere = _corrupt(dataclasses.replace(QUIET, height_missing=1.0), _obs())
    assert np.all(everywhere == clip)
    body = _corrupt(dataclasses.replace(QUIET, height_missing_body=1.0), _obs())
    holes = body == clip
    assert holes.sum() == 15  # 5 x 3 cells: |x| <= 0.4 m, |y| <= 0.2 m at 0.2 m spacing
    np.testing.assert_array_equal(holes, perception.body_cells(EnvConfig().height_map))
    rows, cols = np.nonzero(holes.reshape(S, S))
    assert set(cols) == {8, 9, 10, 11, 12} and set(rows) == {9, 10, 11}  # rows along y
    edge = _corrupt(dataclasses.replace(QUIET, height_missing_edge=1.0), _obs(step_at_col=14))
    rows, cols = np.nonzero((edge == clip).reshape(S, S))
    assert set(cols) == {13, 14} and len(rows) == 2 * S  # the cells either side of the edge
    assert not np.any(_corrupt(dataclasses.replace(QUIET, height_missing_edge=1.0), _obs())
                      == clip)  # a flat map has no edge


def test_missing_cells_come_at_their_rate_and_not_without_noise():
    noise = dataclasses.replace(QUIET, height_missing=0.25)
    rate = np.mean([_corrupt(noise, _obs(), seed=s) == 3.0 for s in range(20)])
    assert 0.21 < rate < 0.29
    obs = _obs()
    assert perception.corrupt(obs, {}, None, EnvConfig(noise=noise)) is obs  # critic / clean
    off = dataclasses.replace(noise, enabled=False)
    assert perception.corrupt(obs, {}, jax.random.PRNGKey(0), EnvConfig(noise=off)) is obs
    assert perception.corrupt(obs, {}, jax.random.PRNGKey(0), EnvConfig()) is obs  # defaults


def test_missing_cells_scale_with_the_episode_draw():
    """height_missing_per_episode: each episode draws a scale in [0, 1] of the chances, so a
    complete map (scale near 0) is as usual in training as a holey one."""
    noise = dataclasses.replace(QUIET, height_missing=0.5, height_missing_per_episode=True)
    cfg = EnvConfig(noise=noise)
    scales = [float(perception.draw(jax.random.PRNGKey(s), cfg)["missing_scale"])
              for s in range(200)]
    assert 0.0 <= min(scales) < 0.05 and 0.95 < max(scales) <= 1.0
    assert 0.45 < np.mean(scales) < 0.55
    assert not np.any(_corrupt(noise, _obs(), {"missing_scale": jnp.float32(0.0)}) == 3.0)
    full = np.mean([_corrupt(noise, _obs(), {"missing_scale": jnp.float32(1.0)}, seed=s) == 3.0
                    for s in range(20)])
    half = np.mean([_corrupt(noise, _obs(), {"missing_scale": jnp.float32(0.5)}, seed=s) == 3.0
                    for s in range(20)])
    assert 0.45 < full < 0.55 and 0.21 < half < 0.29
    fixed = dataclasses.replace(noise, height_missing_per_episode=False)
    assert "missing_scale" not in perception.draw(jax.random.PRNGKey(0), EnvConfig(noise=fixed))
