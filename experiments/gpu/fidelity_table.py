"""Fidelity table of issue 19 from experiments/gpu/fidelity.py's output folders.

  python experiments/gpu/fidelity_table.py experiments/results/ground_truth [--before] > TABLE.md
  python experiments/gpu/fidelity_table.py experiments/results/ground_truth --stiff > STIFF.md

Ground truth: gt_supported/ (the box staircase with a support under every box's top, d08b354:
no foot is held sunk in a seam between boxes; 200 episodes per cell), gt_supported1000/ (1000,
the MJX evaluation's own starts) where present. --before: the box
staircase before it, gt1000/ (1000 episodes per cell) where present, else gt/ (200). MJX:
mjx_<option>.json in the options' folders under the root (1000 robots per cell, 2.5 cm grid;
issue 22's candidates in mjx_columns_*/), one column each.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

ORDER = ("reference", "lean", "nearest_full", "mjx_converged", "columns", "columns_converged",
         "columns_converged_x64", "evaluation", "evaluation_exit")
"""Column order; options not named here (issue 22's candidates) follow in name order."""


def interval(p: float, n: int) -> float:
    """Half-width of the 95 % interval of a success rate p over n episodes, in points."""
    return 100 * 1.96 * math.sqrt(max(p * (1 - p), 1e-4) / n)


def gap_interval(g: float, n: int, s: float, m: int) -> float:
    """Half-width of the unpaired 95 % interval of the difference of two success rates (g over
    n episodes, s over m), in points, Agresti-Caffo (one success and one failure added to each
    sample, so that 200 of 200 is not read as certain). The ground truth runs the MJX
    evaluation's own starts, but its files keep rates, not per-robot outcomes, so the paired
    (tighter) test cannot be made from them."""
    var = 0.0
    for rate, k in ((g, n), (s, m)):
        q = (rate * k + 1) / (k + 2)
        var += q * (1 - q) / (k + 2)
    return 100 * 1.96 * math.sqrt(var)


def _ground_truth(root: Path, before: bool = False, folders: tuple[str, ...] = ()) -> dict:
    gt = {}
    folders = folders or (("gt", "gt1000") if before else ("gt_supported", "gt_supported1000"))
    for folder in folders:
        # the later folder (more episodes) wins
        for f in sorted((root / folder).glob("gt_*.json")):
            r = json.loads(f.read_text())
            c = r["cells"][0]
            gt[(r["policy"], c["family"], c["schedule"], c["level"])] = (
                r["success"][0], r["robots_per_cell"])
    return gt


def main(root: Path, before: bool = False) -> None:
    gt = _ground_truth(root, before)
    mjx = {}
    folders = ["mjx", "mjx_converged", "mjx_columns", "mjx_x64", "mjx_eval", "mjx_evaluation_exit"]
    folders += sorted(p.name for p in root.glob("mjx_columns_*"))  # issue 22's candidates
    for folder in folders:  # not mjx_res0125/ (another grid)
        for f in sorted((root / folder).glob("mjx_*.json")):
            r = json.loads(f.read_text())
            mjx[r["option"]] = r
    options = [o for o in ORDER if o in mjx] + sorted(o for o in mjx if o not in ORDER)
    print("| policy | cell | ground truth (n) | " + " | ".join(options) + " |")
    print("|---|---|---|" + "---|" * len(options))
    worst = {o: (0.0, 0) for o in options}
    within = {o: 0 for o in options}  # cells within 3 points of the ground truth
    beyond = {o: 0 for o in options}  # cells whose gap is beyond sampling noise (unpaired)
    for policy, rec in mjx["reference"]["policies"].items():
        for c in rec["cells"]:
            key = (policy, c["family"], c["schedule"], c["level"])
            g, n = gt.get(key, (None, 0))
            cells = []
            for o in options:
                recs = mjx[o]["policies"][policy]
                found = [j for j, cc in enumerate(recs["cells"]) if cc == c]
                if not found:
                    cells.append("")
                    continue
                s = recs["success"][found[0]]
                cells.append(f"{100 * s:.1f}" + ("" if g is None else f" ({100 * (s - g):+.1f})"))
                if g is not None and abs(s - g) > worst[o][0]:
                    worst[o] = (abs(s - g), worst[o][1])
                if g is not None:
                    worst[o] = (worst[o][0], worst[o][1] + 1)
                    within[o] += abs(s - g) <= 0.03 + 1e-9
                    beyond[o] += abs(s - g) > gap_interval(g, n, s, recs["robots_per_cell"]) / 100
            se = "" if g is None else f" ±{interval(g, n):.1f}"
            gs = "–" if g is None else f"{100 * g:.1f}{se} ({n})"
            name = f"{c['family']} {c['schedule']} L{c['level']}"
            print(f"| {policy} | {name} | {gs} | " + " | ".join(cells) + " |")
    print()
    print("MJX: 1000 robots per cell; ground truth ± is its 95 % interval. Largest "
          "|MJX - ground truth| per option (points, over the cells it was measured on): "
          + ", ".join(f"{o} {100 * w:.1f} ({within[o]} of {k} cells within 3)"
                      for o, (w, k) in worst.items()))
    print()
    print("Cells whose gap lies beyond the unpaired 95 % interval of the difference (both "
          "samples' noise; at 1000 + 1000 episodes and a rate near 50 % that interval is about "
          "±4.4 points, wider than the 3-point bar): "
          + ", ".join(f"{o} {beyond[o]} of {k}" for o, (_, k) in worst.items()))


def stiff_table(root: Path) -> None:
    """Long: the evaluation physics at both contacts, each against the ground truth at its own:
    go2.xml's solref time constant 0.02 s (evaluation_exit against gt_supported[1000]/) and 0.01
    s in both simulators (evaluation_stiff against gt_supported_stiff[1000]/, fidelity.py gt
    --timeconst 0.01), on the cells measured at 0.01."""
    pairs = (("0.02", "mjx_evaluation_exit", ("gt_supported", "gt_supported1000")),
             ("0.01", "mjx_evaluation_stiff", ("gt_supported_stiff", "gt_supported_stiff1000")))
    cols = []
    for label, folder, gt_folders in pairs:
        rec = json.loads(next((root / folder).glob("mjx_*.json")).read_text())["policies"]
        cols.append((label, rec, _ground_truth(root, folders=gt_folders)))
    print("| policy | cell | " + " | ".join(f"ground truth {t} (n) | MJX {t} (gap)"
                                           for t, _, _ in cols) + " |")
    print("|---|---|" + "---|---|" * len(cols))
    worst = {t: [0.0, 0, 0] for t, _, _ in cols}  # largest gap, cells, cells within 3
    for policy, rec in cols[-1][1].items():
        for c in rec["cells"]:
            key = (policy, c["family"], c["schedule"], c["level"])
            row = []
            for t, mjx, gt in cols:
                recs = mjx[policy]
                s = recs["success"][recs["cells"].index(c)]
                g, n = gt.get(key, (None, 0))
                if g is None:
                    row += ["–", f"{100 * s:.1f}"]
                    continue
                row += [f"{100 * g:.1f} ±{interval(g, n):.1f} ({n})", f"{100 * s:.1f} "
                        f"({100 * (s - g):+.1f})"]
                w = worst[t]
                w[0], w[1], w[2] = max(w[0], abs(s - g)), w[1] + 1, w[2] + (abs(s - g) <= 0.03)
            name = f"{c['family']} {c['schedule']} L{c['level']}"
            print(f"| {policy} | {name} | " + " | ".join(row) + " |")
    print()
    print("MJX: 1000 robots per cell. Largest |MJX - ground truth| at each contact: "
          + ", ".join(f"{t} s: {100 * w:.1f} points ({k3} of {k} cells within 3)"
                      for t, (w, k, k3) in worst.items()))


if __name__ == "__main__":
    if "--stiff" in sys.argv[2:]:
        stiff_table(Path(sys.argv[1]))
    else:
        main(Path(sys.argv[1]), before="--before" in sys.argv[2:])
