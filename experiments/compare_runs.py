"""Do two runs of the same training (e.g. one process with two GPUs, two processes with one each)
log the same metrics? Compares their metrics.jsonl chunk by chunk and their throughput.

    python experiments/compare_runs.py RUN_A RUN_B [--rtol 1e-3] [--atol 1e-5] [--out FILE]

RUN_A, RUN_B: run directories or metrics.jsonl files. Timings (wall_time, perf/*) are not
compared; each run's median training rate (perf/steps_per_s, first chunk left out) is reported.
Prints one line per metric outside the tolerance and a verdict; exit status 1 when they differ.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from mjx_stairs import atomic
from mjx_stairs.rl.logger import read_jsonl

TIMINGS = ("wall_time", "perf/")


def _rows(path: str) -> list[dict]:
    p = Path(path)
    return read_jsonl(p / "metrics.jsonl" if p.is_dir() else p)


def _rate(rows: list[dict]) -> float | None:
    rates = sorted(r["perf/steps_per_s"] for r in (rows[1:] or rows) if "perf/steps_per_s" in r)
    return rates[len(rates) // 2] if rates else None


def compare(a: list[dict], b: list[dict], rtol: float, atol: float) -> dict:
    """Per metric: the largest |a - b| and |a - b| / |b| over the chunks both logged, and the
    metrics outside ``atol + rtol * |b|``."""
    by_it = {r["iteration"]: r for r in b}
    worst: dict[str, dict[str, float]] = {}
    outside = set()
    for ra in a:
        rb = by_it.get(ra["iteration"])
        if rb is None:
            continue
        for k, va in ra.items():
            vb = rb.get(k)
            if k.startswith(TIMINGS) or not isinstance(va, (int, float)) or vb is None:
                continue
            diff = abs(va - vb)
            w = worst.setdefault(k, {"abs": 0.0, "rel": 0.0})
            w["abs"] = max(w["abs"], diff)
            w["rel"] = max(w["rel"], diff / max(abs(vb), 1e-12))
            if diff > atol + rtol * abs(vb):
                outside.add(k)
    common = sorted(set(r["iteration"] for r in a) & set(by_it))
    return {"iterations": common, "rtol": rtol, "atol": atol, "outside": sorted(outside),
            "worst": worst, "steps_per_s": [_rate(a), _rate(b)]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("a")
    ap.add_argument("b")
    ap.add_argument("--rtol", type=float, default=1e-3)
    ap.add_argument("--atol", type=float, default=1e-5)
    ap.add_argument("--out", default=None, help="JSON file for the comparison")
    args = ap.parse_args(argv)
    result = compare(_rows(args.a), _rows(args.b), args.rtol, args.atol)
    result["runs"] = [args.a, args.b]
    for k in result["outside"]:
        w = result["worst"][k]
        print(f"  {k}: max |diff| {w['abs']:.3g} (relative {w['rel']:.3g})")
    ra, rb = result["steps_per_s"]
    fmt = lambda r: f"{r:,.0f}" if r else "?"
    same = bool(result["iterations"]) and not result["outside"]
    print(f"{'same' if same else 'DIFFERENT'} metrics over iterations {result['iterations']} "
          f"(rtol {args.rtol}, atol {args.atol}); env steps/s: {fmt(ra)} vs {fmt(rb)}")
    if args.out:
        atomic.write_text(args.out, json.dumps(result, indent=2))
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
