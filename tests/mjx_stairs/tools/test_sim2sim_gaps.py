"""sim2sim_gaps: one policy's MJX evaluations beside its MuJoCo cells, gathered from folders."""

import json

import pytest

from mjx_stairs.tools import sim2sim_gaps

P = "experiments/results/x/policy.npz"


def _cell(root, folder, name, success, episodes=200, policy=P, latency=0.0, sha="aa11",
          direction="up"):
    path = root / folder / "cells" / f"{name}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({
        "cell": name, "episodes": episodes, "success": success, "fell": 1 - success,
        "edge_contacts_per_episode": {"calf": 3.0, "thigh": 0.1, "trunk": 0.0, "hip": 0.0},
        "policy": policy, "robot_sha256": sha, "direction": direction, "latency_ms": latency,
        "contact_timeconst": 0.01, "noise": False, "push": False}))


def _mjx(root, folder, direction, success_u):
    (root / folder).mkdir(parents=True)
    (root / folder / "results.json").write_text(json.dumps([{
        "family": "u_shaped", "schedule": "test", "direction": direction,
        "levels": [1, 2, 3, 4, 5, 6], "success": success_u}]))
    return root / folder


@pytest.fixture()
def tree(tmp_path):
    s2s = tmp_path / "s2s"
    _cell(s2s, "a", "u_shaped_test_L6", 0.90)
    _cell(s2s, "b", "u_shaped_test_L6", 0.50, episodes=100)  # fewer episodes: not kept
    _cell(s2s, "b", "u_shaped_test_L5", 0.99, latency=20.0)  # another setting
    _cell(s2s, "b", "u_shaped_test_L4", 0.10, policy="other/policy.npz")
    _cell(s2s, "c", "u_shaped_test_down_L6", 0.97, direction="down")
    _cell(s2s, "c", "code_commercial_u_left_up", 0.40)
    seeds = [_mjx(tmp_path, "up0", "up", [1, 1, 1, 0.99, 0.98, 0.96]),
             _mjx(tmp_path, "up1", "up", [1, 1, 1, 0.99, 0.98, 0.94]),
             _mjx(tmp_path, "down0", "down", [1, 1, 1, 1, 1, 0.99])]
    code = tmp_path / "code.json"
    code.write_text(json.dumps({"results": [
        {"name": "code_commercial_u_left_up", "direction": "up", "success": 0.45}]}))
    return s2s, seeds, code


def test_each_cell_pairs_the_mean_of_the_mjx_evaluations_with_its_best_mujoco_run(tree):
    s2s, seeds, code = tree
    cells = {c.key: c for c in sim2sim_gaps.gather(P, s2s, seeds, [code])}
    assert len([k for k in cells if k[2]]) == 48  # every paper cell has a row
    u6 = cells[("u_shaped", "up", 6)]
    assert u6.mjx == [0.96, 0.94] and u6.mujoco["episodes"] == 200
    assert u6.gap == pytest.approx(5.0) and len(u6.also) == 1
    assert cells[("u_shaped", "up", 5)].mujoco is None  # only run at 20 ms
    assert cells[("u_shaped", "up", 4)].mujoco is None  # another policy's
    assert cells[("u_shaped", "down", 6)].gap == pytest.approx(2.0)
    assert cells[("code_commercial_u_left_up", "up", 0)].gap == pytest.approx(5.0)
    text = sim2sim_gaps.markdown(list(cells.values()), s2s, "t")
    assert "Paper cells run in both: 2 of 48; within 3 points: 1 of 2; largest gap +5.0" in text
    assert "| u_shaped up L5 | 98.0 / 98.0 | not run |" in text


def test_another_setting_is_gathered_on_its_own(tree):
    s2s, seeds, _ = tree
    cells = {c.key: c for c in sim2sim_gaps.gather(P, s2s, seeds, latency_ms=20.0)}
    assert [k for k, c in cells.items() if c.mujoco] == [("u_shaped", "up", 5)]


def test_cells_from_two_robot_files_are_refused_unless_one_is_named(tree):
    s2s, seeds, _ = tree
    _cell(s2s, "d", "u_shaped_test_L3", 1.0, sha="bb22")
    with pytest.raises(ValueError, match="2 robot files.*--robot-sha"):
        sim2sim_gaps.gather(P, s2s, seeds)
    cells = {c.key: c for c in sim2sim_gaps.gather(P, s2s, seeds, robot_sha="bb")}
    assert [k for k, c in cells.items() if c.mujoco] == [("u_shaped", "up", 3)]


def test_a_broken_cell_file_is_named(tree):
    s2s, seeds, _ = tree
    (s2s / "a" / "cells" / "u_shaped_test_L1.json").write_text("{not json")
    with pytest.raises(ValueError, match="u_shaped_test_L1.json: not a sim2sim cell JSON"):
        sim2sim_gaps.gather(P, s2s, seeds)


def test_the_command_writes_the_table_and_names_a_bad_setting_in_one_line(tree, tmp_path, capsys):
    from mjx_stairs.cli import main

    s2s, seeds, code = tree
    out = tmp_path / "gaps.md"
    args = ["sim2sim-gaps", "--policy", P, "--sim2sim", str(s2s), "--mjx", *map(str, seeds),
            "--mjx-code", str(code), "--out", str(out)]
    assert main(args) == 0
    assert "largest gap +5.0 (u_shaped up L6)" in out.read_text()
    _cell(s2s, "d", "u_shaped_test_L3", 1.0, sha="bb22")
    capsys.readouterr()
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("mjx-stairs sim2sim-gaps: error:") and "\n" not in err
