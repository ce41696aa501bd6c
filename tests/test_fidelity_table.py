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
