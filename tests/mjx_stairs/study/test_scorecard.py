"""The scorecard's rule driven through its cases: each bar met at its value and missed just
under it, seeds counted apart, both code-suite file layouts, and bad input named."""

import json

import pytest

from mjx_stairs import cli
from mjx_stairs.study import scorecard as sc

FAMILIES = sc.FAMILIES


def _eval_file(path, direction, success, seed=0, robots=1000, schedule="test"):
    """An `mjx-stairs eval` results.json: ``success(family, level)`` per cell."""
    recs = [{"family": f, "schedule": schedule, "direction": direction,
             "levels": [1, 2, 3, 4, 5, 6], "success": [success(f, lv) for lv in range(1, 7)],
             "fell": [0.0] * 6,
             "robots_per_level": robots, "seed": seed} for f in FAMILIES]
    path.mkdir(parents=True, exist_ok=True)
    (path / "results.json").write_text(json.dumps(recs))
    return path


def _code_records(success):
    return [{"name": f"code_{lim}_{shape}_{d}", "direction": d, "robots": 1000,
             "success": success(lim, shape, d), "fell": 0.0}
            for lim in ("commercial", "residential") for shape in ("straight", "u_left")
            for d in ("up", "down")]


def test_bars():
    assert [sc.paper_bar("up", lv) for lv in range(1, 7)] == [0.99] * 5 + [0.97]
    assert {sc.paper_bar("down", lv) for lv in range(1, 7)} == {0.97}
    assert sc.code_bar("code_commercial_u_left_up") == 0.95
    assert sc.code_bar("code_residential_spiral_ccw_down") == 0.85
    with pytest.raises(ValueError, match="not a code-suite case"):
        sc.code_bar("paper_u_shaped_level3_up")


def test_paper_cells_at_and_under_each_bar(tmp_path):
    # up: U L5 exactly at 0.99 (met), U L4 just under (missed), L6 at 0.97 met / 0.969 missed
    up = {("u_shaped", 4): 0.989, ("u_shaped", 5): 0.99, ("u_shaped", 6): 0.97,
          ("spiral", 6): 0.969}
    down = {("l_shaped", 1): 0.97, ("straight", 2): 0.9699}
    _eval_file(tmp_path / "up", "up", lambda f, lv: up.get((f, lv), 1.0))
    _eval_file(tmp_path / "down", "down", lambda f, lv: down.get((f, lv), 1.0))
    cells = sc.paper_cells([tmp_path / "up", tmp_path / "down" / "results.json"])[0]
    assert len(cells) == 48
    missed = sorted(k for k, c in cells.items() if not c.met)
    assert missed == [("spiral", "up", 6), ("straight", "down", 2), ("u_shaped", "up", 4)]
    text = sc.scorecard([tmp_path / "up", tmp_path / "down"], [])
    assert "45 of 48 at the bar" in text and "**98.9**" in text and "fewer than" not in text


def test_seeds_counted_apart_and_twice_refused(tmp_path):
    _eval_file(tmp_path / "s0", "up", lambda f, lv: 1.0, seed=0)
    _eval_file(tmp_path / "s1", "up", lambda f, lv: 0.5 if lv == 1 else 1.0, seed=1, robots=200)
    by_seed = sc.paper_cells([tmp_path / "s0", tmp_path / "s1"])
    assert sorted(by_seed) == [0, 1]
    assert sum(c.met for c in by_seed[0].values()) == 24
    assert sum(c.met for c in by_seed[1].values()) == 20
    text = sc.scorecard([tmp_path / "s0", tmp_path / "s1"], [])
    assert "seed 0: 24 of 48" in text and "seed 1: 20 of 48" in text
    assert "24 cells, as few as 200" in text  # seed 1's cells judged with 200 robots
    with pytest.raises(ValueError, match="given twice"):
        sc.paper_cells([tmp_path / "s0", tmp_path / "s0"])


def test_other_schedules_and_the_pyramid_left_out(tmp_path):
    _eval_file(tmp_path / "ext", "up", lambda f, lv: 1.0, schedule="extended")
    assert sc.paper_cells([tmp_path / "ext"]) == {}


def test_code_suite_both_layouts(tmp_path):
    def success(lim, shape, d):
        return {"commercial": 0.95, "residential": 0.849}[lim] if d == "down" else 0.1
    one = tmp_path / "code_p.json"  # experiments/gpu/code_suite.py: one policy a file
    one.write_text(json.dumps({"policy": "p.npz", "seed": 0, "results": _code_records(success)}))
    (label, _, cells), = sc.code_cells(one)
    assert label == "p.npz" and len(cells) == 8
    assert sorted(c.name for c in cells if c.met) == ["code_commercial_straight_down",
                                                      "code_commercial_u_left_down"]
    many = tmp_path / "suite.json"  # mjx-stairs eval --suite code: a record per checkpoint
    recs = [{"checkpoint": ck, **r} for ck in ("a.npz", "b.npz") for r in _code_records(success)]
    many.write_text(json.dumps({"source": "code", "seed": 3, "results": recs}))
    assert [lab for lab, _, _ in sc.code_cells(many)] == ["a.npz", "b.npz"]
    text = sc.scorecard([], [one])
    assert "2 of 8 cases at the bar, mean 50.0 %" in text
    assert "| residential | down | 84.9 | 0 of 2 |" in text


def test_bad_input_named(tmp_path):
    broken = tmp_path / "broken.json"
    broken.write_text("{not json")
    with pytest.raises(ValueError, match="broken.json: not a JSON file"):
        sc.scorecard([], [broken])
    wrong = tmp_path / "wrong.json"
    wrong.write_text(json.dumps({"results": [{"name": "code_commercial_straight_up"}]}))
    with pytest.raises(ValueError, match="wrong.json: not a code suite JSON"):
        sc.code_cells(wrong)
    with pytest.raises(ValueError, match="nothing to score"):
        sc.scorecard([], [])


def test_cli_writes_the_card_and_names_a_missing_file(tmp_path, capsys):
    _eval_file(tmp_path / "up", "up", lambda f, lv: 1.0)
    out = tmp_path / "card.md"
    assert cli.main(["scorecard", "--eval", str(tmp_path / "up"), "--out", str(out)]) == 0
    assert "24 of 48 at the bar** (24 measured" in out.read_text()
    assert cli.main(["scorecard", "--eval", str(tmp_path / "nowhere")]) == 2
    assert "nowhere" in capsys.readouterr().err
