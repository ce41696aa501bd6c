"""experiments/sim2sim_paired.py: episodes matched by start, gained / lost / net / se counted."""

import importlib.util
import json
import math
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("sim2sim_paired",
                                               ROOT / "experiments/sim2sim_paired.py")
sp = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(sp)


def _cell(path, outcomes, cell="code_commercial_u_left_up", shift=0.0):
    recs = [{"start": [0.8 + 0.01 * i + shift, 1.2, 0.1 * i], "success": s}
            for i, s in enumerate(outcomes)]
    path.write_text(json.dumps({"cell": cell, "success": sum(outcomes) / len(outcomes),
                                "records": recs}))
    return path


def test_paired_counts_and_se(tmp_path, capsys):
    a = _cell(tmp_path / "a.json", [True, True, False, True, False])
    b = _cell(tmp_path / "b.json", [True, False, True, False, False])
    _, oa = sp.outcomes(a)
    _, ob = sp.outcomes(b)
    p = sp.paired(oa, ob)
    d = [0, 1, -1, 1, 0]
    sd = math.sqrt(sum((x - 0.2) ** 2 for x in d) / 4)
    assert (p["matched"], p["gained"], p["lost"]) == (5, 2, 1)
    assert p["net"] == pytest.approx(20.0) and p["se"] == pytest.approx(100 * sd / math.sqrt(5))
    sp.main([str(a), str(b)])
    assert "gained 2, lost 1, net +20.0" in capsys.readouterr().out


def test_refuses_other_cells_no_common_start_and_bad_files(tmp_path):
    a = _cell(tmp_path / "a.json", [True, False])
    with pytest.raises(SystemExit, match="runs code_commercial_u_left_up"):
        sp.main([str(a), str(_cell(tmp_path / "c.json", [True, True], cell="other"))])
    with pytest.raises(SystemExit, match="share no start"):
        sp.main([str(a), str(_cell(tmp_path / "d.json", [True, True], shift=5.0))])
    (tmp_path / "e.json").write_text("{")
    with pytest.raises(SystemExit, match="e.json: not a sim2sim cell JSON"):
        sp.main([str(a), str(tmp_path / "e.json")])
