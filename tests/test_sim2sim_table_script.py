"""experiments/gpu/sim2sim_table.py (issue 25's table): a family walked down, from the starts of
`mjx-stairs eval`, with an MJX column of the same starts beside sim2sim's."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest

import terrains

ROOT = Path(__file__).resolve().parents[1]
POLICY = ROOT / "experiments/results/stage2_u/policy.npz"
sys.path.insert(0, str(ROOT / "experiments/gpu"))  # importable by name in its spawned workers
import sim2sim_table as table  # noqa: E402


@pytest.fixture(scope="module")
def out(tmp_path_factory):
    out = tmp_path_factory.mktemp("s2s")
    table.main(["--policy", str(POLICY), "--out", str(out), "--cells", "straight",
                "--direction", "down", "--levels", "2", "--episodes", "4", "--workers", "1",
                "--chunk", "2", "--episode-s", "0.4", "--mjx-column",
                "robot=robot.joint_damping=2.0,robot.implicit_damping=true"])
    return out


def test_the_down_cell_starts_where_eval_starts_its_robots(out):
    cell = json.loads((out / "cells" / "straight_test_down_L2.json").read_text())
    assert cell["direction"] == "down" and cell["episodes"] == 4
    assert cell["contact_timeconst"] == 0.0  # the MJCF's, recorded (--contact-timeconst)
    args = table.main.__globals__["argparse"].Namespace(
        direction="down", levels=[1], episodes=4, seed=0, resolution=0.025)
    groups = table.family_starts(POLICY, table.eval_spec(args, "straight"))
    want = np.concatenate([poses for _, poses in groups["straight_test_down_L2"]])
    got = np.array([r["start"] for r in cell["records"]])
    np.testing.assert_allclose(got[np.lexsort(got.T[::-1])], want[np.lexsort(want.T[::-1])],
                               atol=1e-5)
    # walked down: every robot starts on its tile's top landing, the floor far below
    for variant, poses in groups["straight_test_down_L2"]:
        tile = terrains.make_tile("straight", 1, variant, "test", 0.025, 10.0, direction="down")
        top = tile.height_at(poses[:, 0], poses[:, 1])
        assert np.all(np.asarray(top) > 0.1 + np.min(tile.heights)), variant


def test_the_table_has_the_mjx_column_of_those_starts(out):
    mjx = json.loads((out / "mjx_robot_straight_down.json").read_text())
    assert mjx["direction"] == "down" and mjx["levels"] == [2]
    assert mjx["env_overrides"] == ["robot.joint_damping=2.0", "robot.implicit_damping=true"]
    assert mjx["physics_settings"]["terrain_contacts"] == "columns"  # the evaluation physics
    settings = mjx["physics_settings"]
    assert (settings["joint_damping"], settings["implicit_damping"]) == (2.0, True)
    assert settings["head_collision"] is False  # stage2_u's robot
    rows = (out / "table.md").read_text().splitlines()
    assert "robot success" in rows[0] and "gap (robot - sim2sim)" in rows[0]
    assert rows[2].startswith("| straight_test_down_L2 | 4 |")


def test_a_code_suite_file_is_an_mjx_column_of_the_code_cases(tmp_path):
    src = ROOT / "experiments/results/code_suite/evaluation_exit_d2/code_generalist_mix_1940.json"
    args = table.main.__globals__["argparse"].Namespace(
        mjx=False, mjx_column=[], mjx_json=None, cells=["code"], mjx_code=[f"MJX d2={src}"])
    cols = table.mjx_columns(args, tmp_path)
    want = json.loads(src.read_text())["results"]
    assert list(cols) == ["MJX d2"] and len(cols["MJX d2"]) == len(want) == 24
    for r in want:
        assert cols["MJX d2"][r["name"]] == r["success"]
    # a case's record carries its own direction, whatever --direction says
    assert table.cell_direction("code_residential_u_left_down", "up") == "down"
    assert table.cell_direction("code_commercial_straight_up", "down") == "up"
    assert table.cell_direction("straight_test_down_L2", "down") == "down"
    args.mjx_code = [str(src)]  # no NAME=
    with pytest.raises(SystemExit, match="expected NAME=FILE"):
        table.mjx_columns(args, tmp_path)


def test_cases_picks_code_cases_and_an_unknown_one_is_refused(tmp_path):
    onnx = ROOT / "experiments/results/generalist_d2/policy.onnx"
    args = table.main.__globals__["argparse"].Namespace(
        episode_s=1.0, latency_ms=0.0, noise=False, push=False, seed=0, chunk=2, episodes=3,
        cells=["code"], cases=["code_commercial_straight_down"], resolution=0.025, robot=None,
        contact_timeconst=0.01, code_starts="own")
    tasks = table.tasks_for(args, onnx, set())
    assert {t[0] for t in tasks} == {"code_commercial_straight_down"}
    assert {t[3]["contact_timeconst"] for t in tasks} == {0.01}  # each episode's MuJoCo contact
    assert sum(len(t[2]) for t in tasks) == 3  # the episodes, in chunks of 2
    assert table.tasks_for(args, onnx, {"code_commercial_straight_down"}) == []
    with pytest.raises(SystemExit, match="--cases: no case 'code_nowhere'"):
        table.main(["--out", str(tmp_path), "--cells", "code", "--cases", "code_nowhere"])


def test_the_code_cells_start_where_their_mjx_evaluation_does_and_are_paired_with_it(tmp_path):
    # the U case's tile is padded (centred) to the straight one's size in the cases' atlas
    cases = ["code_commercial_u_left_up", "code_commercial_straight_up"]
    args = table.main.__globals__["argparse"].Namespace(
        episode_s=0.2, latency_ms=0.0, noise=False, push=False, seed=3, chunk=2, episodes=3,
        cells=["code"], cases=cases, resolution=0.025, robot=None, contact_timeconst=0.01,
        code_starts="mjx", policy=POLICY, mjx=True, mjx_column=[], mjx_json=None, mjx_code=[])
    starts = table.code_starts(POLICY, args)
    for case in cases:  # in the case's own tile frame: on its spawn area, facing its heading
        x, y, _, hx, hy, yaw, half = table.course_of(("case", "code", case, 0.025)).spawn
        s = starts[case]
        assert s.shape == (3, 3)
        assert np.all(np.abs(s[:, 0] - x) <= hx) and np.all(np.abs(s[:, 1] - y) <= hy), case
        assert np.all(np.abs((s[:, 2] - yaw + np.pi) % (2 * np.pi) - np.pi) <= half + 1e-5)
    onnx = ROOT / "experiments/results/generalist_d2/policy.onnx"
    tasks = table.tasks_for(args, onnx, set())
    for case in cases:
        got = np.concatenate([t[2] for t in tasks if t[0] == case])
        np.testing.assert_allclose(got, starts[case])
    args.code_starts = "own"  # sim2sim's own seeded starts are other places
    own = np.concatenate([t[2] for t in table.tasks_for(args, onnx, set()) if t[0] == cases[0]])
    assert np.abs(own - starts[cases[0]]).max() > 0.05
    args.code_starts = "mjx"
    cols = table.mjx_columns(args, tmp_path)  # MJX on those very starts (physics stepped)
    mjx = json.loads((tmp_path / "mjx_code.json").read_text())
    assert sorted(r["name"] for r in mjx["results"]) == sorted(cases)
    assert mjx["robots_per_case"] == 3
    assert mjx["physics_settings"]["terrain_contacts"] == "columns"
    assert cols["MJX"] == {r["name"]: r["success"] for r in mjx["results"]}
    args.cases = cases[:1]  # a file of other cases is not reused
    assert set(table.mjx_columns(args, tmp_path)["MJX"]) == {cases[0]}
    assert len(json.loads((tmp_path / "mjx_code.json").read_text())["results"]) == 1
