"""`make bench`'s summary (issue 22): the physics-only and full-training rates of each bench file
side by side, and the time to a trained climber as a row.

  python experiments/bench_table.py runs/bench/lean.json runs/bench/evaluation.json
      [--climber experiments/results/time_to_climber/time_to_climber.json]

Each FILE is `mjx-stairs bench --out FILE`'s record; the row's name is the file's stem. The
climber row is `experiments/gpu/time_to_climber.py`'s record (wall time from nothing to a
stage-2 policy, compile included, and its U-shaped test levels).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def rows(path: Path) -> list[str]:
    rec = json.loads(path.read_text())
    out = []
    for r in rec["results"]:
        phys = r.get("physics", {}).get("steps_per_s")
        train = r.get("train", {}).get("steps_per_s")
        ratio = f"{train / phys:.2f}" if phys and train else "-"
        out.append(f"| {path.stem} | {r['robots']} | {phys / 1e3 if phys else 0:.0f} k | "
                   f"{train / 1e3 if train else 0:.0f} k | {ratio} | {rec['device']} |")
    return out


def climber_row(path: Path) -> str:
    rec = json.loads(path.read_text())
    success = " / ".join(f"{100 * s:.1f}" for s in rec["success"])
    return (f"Time to a trained climber: {rec['time_to_climber_s']:.0f} s "
            f"({rec['time_to_climber_s'] / 60:.1f} min, compile included; stage 1 "
            f"{rec['wall_s']['stage1']:.0f} s + stage 2 {rec['wall_s']['stage2']:.0f} s) on "
            f"{rec['train']['stage1']['device']}; U-shaped test levels {success} % "
            f"({path})")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("files", nargs="+", type=Path)
    ap.add_argument("--climber", type=Path)
    a = ap.parse_args(argv)
    missing = [str(p) for p in a.files + ([a.climber] if a.climber else []) if not p.exists()]
    if missing:
        sys.exit(f"bench_table: no such file: {', '.join(missing)}")
    lines = ["| setting | robots | physics only | full training | training / physics | device |",
             "|---|---|---|---|---|---|"]
    for p in a.files:
        lines += rows(p)
    if a.climber:
        lines += ["", climber_row(a.climber)]
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
