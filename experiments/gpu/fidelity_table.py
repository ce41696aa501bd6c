"""Fidelity table of issue 19 from experiments/gpu/fidelity.py's output folder.

  python experiments/gpu/fidelity_table.py experiments/results/ground_truth > TABLE.md
"""

from __future__ import annotations

import json
import sys
from pathlib import Path


def main(root: Path) -> None:
    gt = {}
    for f in sorted((root / "gt").glob("gt_*.json")):
        r = json.loads(f.read_text())
        c = r["cells"][0]
        gt[(r["policy"], c["family"], c["schedule"], c["level"])] = r["success"][0]
    mjx = {json.loads(f.read_text())["option"]: json.loads(f.read_text())
           for f in sorted((root / "mjx").glob("mjx_*.json"))}
    options = [o for o in ("reference", "lean", "nearest_full") if o in mjx]
    print("| policy | cell | ground truth (200) | " + " | ".join(
        f"{o} (1000)" for o in options) + " |")
    print("|---|---|---|" + "---|" * len(options))
    worst = {o: 0.0 for o in options}
    for o0 in options[:1]:
        for policy, rec in mjx[o0]["policies"].items():
            for i, c in enumerate(rec["cells"]):
                key = (policy, c["family"], c["schedule"], c["level"])
                g = gt.get(key)
                cells = []
                for o in options:
                    s = mjx[o]["policies"][policy]["success"][i]
                    d = "" if g is None else f" ({100 * (s - g):+.1f})"
                    if g is not None:
                        worst[o] = max(worst[o], abs(s - g))
                    cells.append(f"{100 * s:.1f}{d}")
                gs = "–" if g is None else f"{100 * g:.1f}"
                name = f"{c['family']} {c['schedule']} L{c['level']}"
                print(f"| {policy} | {name} | {gs} | " + " | ".join(cells) + " |")
    print()
    print("Largest |MJX - ground truth| per option (points): " + ", ".join(
        f"{o} {100 * w:.1f}" for o, w in worst.items()))


if __name__ == "__main__":
    main(Path(sys.argv[1]))
