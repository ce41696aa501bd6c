"""Atlases joined side by side (families with different numbers of columns) and the per-tile
clear-width table."""

from __future__ import annotations

import numpy as np
import pytest

import terrains
from terrains import build_atlas, join_columns

KW = dict(levels=[0, 6], resolution=0.05, border=1.0, direction="both")


@pytest.fixture(scope="module")
def parts():
    return (build_atlas(["building"], variants_per_family=3, **KW),
            build_atlas(["u_shaped"], variants_per_family=1, **KW))


def test_joined_atlas_is_the_tiles_side_by_side(parts):
    building, u = parts
    both = join_columns([building, u])
    assert both.families == ("building", "u_shaped") and (both.rows, both.cols) == (2, 8)
    assert both.variant_names == building.variant_names + u.variant_names
    for row in range(2):
        for col in range(both.cols):
            t = row * both.cols + col
            src, c = (building, col) if col < building.cols else (u, col - building.cols)
            s = row * src.cols + c
            np.testing.assert_array_equal(both.tile_heights(t), src.tile_heights(s))
            shift = np.array([(col - c) * both.tile_size, 0.0])
            np.testing.assert_allclose(both.origin[t], src.origin[s] + shift)
            np.testing.assert_allclose(both.goal[t, :2], src.goal[s, :2] + shift, atol=1e-4)
            np.testing.assert_allclose(both.centreline[t, :, :2],
                                       src.centreline[s, :, :2] + shift, atol=1e-4)
            for key in ("level", "variant", "direction", "width", "floor_height"):
                assert getattr(both, key)[t] == getattr(src, key)[s], key
            assert both.family[t] == (0 if src is building else 1)


def test_same_counts_join_to_what_build_atlas_gives(parts):
    building, _ = parts
    u3 = build_atlas(["u_shaped"], variants_per_family=3, **KW)
    joined = join_columns([building, u3])
    whole = build_atlas(["building", "u_shaped"], variants_per_family=3, **KW)
    np.testing.assert_array_equal(joined.heights, whole.heights)
    for key in ("level", "family", "variant", "direction", "width", "floor_height", "origin"):
        np.testing.assert_array_equal(getattr(joined, key), getattr(whole, key), err_msg=key)
    for key in ("spawn", "goal", "centreline"):  # re-offset in float32: rounding only
        np.testing.assert_allclose(getattr(joined, key), getattr(whole, key), atol=1e-4)


def test_join_refuses_what_does_not_fit(parts):
    building, u = parts
    with pytest.raises(ValueError, match="appears in two"):
        join_columns([building, building])
    other = build_atlas(["u_shaped"], variants_per_family=1, levels=[0], resolution=0.05,
                        border=1.0)
    with pytest.raises(ValueError, match="differ in rows"):
        join_columns([building, other])


def test_width_is_the_stairs_clear_width_and_survives_a_file(parts, tmp_path):
    building, u = parts
    for atlas in (building, u):
        for t in range(atlas.num_tiles):
            fam = atlas.families[atlas.family[t]]
            var = atlas.variant_names[atlas.family[t]][atlas.variant[t]]
            tile = terrains.make_tile(fam, int(atlas.level[t]), var, resolution=0.05)
            assert atlas.width[t] == np.float32(tile.spec["width"])
    pyramid = build_atlas(["pyramid"], levels=[3], variants_per_family=1, resolution=0.05)
    assert pyramid.width.tolist() == [0.0]  # no clear width: a route is never shifted
    building.save(tmp_path / "a.npz")
    np.testing.assert_array_equal(terrains.Atlas.load(tmp_path / "a.npz").width, building.width)
    with np.load(tmp_path / "a.npz") as z:  # a file from before the table: width 0
        old = {k: z[k] for k in z.files if k != "width"}
    np.savez(tmp_path / "old.npz", **old)
    assert not terrains.Atlas.load(tmp_path / "old.npz").width.any()
