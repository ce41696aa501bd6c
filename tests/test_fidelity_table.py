"""experiments/gpu/fidelity_table.py's noise reading: the 95 % interval of a difference of two
success rates, which says whether a gap to the ground truth is beyond sampling noise."""

from __future__ import annotations

import importlib.util
import math
import random
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
spec = importlib.util.spec_from_file_location("fidelity_table",
                                              ROOT / "experiments/gpu/fidelity_table.py")
fidelity_table = importlib.util.module_from_spec(spec)
spec.loader.exec_module(fidelity_table)


def test_the_gap_interval_is_the_two_samples_noise():
    # near 50 %, 1000 a side: 1.96 * sqrt(2 * 0.25 / 1002) ~ 4.4 points, wider than a 3-point bar
    assert math.isclose(fidelity_table.gap_interval(0.5, 1000, 0.5, 1000), 4.38, abs_tol=0.01)
    # 200 of 200 is not read as certain: a 0.7-point gap to 99.3 % is inside the interval
    assert fidelity_table.gap_interval(1.0, 200, 0.993, 1000) > 0.7


def test_the_gap_interval_covers_95_percent_of_equal_rates():
    rng, p, n, misses = random.Random(0), 0.45, 1000, 0
    for _ in range(400):
        a = sum(rng.random() < p for _ in range(n)) / n
        b = sum(rng.random() < p for _ in range(n)) / n
        misses += 100 * abs(a - b) > fidelity_table.gap_interval(a, n, b, n)
    assert 4 <= misses <= 40  # about 5 % of 400


def _write(path: Path, record: dict) -> None:
    import json

    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(record))


def test_the_stiff_table_judges_each_contact_against_its_own_ground_truth(tmp_path, capsys):
    cells = [{"family": "u_shaped", "schedule": "test", "level": 6},
             {"family": "straight", "schedule": "extended", "level": 5}]
    for folder, rates in (("mjx_evaluation_exit", [0.99, 0.37]),
                          ("mjx_evaluation_stiff", [0.98, 0.50])):
        _write(tmp_path / folder / f"{folder}.json", {"option": folder[4:], "policies": {
            "stage2_u": {"cells": cells, "success": rates, "robots_per_cell": 1000}}})
    for folder, cell, rate in (("gt_supported", 0, 1.0), ("gt_supported", 1, 0.395),
                               ("gt_supported_stiff", 0, 0.97),
                               ("gt_supported_stiff1000", 1, 0.43)):
        _write(tmp_path / folder / f"gt_{cell}.json", {
            "policy": "stage2_u", "cells": [cells[cell]], "success": [rate],
            "robots_per_cell": 1000 if folder.endswith("1000") else 200})
    fidelity_table.stiff_table(tmp_path)
    out = capsys.readouterr().out
    assert "| stage2_u | straight extended L5 | 39.5 ±6.8 (200) | 37.0 (-2.5) | " \
           "43.0 ±3.1 (1000) | 50.0 (+7.0) |" in out
    assert "0.02 s: 2.5 points (2 of 2 cells within 3), 0.01 s: 7.0 points (1 of 2" in out


def test_every_physics_option_is_a_valid_env_config():
    """experiments/gpu/fidelity.py's physics options (run.sh's bench-options and stage2-physics
    train with them) each name real robot keys with valid values: a typo fails here, not on a
    lent GPU."""
    from mjx_stairs.env.config import env_config_from

    spec = importlib.util.spec_from_file_location("fidelity", ROOT / "experiments/gpu/fidelity.py")
    fidelity = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(fidelity)
    for name, overrides in fidelity.OPTIONS.items():
        robot = env_config_from(None, overrides).robot
        for item in overrides:  # each robot field is what the option says (after its preset)
            key, value = item.split("=", 1)
            if key.startswith("robot.") and key != "robot.physics":
                got = str(getattr(robot, key.removeprefix("robot."))).lower()
                assert got == value.lower() or float(got) == float(value), (name, item, got)
    limbs = env_config_from(None, fidelity.OPTIONS["evaluation_stiff_limbs"]).robot
    assert limbs.limb_capsules and limbs.thigh_collision and limbs.solver_iterations == 8
