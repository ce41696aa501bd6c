"""experiments/sim2sim_causes.py's cells: a family's test levels (up<level>/down<level>) or the
`code` suite's cases by name, a bad one refused before anything runs."""

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
spec = importlib.util.spec_from_file_location("sim2sim_causes",
                                              ROOT / "experiments/sim2sim_causes.py")
causes = importlib.util.module_from_spec(spec)
spec.loader.exec_module(causes)


def test_family_cells_are_direction_and_level():
    assert causes.parse_cell("up6") == ("up", 6)
    assert causes.parse_cell("down1") == ("down", 1)
    for bad in ("up", "sideways3", "up6b"):
        with pytest.raises(SystemExit, match=bad):
            causes.check_cell("u_shaped", bad)


def test_code_cells_are_the_suites_cases():
    case = causes.code_case("commercial_straight_up")
    assert (case.name, case.direction) == ("code_commercial_straight_up", "up")
    assert case.staircase.riser == pytest.approx(0.178)
    causes.check_cell("code", "residential_winder_left_down")
    with pytest.raises(SystemExit, match="commercial_ramp_up"):
        causes.check_cell("code", "commercial_ramp_up")
    with pytest.raises(SystemExit, match="up6"):  # a family cell is not a code case
        causes.check_cell("code", "up6")
