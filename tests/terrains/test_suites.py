"""The fixed suites (code, paper) and the folder writer: mesh + JSON per case, in the mesh
frame; the CLI commands suite and sample."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from terrains import HEIGHT_QUANTUM as Q
from terrains.__main__ import main, run
from terrains.mesh_import import raycast_down
from terrains.suites import load_suite, suite_names, suite_tile_size, write_case


def test_code_suite_is_every_shape_at_both_limits_up_and_down():
    cases = load_suite("code")
    assert suite_names() == ("code", "paper")
    assert len(cases) == 6 * 2 * 2
    shapes = {c.staircase.shape for c in cases}
    assert shapes == {"straight", "l", "u", "switchback", "spiral", "winder"}
    dims = {(c.staircase.riser, c.staircase.tread, c.staircase.width) for c in cases}
    assert dims == {(0.178, 0.279, 1.12), (0.197, 0.254, 0.91)}
    assert {c.direction for c in cases} == {"up", "down"}
    assert all(not c.staircase.open_side and c.staircase.height_error == 0 for c in cases)
    assert len({c.name for c in cases}) == len(cases)
    assert suite_tile_size(cases) == 8.0


def test_paper_suite_is_the_six_test_levels_up_and_down():
    cases = load_suite("paper")
    assert len(cases) == 4 * 6 * 2
    t = cases[-1].tile(resolution=0.1)
    assert (t.family, t.level, t.direction, t.spec["schedule"]) == ("spiral", 5, "down", "test")
    assert t.spec["riser"] == 0.14
    with pytest.raises(ValueError, match="unknown suite 'office'.*code, paper"):
        load_suite("office")


@pytest.mark.parametrize("name", ["code_residential_u_left_down", "code_commercial_spiral_ccw_up",
                                  "paper_l_shaped_level3_up"])
def test_case_files_in_the_mesh_frame(name, tmp_path):
    case = next(c for suite in ("code", "paper") for c in load_suite(suite) if c.name == name)
    t = case.tile(resolution=0.05)
    rec = write_case(t, tmp_path, name)
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"{name}.json", f"{name}.stl"]
    back = json.loads((tmp_path / f"{name}.json").read_text())
    assert back == json.loads(json.dumps(rec))
    assert back["mesh"] == f"{name}.stl" and back["direction"] == case.direction
    assert len(back["start"]) == 4 and len(back["goal"]) == 4 and len(back["route"]) == 64
    mesh = trimesh.load(tmp_path / back["mesh"], force="mesh")
    # the mesh surface under start, goal and route is where the JSON says
    pts = np.array([back["start"][:2], back["goal"][:2], *back["route"]])
    h = np.array([raycast_down(mesh.vertices, mesh.faces, np.array([x]), np.array([y]))[0, 0]
                  for x, y in pts[:3]])
    assert abs(h[0] - back["start"][2]) <= Q and abs(h[1] - back["goal"][2]) <= Q
    lo, hi = mesh.bounds
    assert np.all(pts >= lo[:2]) and np.all(pts <= hi[:2])
    np.testing.assert_allclose(back["route"][0], back["start"][:2], atol=1e-3)
    np.testing.assert_allclose(back["route"][-1], back["goal"][:2], atol=1e-3)


def test_cli_suite_and_sample(tmp_path):
    assert run(["suite", "code", "--resolution", "0.1", "--out", str(tmp_path / "code")]) == 0
    files = sorted(p.name for p in (tmp_path / "code").iterdir())
    assert len(files) == 48 and sum(f.endswith(".stl") for f in files) == 24
    assert run(["sample", "--levels", "2,9", "--variants", "spiral_cw,u_left", "--seeds", "2",
                "--resolution", "0.1", "--previews", "--out", str(tmp_path / "s")]) == 0
    names = sorted(p.stem for p in (tmp_path / "s").glob("*.json"))
    assert len(names) == 2 * 2 * 2 * 2
    assert "building_level9_spiral_cw_s1_down" in names
    assert (tmp_path / "s" / "building_level9_spiral_cw_s1_down.png").stat().st_size > 1000
    rec = json.loads((tmp_path / "s" / "building_level9_spiral_cw_s1_down.json").read_text())
    assert rec["family"] == "building" and rec["level"] == 9 and rec["spec"]["shape"] == "spiral"


def test_cli_direction_and_errors(tmp_path, capsys):
    assert run(["preview", "building", "--level", "4", "--variant", "winder_right",
                "--direction", "down", "--resolution", "0.1", "--out",
                str(tmp_path / "w.png")]) == 0
    assert main(["sample", "--levels", "11", "--out", str(tmp_path / "x")]) == 2
    assert "--levels 11 out of range" in capsys.readouterr().err
    assert main(["suite", "office", "--out", str(tmp_path / "x")]) == 2
    assert "unknown suite 'office'" in capsys.readouterr().err


def test_find_case_by_name_or_a_clear_error():
    from terrains.suites import find_case

    case = find_case("code", "code_residential_u_left_down")
    assert (case.direction, case.staircase.riser) == ("down", 0.197)
    assert find_case("paper", "paper_spiral_level6_up").level == 5
    with pytest.raises(ValueError, match="no case 'code_ramp_up' in suite 'code'"):
        find_case("code", "code_ramp_up")
