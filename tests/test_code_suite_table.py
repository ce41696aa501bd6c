"""experiments/gpu/code_suite.py's table: the offset step's re-measure is what the U level 3 row
shows, not the mesh step's older offset cases."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
spec = importlib.util.spec_from_file_location("code_suite", ROOT / "experiments/gpu/code_suite.py")
code_suite = importlib.util.module_from_spec(spec)
spec.loader.exec_module(code_suite)


def _cases(path: Path, **success: float) -> None:
    path.write_text(json.dumps({"results": [{"name": k, "success": v, "fell": 1 - v}
                                            for k, v in success.items()]}))


def test_the_offset_columns_come_from_the_offset_step_where_it_ran(tmp_path):
    for name in ("a", "b"):
        (tmp_path / f"u3_family_{name}.json").write_text(
            json.dumps({"result": {"success": [0.99]}}))
        _cases(tmp_path / f"u3_mesh_{name}.json", u3=0.98, u3_offset_left=0.10,
               u3_offset_right=0.90)
    _cases(tmp_path / "u3_offset_b.json", u3_offset_left=0.784, u3_offset_right=0.968)
    rows = {line.split("|")[1].strip(): line for line in code_suite.mesh_table(tmp_path, {})
            if line.startswith("| a ") or line.startswith("| b ")}
    assert rows["a"] == "| a | 99.0 | 98.0 | - | 10.0 | 90.0 |"  # mesh step's, no re-measure
    assert rows["b"] == "| b | 99.0 | 98.0 | - | 78.4 | 96.8 |"


def test_only_the_policies_of_the_chosen_steps_must_exist(tmp_path, monkeypatch):
    """A default --policies entry whose file is missing stops a suite step, not an offset or
    table step (a call that moved a results folder out of the tree ran no offset step for it)."""
    monkeypatch.setitem(code_suite.POLICIES, "gone", tmp_path / "gone.npz")
    run = [__file__, str(tmp_path / "out"), "--policies", "gone", "--mesh-policies", "gone"]
    monkeypatch.setattr("sys.argv", [*run, "--steps", "table"])
    code_suite.main()  # nothing to check: no suite, mesh or offset step
    for steps in ("suite", "offset"):
        monkeypatch.setattr("sys.argv", [*run, "--steps", steps])
        with pytest.raises(SystemExit) as e:
            code_suite.main()
        # one line naming the policy and the file it looked for
        assert str(e.value) == f"code_suite: no policy file for gone ({tmp_path / 'gone.npz'})"


def test_a_policy_is_named_by_file_by_committed_name_or_by_its_results_folder(tmp_path):
    known = dict(code_suite.POLICIES)
    try:
        names = code_suite.policy_names(f"stage2_u,mine={tmp_path / 'p.npz'},generalist_d2,nowhere")
        assert names == ["stage2_u", "mine", "generalist_d2", "nowhere"]
        assert code_suite.POLICIES["stage2_u"] == known["stage2_u"]
        assert code_suite.POLICIES["mine"] == tmp_path / "p.npz"
        # a published run folder: found without NAME=FILE (its policy is committed)
        assert code_suite.POLICIES["generalist_d2"].exists()
        assert not code_suite.POLICIES["nowhere"].exists()  # main names it as missing
    finally:
        code_suite.POLICIES.clear()
        code_suite.POLICIES.update(known)
