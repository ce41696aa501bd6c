"""terrains.boxes: a height grid as merged boxes with vertical risers."""

import numpy as np
import pytest

import terrains
from terrains.boxes import BOTTOM_DEPTH, MIN_WIDTH, box_top_height, grid_boxes


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
    boxes = grid_boxes(h, 0.1, supports="thin")
    assert len(boxes) == 2
    top = box_top_height(boxes, np.array([0.249, 0.251]), np.array([0.1, 0.1]))
    np.testing.assert_allclose(top, [0.0, 0.17], atol=1e-6)


def test_bad_grids_are_refused():
    with pytest.raises(ValueError, match="2-D"):
        grid_boxes(np.zeros(4), 0.1)
    with pytest.raises(ValueError, match="NaN"):
        grid_boxes(np.full((2, 2), np.nan), 0.1)


@pytest.mark.parametrize("family", ["straight", "u_shaped", "l_shaped"])
def test_rectangular_treads_get_the_plain_partition(family):
    """No box is thin where every riser runs along x or y: with supports="thin" the boxes tile
    the grid, none overlaps (the ground truth's straight, L and U worlds as measured before every
    box got a support)."""
    tile = terrains.make_tile(family, 5, schedule="test", resolution=0.025)
    boxes = grid_boxes(tile.heights, tile.resolution, supports="thin")
    assert np.min(2 * boxes[:, 3:5]) >= MIN_WIDTH - 1e-9
    area = np.sum(4 * boxes[:, 3] * boxes[:, 4])
    assert area == pytest.approx(tile.heights.size * tile.resolution**2, rel=1e-9)


def _stamp_feet(boxes, x, y, z, velocity, push, steps):
    """[N, 3] the centres of foot spheres (Go2 foot radius, mass and contact parameters) started
    at (x, y, z) over ``boxes`` with velocity (vx, vz) and a constant force (fx, fz), after
    ``steps`` MuJoCo steps of 5 ms."""
    import mujoco

    spec = mujoco.MjSpec()
    spec.option.timestep = 0.005
    spec.option.cone = mujoco.mjtCone.mjCONE_PYRAMIDAL
    for cx, cy, cz, hx, hy, hz in boxes:
        spec.worldbody.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, pos=[cx, cy, cz],
                                size=[hx, hy, hz], contype=0, conaffinity=1)
    for px, py, pz in zip(x, y, z, strict=True):
        body = spec.worldbody.add_body(pos=[px, py, pz])
        body.add_freejoint()
        body.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.022, 0, 0], mass=0.2,
                      contype=1, conaffinity=0, friction=[0.8, 0.02, 0.01],
                      solref=[0.02, 1.0], solimp=[0.9, 0.95, 0.001, 0.5, 2.0])
    model = spec.compile()
    data = mujoco.MjData(model)
    data.qvel.reshape(-1, 6)[:, [0, 2]] = velocity
    data.xfrc_applied[1:, [0, 2]] = push
    for _ in range(steps):
        mujoco.mj_step(model, data)
    return data.qpos.reshape(-1, 7)[:, :3]


def test_a_foot_stamped_into_a_spiral_tread_is_pushed_back_up():
    """A spiral's treads are strips one cell wide between its curved risers. A foot sphere (the
    Go2's: radius 0.022 m, its contact parameters) landing fast sinks its centre below a tread's
    top; among strips alone MuJoCo then pushed it sideways from two strips and never up, and it
    sank into the tread (measured: 29 of 40 spheres here ended 2.2 cm (median) under the top,
    the cause of the ground truth's 90 % falls on spiral tiles). The wide box under the strips
    pushes every one back up to stand on the tread, as on a plain slab."""
    tile = terrains.make_tile("spiral", 0, schedule="test", resolution=0.025)
    h, res = tile.heights, tile.resolution
    boxes = grid_boxes(h, res)
    level = np.round(h, 4)
    # points of treads (not floor, not walls) at least 2 cells from any other height
    pad = np.pad(level, 2, mode="edge")
    win = np.lib.stride_tricks.sliding_window_view(pad, (5, 5))
    tread = (win.max((-1, -2)) == win.min((-1, -2))) & (level > level.min()) & (level < level.max())
    iy, ix = np.nonzero(tread)
    rng = np.random.default_rng(0)
    pick = rng.choice(len(iy), 40, replace=False)
    x = (ix[pick] + rng.uniform(-0.5, 0.5, 40)) * res
    y = (iy[pick] + rng.uniform(-0.5, 0.5, 40)) * res
    top = box_top_height(boxes, x, y)
    p = _stamp_feet(boxes, x, y, top + 0.03, velocity=(0.0, -4.0), push=(0.0, -20.0), steps=40)
    centre = p[:, 2]  # a foot landing fast, the leg pressing it down
    assert np.all(centre - top > 0.015)  # on the tread, ~2 mm deep (measured 0.0196-0.0197)


@pytest.mark.parametrize("family, schedule, level", [("u_shaped", "extended", 2),
                                                     ("straight", "extended", 3)])
def test_a_foot_driven_into_a_riser_seam_is_pushed_back_up(family, schedule, level,
                                                           supports="all"):
    """On U-shaped and straight tiles (no thin box) a foot sphere driven fast forward and down
    into the corner of a tread and the next riser used to sink into the seam there, its centre
    inside the tread's box beside the next step's, pushed sideways by the two and never up
    (measured with supports="thin": all 40 here ended sunk, not standing on the tread; the
    ground truth's feet held 1-20 cm inside the steps, issue 19). The support under every box
    pushes each one back up onto the tread."""
    tile = terrains.make_tile(family, level, schedule=schedule, resolution=0.025)
    h, res = tile.heights, tile.resolution
    boxes = grid_boxes(h, res, supports=supports)
    level_ = np.round(h, 4)
    lo, hi = level_[:, :-1], level_[:, 1:]
    iy, ix = np.nonzero((hi > lo) & (hi - lo < 0.3) & (lo > level_.min()))  # riser up along x
    rng = np.random.default_rng(0)
    pick = rng.choice(len(iy), 40, replace=False)
    face = (ix[pick] + 0.5) * res
    x = face - rng.uniform(0.0, 0.03, 40)  # centre 0-3 cm before the riser's face
    y = (iy[pick] + rng.uniform(-0.5, 0.5, 40)) * res
    top = box_top_height(boxes, x, y)
    # a foot swinging into the riser and landing fast, the leg pressing it down and forward
    p = _stamp_feet(boxes, x, y, top + 0.03, velocity=(2.0, -6.0), push=(5.0, -20.0), steps=60)
    assert np.all(p[:, 0] < face)  # still before the riser
    assert np.all(p[:, 2] - top > 0.015)  # on the tread, ~2 mm deep (measured 0.019-0.020)
