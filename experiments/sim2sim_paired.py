"""Two sim2sim runs of one cell on the same starts, compared episode by episode.

    python experiments/sim2sim_paired.py A.json B.json [B2.json ...]

A, B: cell JSONs that experiments/gpu/sim2sim_table.py wrote (`<out>/cells/<cell>.json`, one
record per episode with its start). Episodes are matched by start (x, y, yaw to 1 mm / 1 mrad);
prints, for each B, A's and B's success, the starts A gains and loses against B, the net change
in points and its standard error (sd of the per-start difference / sqrt(n)). Runs of different
cells, or with no start in common, are refused.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path


def outcomes(path: str | Path) -> tuple[dict, dict[tuple, bool]]:
    """The cell JSON and {start rounded: succeeded}."""
    try:
        data = json.loads(Path(path).read_text())
        starts = {tuple(round(float(x), 3) for x in r["start"]): bool(r["success"])
                  for r in data["records"]}
    except (OSError, json.JSONDecodeError, KeyError, TypeError) as e:
        raise SystemExit(f"sim2sim_paired: {path}: not a sim2sim cell JSON ({e})") from e
    return data, starts


def paired(a: dict[tuple, bool], b: dict[tuple, bool]) -> dict:
    """Gained / lost / net (points) / se over the starts both ran."""
    keys = [k for k in a if k in b]
    if not keys:
        raise SystemExit("sim2sim_paired: the two runs share no start")
    d = [int(a[k]) - int(b[k]) for k in keys]
    n = len(d)
    mean = sum(d) / n
    var = sum((x - mean) ** 2 for x in d) / max(n - 1, 1)
    return {"matched": n, "gained": d.count(1), "lost": d.count(-1), "net": 100 * mean,
            "se": 100 * math.sqrt(var / n)}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("a")
    ap.add_argument("b", nargs="+")
    args = ap.parse_args(argv)
    da, a = outcomes(args.a)
    for path in args.b:
        db, b = outcomes(path)
        if da.get("cell") != db.get("cell"):
            raise SystemExit(f"sim2sim_paired: {args.a} runs {da.get('cell')}, {path} "
                             f"{db.get('cell')}")
        p = paired(a, b)
        print(f"{da['cell']}: A {100 * da['success']:.1f} against {path} {100 * db['success']:.1f}"
              f" on {p['matched']} starts: gained {p['gained']}, lost {p['lost']}, net "
              f"{p['net']:+.1f} (se {p['se']:.1f})")


if __name__ == "__main__":
    main()
