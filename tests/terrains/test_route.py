"""The importer's route: in the middle of the walkable width, within 0.15 m (Hausdorff) of the
procedural centre-line on every family's exported test levels 3 and 6; bad input -> one line."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

import terrains
from terrains.mesh import export_tile
from terrains.mesh_import import import_mesh

RES = 0.05
CASES = [(f, lvl, v) for f in terrains.PAPER_FAMILIES for lvl in (2, 5)
         for v in terrains.variants(f)[:1]]
CASES += [("building", lvl, v) for lvl in (2, 5) for v in terrains.variants("building")]

def dense(c: np.ndarray, step: float = 0.01) -> np.ndarray:
    out = [c[:1]]
    for a, b in zip(c[:-1], c[1:], strict=True):
        m = max(int(np.ceil(np.hypot(*(b - a)) / step)), 1)
        out.append(a + (b - a) * (np.arange(1, m + 1) / m)[:, None])
    return np.concatenate(out)


def hausdorff(a: np.ndarray, b: np.ndarray) -> float:
    """Hausdorff distance between two polylines [m, 2], [k, 2] (densified to 1 cm)."""
    a, b = dense(np.asarray(a, float)), dense(np.asarray(b, float))
    d = np.hypot(a[:, None, 0] - b[None, :, 0], a[:, None, 1] - b[None, :, 1])
    return float(max(d.min(1).max(), d.min(0).max()))


@pytest.mark.parametrize("case", CASES, ids=lambda c: f"{c[0]}-test{c[1] + 1}-{c[2]}")
def test_imported_route_follows_the_procedural_centreline(case, tmp_path):
    fam, lvl, v = case
    t = terrains.make_tile(fam, lvl, v, schedule="test", resolution=RES)
    path = tmp_path / "stairs.stl"
    export_tile(t, path)
    back = import_mesh(path, t.spawn[:2], t.goal[:2], resolution=RES)
    route = back.centreline[:, :2] + np.asarray(back.spec["origin"])
    assert hausdorff(route, t.centreline[:, :2]) <= 0.15


def test_route_is_centred_in_a_corridor_and_turns_mid_landing(tmp_path):
    """A U of 1.2 m flights: the route runs on the flights' middle lines and crosses the 1.0 m
    landing on its middle line, not round the end of the dividing wall."""
    s = terrains.Staircase("u", 0.15, 0.28, 1.2, (6, 6), landing=1.0)
    t = terrains.staircase_tile(s, RES)
    export_tile(t, tmp_path / "u.obj")
    back = import_mesh(tmp_path / "u.obj", t.spawn[:2], t.goal[:2], resolution=RES)
    route = dense(back.centreline[:, :2].astype(float) + np.asarray(back.spec["origin"]))
    fl = t.spec["flights"]
    x_mid = fl[0]["start"][0] + (fl[0]["n"] - 1) * s.tread + s.landing / 2
    y1, y2 = fl[0]["start"][1], fl[1]["start"][1]
    on_landing = (route[:, 1] > y1 + 2 * RES) & (route[:, 1] < y2 - 2 * RES)   # crossing it
    assert on_landing.sum() > 10 and np.abs(route[on_landing, 0] - x_mid).max() <= 2 * RES
    on_flight = np.abs(route[:, 0] - (fl[0]["start"][0] + 0.5)) < RES
    ys = route[on_flight, 1]
    assert np.min(np.abs(ys[:, None] - np.array([fl[0]["start"][1], fl[1]["start"][1]])),
                  axis=1).max() <= RES


@pytest.mark.parametrize("shape", ["l", "spiral"])
def test_open_side_route_reaches_the_flight_on_its_axis(shape, tmp_path):
    """An open side widens the start floor by the strip beside the first flight (l) or by the
    floor ring round the annulus (spiral). The route still reaches the first riser on the
    flight's axis (the l's middle line, the spiral's walking circle), as on the walled twin,
    not through the middle of the wider floor."""
    for open_side in (False, True):
        if shape == "l":
            s = terrains.Staircase("l", 0.12, 0.3, 1.4, (8, 8), open_side=open_side)
        else:
            s = terrains.Staircase("spiral", 0.12, 0.3, 1.4, (9,), inner_radius=0.8, turns=0.75,
                                   open_side=open_side)
        t = terrains.staircase_tile(s, RES)
        export_tile(t, tmp_path / "s.stl")
        back = import_mesh(tmp_path / "s.stl", t.spawn[:2], t.goal[:2], resolution=RES)
        route = dense(back.centreline[:, :2].astype(float) + np.asarray(back.spec["origin"]))
        fl = t.spec["flights"][0]
        if shape == "l":        # the start floor and the first tread
            foot = route[:, 0] < fl["start"][0] + s.tread
            off = np.abs(route[foot, 1] - fl["start"][1])
        else:                   # the floor sector from the corridor to the first riser, 1 tread
            rel = route - np.asarray(fl["centre"])
            th = np.arctan2(rel[:, 1], rel[:, 0])
            foot = (th > fl["walk"][0] + 0.1) & (th < fl["theta0"] + s.tread / fl["radius"])
            off = np.abs(np.hypot(*rel[foot].T) - fl["radius"])
        assert foot.sum() > 20 and off.max() <= 2 * RES, (open_side, float(off.max()))


def _one_line(exc) -> str:
    msg = str(exc.value)
    assert "\n" not in msg
    return msg


def test_bad_inputs_one_line_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="nothere.stl: no such mesh file") as e:
        import_mesh(tmp_path / "nothere.stl", (0, 0), (1, 1))
    _one_line(e)
    # a floor with a tower: the goal on the tower cannot be reached
    floor = trimesh.creation.box((3, 3, 0.2))
    tower = trimesh.creation.box((0.6, 0.6, 2.0))
    tower.apply_translation((0.8, 0.8, 1.0))
    mesh = trimesh.util.concatenate([floor, tower])
    mesh.export(tmp_path / "tower.stl")
    with pytest.raises(ValueError, match="tower.stl: no walkable route") as e:
        import_mesh(tmp_path / "tower.stl", (-1.0, -1.0), (0.8, 0.8), resolution=RES)
    _one_line(e)
    with pytest.raises(ValueError, match=r"tower.stl: start \(9.0, 9.0\) lies outside") as e:
        import_mesh(tmp_path / "tower.stl", (9.0, 9.0), (0.0, 0.0), resolution=RES)
    _one_line(e)
    # the same staircase in millimetres
    t = terrains.make_tile("straight", 3, resolution=0.1)
    export_tile(t, tmp_path / "mm.stl")
    mm = trimesh.load(tmp_path / "mm.stl", force="mesh")
    mm.apply_scale(1000.0)
    mm.export(tmp_path / "mm.stl")
    with pytest.raises(ValueError, match="mm.stl: .*looks like millimetres") as e:
        import_mesh(tmp_path / "mm.stl", t.spawn[:2] * 1000, t.goal[:2] * 1000)
    _one_line(e)


def test_offset_route_keeps_every_segment_at_the_distance():
    """A U-turn (two 90-degree corners) shifted 0.5 m left and right: every segment of the
    shifted polyline runs parallel to its original at 0.5 m, on the asked side."""
    from terrains.cases import offset_route

    u = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 2.0], [0.0, 2.0]])
    for dist in (0.5, -0.5):
        off = offset_route(u, dist)
        for a, b, p, q in zip(u[:-1], u[1:], off[:-1], off[1:], strict=True):
            t = (b - a) / np.hypot(*(b - a))
            left = np.array([-t[1], t[0]])
            assert abs(t[0] * (q - p)[1] - t[1] * (q - p)[0]) < 1e-9  # parallel
            assert np.allclose([(p - a) @ left, (q - b) @ left], dist)  # at the distance
    assert np.allclose(offset_route(u, 0.5)[1], [3.5, 0.5])  # inside the turn: a mitre
    line = np.stack([np.linspace(0.0, 4.0, 9), np.zeros(9)], 1)
    tapered = offset_route(line, 0.6, taper_m=1.0)  # ends on the route's end, as in training
    assert np.allclose(np.interp(line[:, 0], tapered[:, 0], tapered[:, 1]), [0.6] * 7 + [0.3, 0.0])
    assert np.allclose(tapered[-1], line[-1])
    with pytest.raises(ValueError, match="at least 2"):
        offset_route([[1.0, 1.0]], 0.3)


def test_offset_route_never_runs_backwards_inside_a_turn():
    """The U-shaped test level 3 centre-line (64 evenly spaced points, the tile's) shifted a
    third of its width to the inside of the turn, as code_suite's offset case: the shifted route
    is the corners' mitre (no loop), each segment runs the way its original does, and every
    point keeps the distance from the centre-line (the first run looped back 0.5 m at both
    landing corners: its robots fell or timed out)."""
    import terrains
    from terrains.cases import offset_route

    tile = terrains.make_tile("u_shaped", 2, "left", "test", 0.1)
    line = tile.centreline[:, :2].astype(np.float64)
    width = tile.spec["width"]
    for side in (1.0, -1.0):
        off = offset_route(line, side * width / 3)
        corners = offset_route(line[[0, 24, 39, 63]], side * width / 3)  # start, corners, goal
        assert np.allclose(off, corners, atol=1e-6), (off, corners)
        assert len(off) == 4 and off[2, 1] > off[1, 1]  # across the landing, one way
    # a swallowtail made and removed: a 0.4 m jog shifted 0.5 m into the turn
    z = np.array([[0.0, 0.0], [3.0, 0.0], [3.0, 0.4], [0.0, 0.4]])
    off = offset_route(z, 0.5)
    assert len(off) == 3 and np.allclose(off, [[0.0, 0.5], [2.5, 0.5], [0.0, -0.1]])
