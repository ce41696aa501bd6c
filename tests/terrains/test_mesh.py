"""Mesh export (closed, vertical risers) and import (ray casting) of tiles."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

import terrains
from terrains import HEIGHT_QUANTUM as Q
from terrains.mesh import export_tile, heights_to_mesh
from terrains.mesh_import import import_mesh, load_mesh, raycast_down

RES = 0.05


@pytest.mark.parametrize("family", list(terrains.PAPER_FAMILIES))
def test_mesh_is_closed_with_vertical_risers(family):
    t = terrains.make_tile(family, 6, terrains.variants(family)[-1], resolution=RES)
    m = heights_to_mesh(t.heights, t.resolution)
    assert m.is_watertight and m.is_winding_consistent
    # volume of the solid = sum over cells of (height - base) * cell area
    base = t.heights.min() - 0.1
    expect = (t.heights.astype(np.float64) - base).sum() * RES ** 2
    assert m.volume == pytest.approx(expect, rel=1e-6)
    # every face is horizontal or vertical: risers are vertical, treads flat
    nz = np.abs(m.face_normals[:, 2])
    assert np.all((nz > 1 - 1e-9) | (nz < 1e-9))
    # coplanar cells are merged: far fewer triangles than two per grid cell
    assert len(m.faces) < 0.5 * t.heights.size


def test_mesh_of_a_hand_made_grid():
    h = np.array([[0.0, 0.0, 0.2], [0.0, 0.1, 0.2], [0.3, 0.3, 0.3]])
    m = heights_to_mesh(h, 0.5, origin=(1.0, 2.0))
    assert m.is_watertight
    assert m.volume == pytest.approx(((h + 0.1) * 0.25).sum())
    lo, hi = m.bounds
    np.testing.assert_allclose(lo, [0.75, 1.75, -0.1])
    np.testing.assert_allclose(hi, [2.25, 3.25, 0.3])


@pytest.mark.parametrize("family,ext", [("u_shaped", "obj"), ("spiral", "glb"),
                                        ("l_shaped", "stl"), ("pyramid", "ply"),
                                        ("straight", "glb")])
def test_export_then_import_reproduces_heights(family, ext, tmp_path):
    t = terrains.make_tile(family, 8, terrains.variants(family)[-1], resolution=RES)
    path = tmp_path / f"tile.{ext}"
    export_tile(t, path)
    back = import_mesh(path, t.spawn[:2], t.goal[:2], resolution=RES)
    assert back.heights.shape == t.heights.shape
    np.testing.assert_allclose(back.spec["origin"], [0, 0], atol=1e-6)
    assert np.abs(back.heights - t.heights).max() <= Q
    assert abs(back.goal_height - t.goal_height) <= Q
    assert abs(back.floor_height - t.floor_height) <= Q
    # the imported centre-line joins start to goal and climbs no more than a riser at a time
    c = back.centreline
    np.testing.assert_allclose(c[0, :2], t.spawn[:2], atol=1e-5)
    np.testing.assert_allclose(c[-1, :2], t.goal[:2], atol=1e-5)
    s = np.linspace(0, 1, 40)[:, None]
    dense = np.concatenate([a + s * (b - a) for a, b in zip(c[:-1, :2], c[1:, :2], strict=True)])
    hz = back.height_at(dense[:, 0], dense[:, 1])
    assert np.abs(np.diff(hz)).max() <= t.spec["riser"] + Q
    assert hz.max() <= t.goal_height + Q
    # walls: what the path search cannot reach, i.e. the tile's walls
    assert np.array_equal(back.walls, t.walls)


def test_raycast_down_hits_highest_surface():
    # two stacked horizontal squares: the upper one wins; a ceiling hides it
    sq = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    v = np.concatenate([sq, sq + [0, 0, 0.5]])
    f = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    x = np.linspace(-0.5, 1.5, 9)
    h = raycast_down(v, f, x, x)
    inside = (x >= 0) & (x <= 1)
    assert np.all(h[np.ix_(inside, inside)] == 0.5)
    assert np.isnan(h[0]).all() and np.isnan(h[:, -1]).all()
    assert np.all(raycast_down(v, f, x, x, ceiling=0.4)[np.ix_(inside, inside)] == 0.0)
    # a sloped triangle: z interpolated
    h = raycast_down(np.array([[0, 0, 0], [2, 0, 2], [0, 2, 0]], float), np.array([[0, 1, 2]]),
                     np.array([0.5]), np.array([0.5]))
    assert h[0, 0] == pytest.approx(0.5)


def test_import_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="nothere.obj"):
        load_mesh(tmp_path / "nothere.obj")
    empty = tmp_path / "empty.stl"
    empty.write_bytes(b"")
    with pytest.raises(ValueError, match="empty.stl: empty"):
        load_mesh(empty)
    junk = tmp_path / "junk.glb"
    junk.write_bytes(b"\x00\x01garbage" * 10)
    with pytest.raises(ValueError, match="junk.glb") as e:
        load_mesh(junk)
    assert "\n" not in str(e.value)
    no_faces = tmp_path / "points.obj"
    no_faces.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    with pytest.raises(ValueError, match="points.obj"):
        load_mesh(no_faces)
    flat = tmp_path / "line.obj"   # all vertices on a line: no footprint
    flat.write_text("v 0 0 0\nv 1 0 0\nv 2 0 1\nf 1 2 3\n")
    with pytest.raises(ValueError, match="line.obj: not a 3-D"):
        load_mesh(flat)
    txt = tmp_path / "notes.txt"
    txt.write_text("hello")
    with pytest.raises(ValueError, match="notes.txt: unsupported mesh format"):
        load_mesh(txt)
    # start outside the footprint, unreachable goal
    box = trimesh.creation.box((2, 2, 0.2))
    tower = trimesh.creation.box((0.5, 0.5, 2.0))
    tower.apply_translation((0.5, 0.5, 1.0))
    path = tmp_path / "tower.stl"
    trimesh.util.concatenate([box, tower]).export(path)
    with pytest.raises(ValueError, match="start .* outside"):
        import_mesh(path, (5.0, 5.0), (0.0, 0.0), resolution=RES)
    with pytest.raises(ValueError, match="cannot be reached"):
        import_mesh(path, (-0.7, -0.7), (0.5, 0.5), resolution=RES)
