"""Issue 22's fidelity table (no GPU): stage-2 policies trained one physics option at a time,
each judged in the evaluation physics on the U-shaped and straight `extended` levels and the
`code` suite (1000 robots per cell), beside the one trained in the evaluation physics itself.

  python experiments/physics_table.py [--baseline RUN [RUN ...]] [--out FILE]

Reads experiments/results/physics_eval/<run>/ (run.sh step eval-physics: u_shaped/, straight/,
code.json) for the runs trained with run.sh step stage2-physics, and, for the two stage-2
policies published before (stage2_u: reference physics; stage2_u_lean: lean physics, both 290
iterations from the same stage-1 policy), the same cells from their evaluation-physics
re-judging: ground_truth/mjx_evaluation_exit/ (the `extended` levels) and
code_suite/evaluation_exit/ (the code suite, 30 s episodes). The training rate is the run's
median env steps/s (run.json). Writes physics_eval/table.md: per run the success per cell, the
largest gap to each baseline (by default the two seeds trained in the evaluation physics) and,
with several baselines, to their per-cell mean, and the cells within 2 points of each.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

R = Path("experiments/results")
EXT = ("u_shaped", "straight")
PUBLISHED = {  # run -> (training physics, where its evaluation-physics cells are)
    "stage2_u": "reference (MJX collider, shins, ls 5)",
    "stage2_u_lean": "lean (nearest-point, no shins, ls 3)",
}
TRAINED = {
    "stage2_u_evaluation_exit_s0": "evaluation (columns, 8 Newton / 10 ls)",
    "stage2_u_evaluation_exit_s1": "evaluation (columns, 8 Newton / 10 ls), seed 1",
    "stage2_u_columns_n4_s0": "columns_n4 (columns, 4 Newton / 8 ls)",
    "stage2_u_lean_s1": "lean (nearest-point, no shins, ls 3), seed 1",
    "stage2_u_nearest_full_s0": "nearest_full (nearest-point, shins, 1 Newton / ls 5)",
    "stage2_u_nearest_full_s1": "nearest_full (nearest-point, shins, 1 Newton / ls 5), seed 1",
}
BASELINES = ["stage2_u_evaluation_exit_s0", "stage2_u_evaluation_exit_s1"]


def _cells(run: str) -> dict[str, float]:
    """{cell name: success %} of a run: U and straight extended L1-6, the 24 code cases."""
    out: dict[str, float] = {}
    if run in PUBLISHED:
        fid = json.loads((R / "ground_truth/mjx_evaluation_exit/mjx_evaluation_exit.json")
                         .read_text())["policies"][run]
        for c, s in zip(fid["cells"], fid["success"], strict=True):
            if c["schedule"] == "extended":
                out[f"{c['family']} ext L{c['level']}"] = 100 * s
        code = json.loads((R / f"code_suite/evaluation_exit/code_{run}.json").read_text())
    else:
        d = R / "physics_eval" / run
        for fam in EXT:
            (rec,) = json.loads((d / fam / "results.json").read_text())
            for lv, s in zip(rec["levels"], rec["success"], strict=True):
                out[f"{fam} ext L{lv}"] = 100 * s
        code = json.loads((d / "code.json").read_text())
    for r in code["results"]:
        out[r["name"].removeprefix("code_")] = 100 * r["success"]
    return out


def _rate(run: str) -> str:
    facts = json.loads((R / run / "run.json").read_text())
    return f"{facts['steps_per_s_median'] / 1e3:.0f} k"


def _row(label: str, c: dict[str, float], bases: dict[str, dict[str, float]]) -> str:
    """A summary row: the cells' means and, per baseline, their largest signed gap to the
    baseline's cells and how many lie within 2 points of them."""
    ext = [v for n, v in c.items() if " ext " in n]
    code = [v for n, v in c.items() if " ext " not in n]
    out = f"{label} | {sum(ext) / len(ext):.1f} | {sum(code) / len(code):.1f}"
    for base in bases.values():
        gaps = [c[n] - base[n] for n in base]
        within = sum(abs(g) <= 2.0 for g in gaps)
        out += f" | {max(gaps, key=abs):+.1f} | {within} of {len(gaps)}"
    return out + " |"


def _spread_rows(cells: dict[str, dict[str, float]], seeds: list[str]) -> list[str]:
    """Per run, its cells inside the seeds' per-cell range widened by 2 points, and how many lie
    below or above it: with seeds that differ by tens of points on half the cells, a gap beyond
    their own spread is what two seeds can show (docs/results.md 5c)."""
    names = list(cells[seeds[0]])
    lo = {n: min(cells[b][n] for b in seeds) - 2.0 for n in names}
    hi = {n: max(cells[b][n] for b in seeds) + 2.0 for n in names}
    rows = ["", f"Cells inside the range of {', '.join(f'`{b}`' for b in seeds)} widened by 2 "
            "points:", "", "| run | inside | below | above |", "|---|---|---|---|"]
    for run, c in cells.items():
        below = [n for n in names if c[n] < lo[n]]
        above = [n for n in names if c[n] > hi[n]]
        rows.append(f"| `{run}` | {len(names) - len(below) - len(above)} of {len(names)} | "
                    f"{len(below)} | {len(above)} |")
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--baseline", nargs="+", default=BASELINES)
    ap.add_argument("--out", type=Path, default=R / "physics_eval/table.md")
    args = ap.parse_args(argv)
    runs = {**TRAINED, **PUBLISHED}
    cells = {r: _cells(r) for r in runs}
    bases = {f"`{b}`": cells[b] for b in args.baseline}
    names = list(cells[args.baseline[0]])
    if len(bases) > 1:
        bases["their mean"] = {n: sum(b[n] for b in bases.values()) / len(bases) for n in names}
    lines = ["# Stage 2 trained one physics option at a time, judged in the evaluation physics",
             "", f"Baselines: {', '.join(bases)}. Success in % of 1000 robots per cell (U and "
             "straight `extended` levels, 20 s; the `code` suite, 30 s), H100, evaluation "
             "physics. Written by `python experiments/physics_table.py`.", "",
             "| run | training physics | train env steps/s | mean ext | mean code | "
             + " | ".join(f"largest gap to {b} | cells within 2" for b in bases) + " |",
             "|---|---|---|---|---|" + "---|---|" * len(bases)]
    lines += [_row(f"| `{r}` | {phys} | {_rate(r)}", cells[r], bases) for r, phys in runs.items()]
    if "their mean" in bases:  # the baselines' per-cell mean as a row of its own
        lines.append(_row("| their mean (baselines) | | ", bases["their mean"], bases))
        lines += _spread_rows(cells, args.baseline)
    lines += ["", "| cell | " + " | ".join(f"`{r}`" for r in runs) + " |",
              "|---|" + "---|" * len(runs)]
    lines += [f"| {n} | " + " | ".join(f"{cells[r][n]:.1f}" for r in runs) + " |"
              for n in names]
    args.out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines[:lines.index("", 4)]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
