"""The atlas: tiles and tables where the tables say, .npz round trip, errors."""

from __future__ import annotations

import numpy as np
import pytest

import terrains
from terrains import Atlas, build_atlas, sample_heights


@pytest.fixture(scope="module")
def atlas():
    return build_atlas(["u_shaped", "pyramid"], schedule="train", levels=[0, 4, 9],
                       variants_per_family=3, resolution=0.05, tile_size=10.0, border=1.0)


def test_layout(atlas):
    assert (atlas.rows, atlas.cols) == (3, 6)
    n = 200
    assert atlas.heights.shape == (2 * 20 + 3 * n + 1, 2 * 20 + 6 * n + 1)
    assert atlas.heights.dtype == np.float32
    assert atlas.origin.shape == (18, 2) and atlas.spawn.shape == (18, 7)
    assert atlas.goal.shape == (18, 4) and atlas.centreline.shape == (18, 64, 3)
    assert atlas.level.dtype == np.int32 and list(atlas.level[:6]) == [0] * 6
    assert list(atlas.level[6::6]) == [4, 9]
    assert list(atlas.family[:6]) == [0, 0, 0, 1, 1, 1]
    assert list(atlas.variant[:6]) == [0, 1, 0, 0, 1, 2]            # left, right, left; +x, -x, +y
    assert np.allclose(atlas.origin[7], [1.0 + 1 * 10.0, 1.0 + 1 * 10.0])
    # the border is flat at 0
    b = 20
    assert not atlas.heights[:b].any() and not atlas.heights[:, :b].any()
    assert not atlas.heights[-b:].any() and not atlas.heights[:, -b:].any()


def test_tiles_are_where_the_tables_say(atlas):
    for t in range(atlas.num_tiles):
        fam = atlas.families[atlas.family[t]]
        var = atlas.variant_names[atlas.family[t]][atlas.variant[t]]
        tile = terrains.make_tile(fam, int(atlas.level[t]), var, resolution=0.05)
        ix, iy = np.round(atlas.origin[t] / atlas.resolution).astype(int)
        np.testing.assert_array_equal(atlas.heights[iy:iy + 200, ix:ix + 200], tile.heights)
        np.testing.assert_array_equal(atlas.tile_heights(t), tile.heights)
        o = atlas.origin[t]
        np.testing.assert_allclose(atlas.spawn[t, :2], tile.spawn[:2] + o, atol=1e-5)
        np.testing.assert_allclose(atlas.spawn[t, 2:], tile.spawn[2:])
        np.testing.assert_allclose(atlas.goal[t, :2], tile.goal[:2] + o, atol=1e-5)
        np.testing.assert_allclose(atlas.centreline[t, :, :2], tile.centreline[:, :2] + o,
                                   atol=1e-5)
        # world tables index the world heightfield: goal z is the atlas height at the goal
        gz = sample_heights(atlas.heights, atlas.resolution, atlas.goal[t, 0], atlas.goal[t, 1])
        assert abs(gz - atlas.goal[t, 2]) < 1e-5
        assert abs(atlas.goal_height[t] - tile.goal_height) < 1e-6
        sz = sample_heights(atlas.heights, atlas.resolution, atlas.spawn[t, 0], atlas.spawn[t, 1])
        assert abs(sz - atlas.floor_height[t]) < 1e-6
        cz = sample_heights(atlas.heights, atlas.resolution, atlas.centreline[t, :, 0],
                            atlas.centreline[t, :, 1])
        np.testing.assert_allclose(cz, atlas.centreline[t, :, 2], atol=1e-5)


def test_save_load_round_trip(atlas, tmp_path):
    path = tmp_path / "atlas.npz"
    atlas.save(path)
    back = Atlas.load(path)
    for k in ("heights", "origin", "spawn", "goal", "centreline", "level", "family", "variant",
              "floor_height", "goal_height"):
        a, b = getattr(atlas, k), getattr(back, k)
        assert a.dtype == b.dtype and np.array_equal(a, b), k
    for k in ("resolution", "tile_size", "border", "rows", "cols", "families", "schedule",
              "variant_names"):
        assert getattr(atlas, k) == getattr(back, k), k
    assert [p.name for p in tmp_path.iterdir()] == ["atlas.npz"]  # no temporary left behind


def test_load_errors(atlas, tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.npz"):
        Atlas.load(tmp_path / "nope.npz")
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"this is not a zip file")
    with pytest.raises(ValueError, match="bad.npz") as e:
        Atlas.load(bad)
    assert "\n" not in str(e.value)
    truncated = tmp_path / "trunc.npz"
    atlas.save(truncated)
    data = truncated.read_bytes()
    truncated.write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match="trunc.npz"):
        Atlas.load(truncated)
    tile_file = tmp_path / "tile.npz"
    terrains.make_tile("straight", 0, resolution=0.05).save(tile_file)
    with pytest.raises(ValueError, match="tile.npz: not a saved atlas"):
        Atlas.load(tile_file)


def test_tiny_cpu_atlas():
    a = build_atlas(["u_shaped"], levels=[0, 1], variants_per_family=1, resolution=0.05,
                    tile_size=8.0)
    assert (a.rows, a.cols) == (2, 1) and a.heights.shape == (80 + 2 * 160 + 1, 80 + 160 + 1)


def test_mixed_schedules_need_levels():
    with pytest.raises(ValueError, match="levels="):
        build_atlas(["pyramid", "u_shaped"], schedule="test", resolution=0.1)
    a = build_atlas(["pyramid", "u_shaped"], schedule="test", levels=[0], resolution=0.1,
                    variants_per_family=1)
    assert a.cols == 2


def test_bad_arguments():
    with pytest.raises(ValueError, match="'stairs'.*pyramid"):
        build_atlas(["stairs"])
    with pytest.raises(ValueError, match="schedule"):
        build_atlas(["u_shaped"], schedule="hard")
    with pytest.raises(ValueError, match="level 12"):
        build_atlas(["u_shaped"], levels=[12], resolution=0.1)
    with pytest.raises(ValueError, match="variants_per_family"):
        build_atlas(["u_shaped"], variants_per_family=0)
