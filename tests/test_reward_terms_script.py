"""experiments/reward_terms.py: each term's mean per second over the robots' running steps, per
case, from [T, B] records whose columns hold the cases' robots in order."""

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "experiments"))  # the script imports its neighbour
spec = importlib.util.spec_from_file_location("reward_terms", ROOT / "experiments/reward_terms.py")
reward_terms = importlib.util.module_from_spec(spec)
spec.loader.exec_module(reward_terms)


def test_a_terms_per_second_counts_the_running_steps_of_each_case_alone():
    # 2 cases x 2 robots, 4 steps of 0.02 s; case a's robot 1 ended after 2 steps, its frozen
    # values after that (9.0) must not count; case b's robots run all 4
    running = np.array([[1, 1, 1, 1], [1, 1, 1, 1], [1, 0, 1, 1], [1, 0, 1, 1]], bool)
    stall = np.array([[-0.01, -0.02, 0.0, 0.0], [-0.01, -0.02, 0.0, 0.0],
                      [-0.01, 9.0, 0.0, -0.04], [-0.01, 9.0, 0.0, -0.04]])
    rec = {"running": running, "reward/stall": stall, "level": np.zeros((4, 4))}
    rows = reward_terms.per_second(rec, robots=2, dt=0.02, names=["a", "b"])
    assert [r["case"] for r in rows] == ["a", "b"]
    assert rows[0]["robot_seconds"] == pytest.approx(6 * 0.02)
    assert rows[0]["per_second"] == {"stall": pytest.approx((-0.04 - 0.04) / 0.12)}
    assert rows[1]["per_second"]["stall"] == pytest.approx(-0.08 / 0.16)
