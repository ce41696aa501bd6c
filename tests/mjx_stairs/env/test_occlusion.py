"""The height map's wall rule (HeightMapConfig.occlusion_samples, issue 24: "nothing behind a
wall"): on the U-shaped tile, a robot on the upper landing beside the divider sees the divider
where the map without the rule reads the lower landing behind it as a 0.8 m drop."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import terrains
from mjx_stairs.config import ConfigError
from mjx_stairs.env.config import EnvConfig, HeightMapConfig
from mjx_stairs.env.stair_env import StairEnv

K = 32


@pytest.fixture(scope="module")
def case():
    atlas = terrains.build_cell_atlas([("u_shaped", "test", 0)], 2, resolution=0.05,
                                      tile_size=10.0, border=1.0)
    plain = StairEnv(atlas, EnvConfig())
    occluded = StairEnv(atlas, EnvConfig(height_map=HeightMapConfig(occlusion_samples=K)))
    hmap = {name: jax.jit(jax.vmap(env.height_map, in_axes=(0, 0, 0)))
            for name, env in (("plain", plain), ("occluded", occluded))}
    rng = np.random.default_rng(0)
    pos, tiles = [], []
    for t in range(2):  # both turns; on each, the landing at 0.8 m beside the divider
        o = atlas.origin[t]
        for local in ((3.1, 4.2), (3.1, 5.9)):
            xy = o + np.asarray(local) + rng.uniform(-0.2, 0.2, 2)
            z = float(terrains.sample_heights(atlas.heights, atlas.resolution, xy[0], xy[1]))
            if z > 0.7:
                pos.append([*xy, z + 0.35])
                tiles.append(t)
    pos, tiles = np.asarray(pos, np.float32), np.asarray(tiles, np.int32)
    yaw = rng.uniform(-0.8, 0.8, len(pos)).astype(np.float32)
    maps = {k: np.asarray(f(jnp.asarray(pos), jnp.asarray(yaw), jnp.asarray(tiles)))
            for k, f in hmap.items()}
    return dict(atlas=atlas, env=occluded, pos=pos, yaw=yaw, tiles=tiles, **maps)


def _reference(case, i) -> tuple[np.ndarray, np.ndarray]:
    """(seen terrain z, plain terrain z) [S * S] at robot i by the rule, in numpy."""
    atlas, hm = case["atlas"], case["env"].config.height_map
    half = 0.5 * (hm.size - 1) * hm.spacing
    gx, gy = np.meshgrid(np.linspace(-half, half, hm.size), np.linspace(-half, half, hm.size))
    p, c, s = case["pos"][i].astype(np.float64), np.cos(case["yaw"][i]), np.sin(case["yaw"][i])
    o = atlas.origin[case["tiles"][i]]
    extent = (atlas.tile_points - 1) * atlas.resolution
    wx = np.clip(p[0] + c * gx - s * gy, o[0], o[0] + extent).ravel()
    wy = np.clip(p[1] + s * gx + c * gy, o[1], o[1] + extent).ravel()
    z = terrains.sample_heights(atlas.heights, atlas.resolution, wx, wy)
    f = np.arange(1, K)[None, :] / K
    zs = terrains.sample_heights(atlas.heights, atlas.resolution, p[0] + f * (wx[:, None] - p[0]),
                                 p[1] + f * (wy[:, None] - p[1]))
    return np.maximum(z, np.where(zs > p[2] + hm.sensor_height, zs, -np.inf).max(-1)), z


def test_the_map_reads_the_divider_behind_it_with_the_rule_and_the_drop_without(case):
    hm = case["env"].config.height_map
    assert len(case["pos"]) == 2  # one robot per turn
    for i in range(len(case["pos"])):
        seen, plain = _reference(case, i)
        base_z = float(case["pos"][i, 2])
        for name, z in (("occluded", seen), ("plain", plain)):
            np.testing.assert_allclose(
                case[name][i], np.clip(base_z - z - hm.offset, -hm.clip, hm.clip), atol=2e-4)
        behind = seen > plain + 0.5  # what the rule hides, read as the divider (1.6 m)
        assert np.all(seen[behind] > 1.5)
        low = behind & (plain < 0.5)  # the lower landing and flight past the divider
        assert low.sum() >= 20
        # the plain map shows a drop of 0.4-0.8 m there, the rule's map the divider above
        drop = case["plain"][i][low] - case["plain"][i][np.argmin(np.abs(plain - 0.8))]
        assert np.all(drop > 0.35) and np.all(case["occluded"][i][low] < -0.8)


def test_the_rule_is_off_by_default_and_checked():
    assert HeightMapConfig().occlusion_samples == 0
    for bad in (dict(occlusion_samples=1), dict(occlusion_samples=-3), dict(sensor_height=-0.1)):
        with pytest.raises(ConfigError, match="env.height_map"):
            dataclasses.replace(HeightMapConfig(), **bad)
