"""terrains.boxes: a height grid as merged boxes with vertical risers."""

import numpy as np
import pytest

import terrains
from terrains.boxes import BOTTOM_DEPTH, box_top_height, grid_boxes


@pytest.mark.parametrize("family", ["straight", "u_shaped", "spiral"])
def test_boxes_reproduce_every_grid_height(family):
    tile = terrains.make_tile(family, 4, schedule="test", resolution=0.05)
    boxes = grid_boxes(tile.heights, tile.resolution, origin=(1.0, 2.0))
    ny, nx = tile.heights.shape
    x, y = np.meshgrid(1.0 + np.arange(nx) * 0.05, 2.0 + np.arange(ny) * 0.05)
    np.testing.assert_allclose(box_top_height(boxes, x, y), tile.heights, atol=1e-4)
    assert len(boxes) < tile.heights.size / 20  # equal heights merged
    assert np.allclose(boxes[:, 2] - boxes[:, 5], tile.heights.min() - BOTTOM_DEPTH)


def test_a_riser_stands_vertically_half_way_between_grid_points():
    h = np.zeros((3, 6), np.float32)
    h[:, 3:] = 0.17
    boxes = grid_boxes(h, 0.1)
    assert len(boxes) == 2
    top = box_top_height(boxes, np.array([0.249, 0.251]), np.array([0.1, 0.1]))
    np.testing.assert_allclose(top, [0.0, 0.17], atol=1e-6)


def test_bad_grids_are_refused():
    with pytest.raises(ValueError, match="2-D"):
        grid_boxes(np.zeros(4), 0.1)
    with pytest.raises(ValueError, match="NaN"):
        grid_boxes(np.full((2, 2), np.nan), 0.1)
