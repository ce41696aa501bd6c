"""table.md of a folder of `mjx-stairs sim2sim` cell files (experiments/sim2sim_generalist.sh).

    python experiments/sim2sim_generalist_table.py experiments/results/sim2sim/generalist \
        --note "Made by experiments/sim2sim_generalist.sh (N=20)."

One row per u_shaped_test_{down,up}_L*.json (down first, then up, by level): episodes, success,
falls and timeouts in %, the cell's wall time, step-edge touches per episode. The footnote takes
the robot, latency, seed and episode length from the cell files (one value each, or a list) and
ends with --note.
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

NAME = re.compile(r"u_shaped_test_(down|up)_L(\d+)\.json$")
PARTS = ("trunk", "hip", "thigh", "calf")


def _cells(folder: Path) -> list[tuple[str, dict]]:
    found = []
    for path in folder.glob("*.json"):
        m = NAME.search(path.name)
        if m:
            found.append(((m.group(1) != "down", int(m.group(2))), path))
    return [(p.stem, json.loads(p.read_text())) for _, p in sorted(found)]


def _one(values: list) -> str:
    return ", ".join(sorted({f"{v:g}" if isinstance(v, float) else str(v) for v in values}))


def table(folder: Path, note: str = "") -> str:
    cells = _cells(folder)
    if not cells:
        raise SystemExit(f"no u_shaped_test_*_L*.json in {folder}")
    rows = ["| cell | episodes | sim2sim success | fell | timeout | wall s | "
            + " | ".join(PARTS) + " |", "|" + "---|" * (6 + len(PARTS))]
    for name, d in cells:
        n = d["episodes"]
        timeout = sum(r["outcome"] == "timeout" for r in d["records"]) / n
        edges = " | ".join(f"{d['edge_contacts_per_episode'][p]:.2f}" for p in PARTS)
        rows.append(f"| {name} | {n} | {100 * d['success']:.1f} | {100 * d['fell']:.1f} | "
                    f"{100 * timeout:.1f} | {d['wall_s']:.0f} | {edges} |")
    robot = _one([Path(d["robot"]).name for _, d in cells])
    latency = _one([f'{d["options"]["latency_ms"]:.1f}' for _, d in cells])
    seed = _one([d["options"]["seed"] for _, d in cells])
    episode_s = _one([d["options"]["episode_s"] for _, d in cells])
    foot = ("Success, falls, timeouts in % of the episodes; wall s: the cell's wall time on the "
            "2-core development machine (one process); trunk/hip/thigh/calf: touches of a step "
            f"edge per episode. Robot: {robot}, latency {latency} ms, seed {seed}, "
            f"{episode_s} s episodes.")
    return "\n".join(rows) + "\n\n" + (foot + " " + note).strip() + "\n"


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", type=Path)
    ap.add_argument("--note", default="", help="the footnote's last sentence(s)")
    args = ap.parse_args(argv)
    (args.folder / "table.md").write_text(table(args.folder, args.note))
    print((args.folder / "table.md").read_text(), end="")


if __name__ == "__main__":
    main()
