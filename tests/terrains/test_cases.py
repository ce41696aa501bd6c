"""A user's staircases as tiles (terrains.cases): a case folder read back as the tiles it was
written from, a mesh walled where its grid ends, the user's route followed, staircases of any
size in one atlas without cropping, and one-line errors for bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

import terrains
from terrains import WALL_RISE
from terrains.cases import (
    WALL_RING,
    mesh_tile,
    parse_pose,
    read_case,
    read_case_folder,
    read_route_csv,
)
from terrains.suites import load_suite, write_case
from terrains.tile import pad_tile

RES = 0.1


def _mesh_frame(tile, xy):
    return np.asarray(xy, np.float64) + np.asarray(tile.spec["origin"])


def _inner(tile, shape):
    """The part of an imported tile's grid that is the mesh's own (inside the wall ring)."""
    ox, oy = tile.spec["padded_by"]
    return tile.heights[oy:oy + shape[0], ox:ox + shape[1]]


@pytest.mark.parametrize("name", ["code_residential_u_left_down", "paper_spiral_level3_up"])
def test_case_folder_reads_back_the_tiles_it_was_written_from(name, tmp_path):
    case = next(c for s in ("code", "paper") for c in load_suite(s) if c.name == name)
    t = case.tile(RES)
    write_case(t, tmp_path, name)
    [(got_name, back)] = read_case_folder(tmp_path, RES)
    assert got_name == name and back.direction == t.direction
    np.testing.assert_array_equal(_inner(back, t.heights.shape), t.heights)
    np.testing.assert_allclose(_mesh_frame(back, back.spawn[:2]), t.spawn[:2], atol=1e-4)
    np.testing.assert_allclose(back.spawn[2:], t.spawn[2:], atol=1e-4)
    np.testing.assert_allclose(_mesh_frame(back, back.goal[:2]), t.goal[:2], atol=1e-4)
    np.testing.assert_allclose(_mesh_frame(back, back.centreline[:, :2]), t.centreline[:, :2],
                               atol=1e-3)
    np.testing.assert_allclose(back.centreline[:, 2], t.centreline[:, 2], atol=2e-3)


def _open_flight(path, risers=6, riser=0.15, tread=0.3, width=1.0):
    """A straight flight open on both sides (no walls), floor before and landing after."""
    parts = [trimesh.creation.box((1.5, width, 0.1), trimesh.transformations.translation_matrix(
        (-0.75, 0, -0.05)))]
    for k in range(1, risers + 1):
        h = k * riser
        parts.append(trimesh.creation.box((tread, width, h), trimesh.transformations
                                          .translation_matrix(((k - 0.5) * tread, 0, h / 2))))
    top = risers * riser
    parts.append(trimesh.creation.box((1.5, width, top), trimesh.transformations
                                      .translation_matrix((risers * tread + 0.75, 0, top / 2))))
    trimesh.util.concatenate(parts).export(path)
    return risers * tread + 1.0, top


def test_a_mesh_is_walled_where_its_grid_ends(tmp_path):
    goal_x, top = _open_flight(tmp_path / "open.stl")
    t = mesh_tile(tmp_path / "open.stl", (-1.0, 0.0), (goal_x, 0.0), resolution=RES)
    ring = int(np.ceil(WALL_RING / RES - 1e-9))
    edge = np.ones(t.heights.shape, bool)
    edge[ring:-ring, ring:-ring] = False
    assert t.walls[edge].all()
    assert t.heights[edge].min() >= top + WALL_RISE - 1e-3   # nothing walks off the grid
    assert t.heights.shape[0] == t.heights.shape[1]           # square, for an atlas
    assert t.direction == "up" and t.goal[2] == pytest.approx(top, abs=1e-3)
    back = mesh_tile(tmp_path / "open.stl", (goal_x, 0.0, np.pi), (-1.0, 0.0), resolution=RES)
    assert back.direction == "down" and back.spawn[5] == pytest.approx(np.pi)


def test_the_users_route_is_followed(tmp_path):
    goal_x, _ = _open_flight(tmp_path / "open.stl", width=2.0)
    route = [(-1.0, 0.0), (0.5, 0.4), (goal_x - 0.5, 0.4), (goal_x, 0.0)]
    csv = tmp_path / "route.csv"
    csv.write_text("x,y\n# off-centre on purpose\n" + "\n".join(f"{x},{y}" for x, y in route))
    pts = read_route_csv(csv)
    np.testing.assert_allclose(pts, route)
    t = mesh_tile(tmp_path / "open.stl", (-1.0, 0.0), (goal_x, 0.0), pts, resolution=RES)
    line = _mesh_frame(t, t.centreline[:, :2])
    np.testing.assert_allclose(line[0], route[0], atol=1e-5)
    np.testing.assert_allclose(line[-1], route[-1], atol=1e-5)
    for p in route:  # every corner of the route is on the centre-line
        assert np.hypot(*(line - p).T).min() < 1e-5
    on_flight = (line[:, 0] > 0.6) & (line[:, 0] < goal_x - 0.6)
    np.testing.assert_allclose(line[on_flight, 1], 0.4, atol=1e-5)
    assert t.spawn[5] == pytest.approx(np.arctan2(0.4, 1.5), abs=1e-5)  # facing along it
    assert np.allclose(t.centreline[:, 2], t.height_at(t.centreline[:, 0], t.centreline[:, 1]))


def test_a_staircase_bigger_than_the_tile_is_padded_not_cropped():
    big = terrains.staircase_tile(terrains.Staircase("straight", 0.17, 0.3, 1.0, (36,)), RES)
    small = terrains.make_tile("u_shaped", 2, schedule="test", resolution=RES)
    assert big.heights.shape[0] * RES > terrains.DEFAULT_TILE_SIZE
    atlas = terrains.build_tile_atlas([[small], [big]])
    assert atlas.tile_size == pytest.approx(big.heights.shape[0] * RES)
    np.testing.assert_array_equal(atlas.tile_heights(1), big.heights)
    padded = atlas.tile_heights(0)
    ox, oy = pad_tile(small, atlas.tile_points).spec["padded_by"]
    n = small.heights.shape[0]
    np.testing.assert_array_equal(padded[oy:oy + n, ox:ox + n], small.heights)
    outside = np.ones(padded.shape, bool)
    outside[oy:oy + n, ox:ox + n] = False
    assert padded[outside].min() >= small.heights[~small.walls].max() + WALL_RISE - 1e-3
    np.testing.assert_allclose(atlas.goal[0, :2], small.goal[:2] + atlas.origin[0]
                               + np.array([ox, oy]) * RES, atol=1e-5)
    np.testing.assert_allclose(atlas.goal[1, :2], big.goal[:2] + atlas.origin[1], atol=1e-5)


def _one_line(exc) -> str:
    msg = str(exc.value)
    assert "\n" not in msg
    return msg


@pytest.mark.parametrize("text, message", [
    ("{not json", "malformed case JSON (line 1"),
    ('{"start": [0, 0], "goal": [1, 1]}', "malformed case JSON (missing key 'mesh')"),
    ('{"mesh": "m.stl", "start": [0], "goal": [1, 1]}', "start must be [x, y]"),
    ('{"mesh": "m.stl", "start": [0, 0], "goal": "up"}', "malformed case JSON"),
    ('{"mesh": "m.stl", "start": [0, 0], "goal": [1, 0], "route": [1, 2, 3]}',
     "route must be a list of [x, y] pairs"),
    ('[1, 2]', "malformed case JSON"),
])
def test_malformed_case_json_one_line(text, message, tmp_path):
    (tmp_path / "c.json").write_text(text)
    with pytest.raises(ValueError) as e:
        read_case(tmp_path / "c.json", RES)
    assert "c.json: " in _one_line(e) and message in str(e.value)


def test_bad_cases_one_line_errors(tmp_path):
    goal_x, _ = _open_flight(tmp_path / "open.stl")
    (tmp_path / "c.json").write_text(json.dumps(
        {"mesh": "gone.stl", "start": [-1, 0], "goal": [goal_x, 0]}))
    with pytest.raises(FileNotFoundError, match="gone.stl: no such mesh file") as e:
        read_case(tmp_path / "c.json", RES)
    _one_line(e)
    with pytest.raises(FileNotFoundError, match="nope: no such folder of cases"):
        read_case_folder(tmp_path / "nope")
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="empty: no case files"):
        read_case_folder(tmp_path / "empty")
    with pytest.raises(ValueError, match=r"route point \(9, 0\) lies outside the mesh") as e:
        mesh_tile(tmp_path / "open.stl", (-1, 0), (goal_x, 0), [(-1, 0), (9, 0)], RES)
    _one_line(e)
    (tmp_path / "r.csv").write_text("0,0\n1;2\nx,y\n")
    with pytest.raises(ValueError, match=r"r.csv:3: expected x,y"):
        read_route_csv(tmp_path / "r.csv")
    with pytest.raises(FileNotFoundError, match="no such route file"):
        read_route_csv(tmp_path / "none.csv")
    assert parse_pose("1,2", "start") == (1.0, 2.0, None)
    assert parse_pose("1,2,0.5", "goal") == (1.0, 2.0, 0.5)
    with pytest.raises(ValueError, match="--start: expected x,y or x,y,yaw"):
        parse_pose("1", "start")
