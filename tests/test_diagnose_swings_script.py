"""experiments/diagnose_cases.py's swings: how high each foot rose between lift-off and
touch-down, read from a foot-height and contact series, and the share that cleared a riser."""

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "experiments"))  # the script imports its neighbour
spec = importlib.util.spec_from_file_location("diagnose_cases",
                                              ROOT / "experiments/diagnose_cases.py")
diagnose = importlib.util.module_from_spec(spec)
spec.loader.exec_module(diagnose)


def test_a_swing_rises_from_its_lift_off_height():
    # foot 0: on the floor, a swing up onto a 0.2 m step, a shuffle of 2 cm there, then a swing
    # still open at the end; foot 1 never lifts
    z = np.array([0.02, 0.02, 0.10, 0.30, 0.25, 0.22, 0.22, 0.24, 0.22, 0.30, 0.35])
    touching = np.array([1, 1, 0, 0, 0, 1, 1, 0, 1, 0, 0], bool)
    rises = diagnose.swing_rises(np.stack([z, np.full(11, 0.02)], 1),
                                 np.stack([touching, np.ones(11, bool)], 1))
    assert rises[0] == pytest.approx([0.28, 0.02, 0.13])
    assert rises[1] == []
    s = diagnose.swing_summary(rises, riser=0.197)
    assert s["swings"] == [3, 0]
    assert s["swings_over_riser"] == [pytest.approx(1 / 3, abs=1e-3), None]
    assert s["swing_rise_m"][0] == [0.13, 0.28] and s["swing_rise_m"][1] is None
