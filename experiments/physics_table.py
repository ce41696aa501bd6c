"""Issue 22's fidelity table (no GPU): stage-2 policies trained one physics option at a time,
each judged in the evaluation physics on the U-shaped and straight `extended` levels and the
`code` suite (1000 robots per cell), beside the one trained in the evaluation physics itself.

  python experiments/physics_table.py [--baseline stage2_u_evaluation_exit_s0] [--out FILE]

Reads experiments/results/physics_eval/<run>/ (run.sh step eval-physics: u_shaped/, straight/,
code.json) for the runs trained with run.sh step stage2-physics, and, for the two stage-2
policies published before (stage2_u: reference physics; stage2_u_lean: lean physics, both 290
iterations from the same stage-1 policy), the same cells from their evaluation-physics
re-judging: ground_truth/mjx_evaluation_exit/ (the `extended` levels) and
code_suite/evaluation_exit/ (the code suite, 30 s episodes). The training rate is the run's
median env steps/s (run.json). Writes physics_eval/table.md: per run the success per cell, the
largest gap to the baseline and the cells within 2 points.
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
    "stage2_u_columns_n4_s0": "columns_n4 (columns, 4 Newton / 8 ls)",
}


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


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--baseline", default="stage2_u_evaluation_exit_s0")
    ap.add_argument("--out", type=Path, default=R / "physics_eval/table.md")
    args = ap.parse_args(argv)
    runs = {**TRAINED, **PUBLISHED}
    cells = {r: _cells(r) for r in runs}
    base = cells[args.baseline]
    names = list(base)
    lines = ["# Stage 2 trained one physics option at a time, judged in the evaluation physics",
             "", f"Baseline: `{args.baseline}`. Success in % of 1000 robots per cell (U and "
             "straight `extended` levels, 20 s; the `code` suite, 30 s), H100, evaluation "
             "physics. Written by `python experiments/physics_table.py`.", "",
             "| run | training physics | train env steps/s | mean ext | mean code | largest gap "
             "to baseline | cells within 2 |", "|---|---|---|---|---|---|---|"]
    for run, phys in runs.items():
        c = cells[run]
        ext = [c[n] for n in names if " ext " in n]
        code = [c[n] for n in names if " ext " not in n]
        gaps = [c[n] - base[n] for n in names]
        worst = max(gaps, key=abs)
        within = sum(abs(g) <= 2.0 for g in gaps)
        lines.append(f"| `{run}` | {phys} | {_rate(run)} | {sum(ext) / len(ext):.1f} | "
                     f"{sum(code) / len(code):.1f} | {worst:+.1f} | {within} of {len(gaps)} |")
    lines += ["", "| cell | " + " | ".join(f"`{r}`" for r in runs) + " |",
              "|---|" + "---|" * len(runs)]
    lines += [f"| {n} | " + " | ".join(f"{cells[r][n]:.1f}" for r in runs) + " |"
              for n in names]
    args.out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines[:6 + len(runs)]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
