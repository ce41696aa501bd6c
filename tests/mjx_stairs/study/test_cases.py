"""eval on any staircase, through the CLI on the CPU with the committed stage-2 policy: a folder
of cases in one atlas (one record per case), a case scoring the same alone, the critic map of a
mesh, and one-line errors for every bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

import terrains
from mjx_stairs import cli
from terrains.mesh import export_tile
from terrains.suites import load_suite, write_case

POLICY = "experiments/results/stage2_u/policy.npz"
RES, ROBOTS, EPISODE_S = 0.05, 4, 3.0
RUN = ["--checkpoint", POLICY, "--robots", str(ROBOTS), "--episode-s", str(EPISODE_S),
       "--resolution", str(RES), "--seed", "1"]
FLOOR_START, FLOOR_GOAL = (-0.6, 0.0), (0.6, 0.0)  # a goal 1.2 m away on flat ground


def _floor(path):
    floor = trimesh.creation.box((3.0, 2.0, 0.2))
    floor.apply_translation((0.0, 0.0, -0.1))
    floor.export(path)


@pytest.fixture(scope="module")
def suite(tmp_path_factory):
    """A folder of two cases: a staircase of the code suite walked down (written by `terrains
    suite`'s writer) and a flat floor with the goal 1.2 m from the start (written by hand)."""
    d = tmp_path_factory.mktemp("cases")
    code = next(c for c in load_suite("code") if c.name == "code_residential_u_left_down")
    write_case(code.tile(RES), d, code.name)
    _floor(d / "floor.stl")
    (d / "floor.json").write_text(json.dumps(
        {"mesh": "floor.stl", "start": [*FLOOR_START, 0.0, 0.0], "goal": [*FLOOR_GOAL, 0, 0]}))
    return d


@pytest.fixture(scope="module")
def together(suite, tmp_path_factory):
    out = tmp_path_factory.mktemp("out") / "cases.json"
    assert cli.main(["eval", "--suite", str(suite), *RUN, "--out", str(out)]) == 0
    assert list(out.parent.iterdir()) == [out]  # written atomically: no temporary file left
    return json.loads(out.read_text())


def test_a_folder_of_cases_one_record_each(together, suite, capsys):
    recs = {r["name"]: r for r in together["results"]}
    assert set(recs) == {"code_residential_u_left_down", "floor"}
    for r in recs.values():
        assert set(r) >= {"checkpoint", "name", "direction", "robots", "success", "fell",
                          "timeout", "mean_time_to_goal_s"}
        assert r["robots"] == ROBOTS
        assert r["success"] + r["fell"] + r["timeout"] >= 1.0 - 1e-9
    assert recs["code_residential_u_left_down"]["direction"] == "down"
    floor = recs["floor"]
    assert floor["direction"] == "up" and floor["success"] == 1.0  # a trained policy walks 1.2 m
    assert 0.5 < floor["mean_time_to_goal_s"] < EPISODE_S         # the 0.5 s hold included
    assert together["robots_per_case"] == ROBOTS and together["episode_length_s"] == EPISODE_S
    assert together["tile_size"] >= 5.0  # the U (5 m and a wall ring): the 3.4 m floor padded


def test_a_case_scores_the_same_alone(together, suite, tmp_path):
    """The floor case alone (eval --mesh, the same seed) against the floor among the suite: a
    robot starts from the same key, so the outcomes agree; its place in the atlas differs, so
    the trajectories agree up to float rounding (time to goal within a few steps)."""
    out = tmp_path / "alone.json"
    assert cli.main(["eval", "--mesh", str(suite / "floor.stl"),
                     "--start", ",".join(map(str, FLOOR_START)),
                     "--goal", ",".join(map(str, FLOOR_GOAL)), *RUN, "--out", str(out)]) == 0
    [alone] = json.loads(out.read_text())["results"]
    floor = next(r for r in together["results"] if r["name"] == "floor")
    for key in ("success", "fell", "timeout", "robots", "direction"):
        assert alone[key] == floor[key], key
    assert alone["mean_time_to_goal_s"] == pytest.approx(floor["mean_time_to_goal_s"], abs=0.1)


def test_critic_map_of_a_mesh(suite, tmp_path):
    out = tmp_path / "critic.png"
    assert cli.main(["critic-map", "--checkpoint", POLICY, "--mesh", str(suite / "floor.stl"),
                     "--start", "-0.6,0", "--goal", "0.6,0", "--resolution", "0.1",
                     "--out", str(out)]) == 0
    assert out.stat().st_size > 5000


def _tower(path):
    floor = trimesh.creation.box((3, 3, 0.2))
    tower = trimesh.creation.box((0.6, 0.6, 2.0))
    tower.apply_translation((0.8, 0.8, 1.0))
    trimesh.util.concatenate([floor, tower]).export(path)


def _mm(path):
    """A straight staircase exported in millimetres."""
    export_tile(terrains.make_tile("straight", 3, resolution=0.1), path)
    stairs = trimesh.load(path, force="mesh")
    stairs.apply_scale(1000.0)
    stairs.export(path)


@pytest.mark.parametrize("what, flags, message", [
    ("missing", ["--mesh", "{d}/nothere.stl", "--start", "0,0", "--goal", "1,1"],
     "nothere.stl: no such mesh file"),
    ("tower", ["--mesh", "{d}/tower.stl", "--start", "-1,-1", "--goal", "0.8,0.8"],
     "tower.stl: no walkable route"),
    ("tower", ["--mesh", "{d}/tower.stl", "--start", "9,9", "--goal", "0,0"],
     "tower.stl: start (9.0, 9.0) lies outside the mesh footprint"),
    ("mm", ["--mesh", "{d}/mm.stl", "--start", "500,500", "--goal", "1000,1000"],
     "looks like millimetres"),
    ("json", ["--suite", "{d}"], "bad.json: malformed case JSON"),
    ("none", ["--suite", "office"], "unknown suite 'office': not a folder of cases, nor one of "
     "code, paper"),
    ("none", ["--mesh", "x.stl", "--start", "0,0"], "--mesh needs --start"),
    ("none", ["--start", "0,0"], "--start, --goal and --route go with --mesh"),
    ("none", ["--mesh", "x.stl", "--start", "0", "--goal", "1,1"], "--start: expected x,y"),
    ("tower", ["--mesh", "{d}/tower.stl", "--start", "-1,-1", "--goal", "-1,1", "--route",
               "{d}/nothere.csv"], "nothere.csv: no such route file"),
])
def test_bad_inputs_one_line_errors(what, flags, message, tmp_path, capsys):
    {"tower": _tower, "mm": _mm}.get(what, lambda p: None)(tmp_path / f"{what}.stl")
    if what == "json":
        (tmp_path / "bad.json").write_text('{"mesh": "bad.stl", "start": [0, 0]}')
    flags = [f.format(d=tmp_path) for f in flags]
    code = cli.main(["eval", "--checkpoint", POLICY, "--resolution", "0.1", *flags])
    err = [line for line in capsys.readouterr().err.strip().splitlines() if "warp" not in line]
    assert code == 2
    assert len(err) == 1 and err[0].startswith("mjx-stairs eval: error:"), err
    assert message in err[0]


def test_case_record_counts_timeouts_and_time_to_goal():
    """Timeout: neither success nor fall; the time to goal averages the robots that got there."""
    from mjx_stairs.study.cases import case_record

    class T:
        direction = "up"

    s = np.array([1, 1, 0, 0], bool)
    r = case_record("a", T(), s, ~s, np.array([10, 20, -1, -1]), 0.02)
    assert (r["success"], r["fell"], r["timeout"]) == (0.5, 0.5, 0.0)
    assert r["mean_time_to_goal_s"] == pytest.approx(0.3)


def test_cell_records_keep_every_robots_outcome_in_cell_order():
    """cell_records: per cell, one character per robot (s / f / -) whose counts are the cell's
    success and fall rates, cells in row-major order of the [cells * robots] outcomes."""
    from mjx_stairs.study.evaluate import CellSpec, cell_records

    spec = CellSpec(cells=(("straight", "test", 0), ("u_shaped", "test", 5)),
                    robots_per_cell=4)
    success = np.array([1, 0, 0, 1, 0, 0, 0, 1], bool)
    fell = np.array([0, 1, 0, 0, 1, 1, 0, 0], bool)
    r = cell_records(spec, success, fell)
    assert r["outcomes"] == ["sf-s", "ff-s"]
    assert r["success"] == [0.5, 0.25] and r["fell"] == [0.25, 0.5]
    assert [c["level"] for c in r["cells"]] == [1, 6]


def test_eval_direction_down_walks_the_family_from_the_top():
    """eval --direction down: the same tiles, robots spawned on the top landing, goal below."""
    from mjx_stairs.rl.policy import load_policy
    from mjx_stairs.study.evaluate import make_eval_env
    from mjx_stairs.study.specs import EvalSpec

    policy = load_policy(POLICY)
    up, _ = make_eval_env(policy, EvalSpec(levels=(2,), resolution=0.1))
    down, _ = make_eval_env(policy, EvalSpec(levels=(2,), resolution=0.1, direction="down"))
    np.testing.assert_array_equal(down.terrain.heights(), up.terrain.heights())
    spawn, goal = np.asarray(down.tiles.spawn), np.asarray(down.tiles.goal)
    assert (spawn[:, 2] > goal[:, 2] + 1.0).all()
    np.testing.assert_allclose(spawn[:, 2], np.asarray(up.tiles.goal)[:, 2])
