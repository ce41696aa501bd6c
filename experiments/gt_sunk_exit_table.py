"""Issue 19: the columns collider's sunk rule at 1000 robots, MJX on the 2-core CPU, against the
ground truth and the published evaluation physics (GPU). Reads the records that
`experiments/gt_sunk_exit.py RULE 1000 CELL POLICY` printed (one JSON object per line) and prints
a markdown table.

Usage: python experiments/gt_sunk_exit_table.py experiments/results/ground_truth \
    experiments/results/ground_truth/sunk_exit/*.jsonl
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent / "gpu"))


def main(root: Path, files: list[Path]) -> None:
    from fidelity_table import _ground_truth, interval

    gt = _ground_truth(root)
    published = json.loads((root / "mjx_eval" / "mjx_evaluation.json").read_text())["policies"]
    rows = {}
    for f in files:
        for line in f.read_text().splitlines():
            if line.startswith("{"):
                r = json.loads(line)
                family, schedule, level = r["cell"]  # 0-based level, as fidelity.CELLS
                rows[(r["policy"], family, schedule, level + 1, r["rule"])] = (
                    r["success"][0], r["robots"])
    cells = sorted({k[:4] for k in rows})
    print("| policy | cell | ground truth (n) | evaluation, GPU (`top`, published) "
          "| MJX CPU `top` | MJX CPU `nearest` |")
    print("|---|---|---|---|---|---|")
    for policy, family, schedule, level in cells:
        g, n = gt[(policy, family, schedule, level)]
        rec = published[policy]
        j = rec["cells"].index(dict(family=family, schedule=schedule, level=level))
        pub = rec["success"][j]
        cols = [f"{100 * pub:.1f} ({100 * (pub - g):+.1f})"]
        for rule in ("top", "nearest"):
            s = rows.get((policy, family, schedule, level, rule))
            cols.append("" if s is None else
                        f"{100 * s[0]:.1f} ({100 * (s[0] - g):+.1f}, n {s[1]})")
        name = f"{family} {schedule} L{level}"  # 1-based, as the fidelity table
        print(f"| {policy} | {name} | {100 * g:.1f} ±{interval(g, n):.1f} ({n}) | "
              + " | ".join(cols) + " |")


if __name__ == "__main__":
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    main(Path(sys.argv[1]), [Path(p) for p in sys.argv[2:]])
