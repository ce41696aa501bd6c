"""A policy's sim-to-sim table: its MJX evaluation beside its runs in MuJoCo itself, per cell.

Issue 25 asks for one table per policy: success and falls per level of the paper's test levels
(and per `code` case) in MuJoCo itself, beside the MJX evaluation of the same policy, with the
step-edge touches. The MuJoCo cells come from `sim2sim_table.py` runs (`<out>/cells/<cell>.json`),
often spread over several folders and sessions; this module gathers every cell of one policy in
one setting (the robot file, the latency, the contact time constant; no noise, no push) under a
folder, pairs it with the MJX evaluations given (`mjx-stairs eval` results.json folders, several
seeds allowed; a `code` suite JSON), and writes the table with the gap (MJX mean − MuJoCo).

    mjx-stairs sim2sim-gaps --policy experiments/results/generalist_from_stage1_mix/policy.npz \\
        --sim2sim experiments/results/sim2sim/mix_wall_rule_export \\
        --mjx experiments/results/generalist_from_stage1_mix/eval/up_wallrule \\
              experiments/results/generalist_from_stage1_mix/eval/down_wallrule
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

FAMILIES = ("straight", "l_shaped", "u_shaped", "spiral")
LEVELS = (1, 2, 3, 4, 5, 6)
EDGE_PARTS = ("calf", "thigh", "trunk", "hip")


@dataclass
class Cell:
    """One cell: ("u_shaped", "up", 6) for a paper level, ("code_commercial_u_left_up", "up",
    0) for a `code` case; MJX successes (one per evaluation given) and the MuJoCo run."""

    key: tuple[str, str, int]
    mjx: list[float] = field(default_factory=list)
    mujoco: dict | None = None
    source: str = ""
    also: list[str] = field(default_factory=list)

    @property
    def gap(self) -> float | None:
        if not self.mjx or self.mujoco is None:
            return None
        return 100.0 * (sum(self.mjx) / len(self.mjx) - self.mujoco["success"])


def _paper_key(rec: dict) -> tuple[str, str, int] | None:
    name = rec.get("cell", "")
    for fam in FAMILIES:  # "u_shaped_test_L6", "u_shaped_test_down_L6"
        if name.startswith(f"{fam}_test_") and name.rsplit("_L", 1)[-1].isdigit():
            return fam, rec.get("direction", "up"), int(name.rsplit("_L", 1)[1])
    if name.startswith("code_"):
        return name, rec.get("direction", "up"), 0
    return None


def mujoco_cells(root: str | Path, policy: str, robot_sha: str | None, latency_ms: float,
                 contact_timeconst: float) -> tuple[dict, set[str]]:
    """{key: (record, path, [other paths])} of every sim2sim cell JSON under `root` run with
    `policy` in this setting, and the robot files' SHA-256s seen among them (with `robot_sha`
    None every robot is taken, and the caller refuses more than one). Where a cell was run
    twice the run with more episodes is kept (the first by path on a tie)."""
    found: dict = {}
    shas: set[str] = set()
    for path in sorted(Path(root).rglob("cells/*.json")):
        try:
            rec = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError) as e:
            raise ValueError(f"{path}: not a sim2sim cell JSON ({e})") from e
        key = _paper_key(rec)
        if (key is None or rec.get("policy") != policy or rec.get("noise") or rec.get("push")
                or abs(float(rec.get("latency_ms", 0.0)) - latency_ms) > 1e-9
                or abs(float(rec.get("contact_timeconst", -1)) - contact_timeconst) > 1e-9
                or (robot_sha and not rec.get("robot_sha256", "").startswith(robot_sha))):
            continue
        shas.add(rec.get("robot_sha256", "?"))
        if key in found:
            best, where, others = found[key]
            if rec["episodes"] > best["episodes"]:
                found[key] = (rec, str(path), [where, *others])
            else:
                others.append(str(path))
            continue
        found[key] = (rec, str(path), [])
    return found, shas


def mjx_successes(folders: list[str | Path], code_json: list[str | Path]) -> dict:
    """{key: [success, ...]} from `mjx-stairs eval` folders (results.json) and `code` suite
    JSON files, one entry per evaluation."""
    out: dict = {}
    for folder in folders:
        path = Path(folder) / "results.json"
        for rec in json.loads(path.read_text()):
            if rec.get("schedule", "test") != "test":  # the paper's test levels only
                continue
            for level, s in zip(rec["levels"], rec["success"], strict=True):
                out.setdefault((rec["family"], rec.get("direction", "up"), int(level)),
                               []).append(float(s))
    for path in code_json:
        for rec in json.loads(Path(path).read_text())["results"]:
            out.setdefault((rec["name"], rec["direction"], 0), []).append(float(rec["success"]))
    return out


def gather(policy: str, sim2sim_root: str | Path, mjx: list, code_json: list = (),
           robot_sha: str | None = None, latency_ms: float = 0.0,
           contact_timeconst: float = 0.01) -> list[Cell]:
    """Every paper cell (and every code case with an MJX or MuJoCo figure), in table order."""
    runs, shas = mujoco_cells(sim2sim_root, policy, robot_sha, latency_ms, contact_timeconst)
    if len(shas) > 1:
        raise ValueError(f"the cells of {policy} under {sim2sim_root} ran {len(shas)} robot "
                         f"files ({', '.join(s[:12] for s in sorted(shas))}): name one with "
                         "--robot-sha")
    succ = mjx_successes(mjx, code_json)
    keys = [(f, d, lv) for d in ("up", "down") for f in FAMILIES for lv in LEVELS]
    keys += sorted(k for k in set(succ) | set(runs) if k[2] == 0)
    cells = []
    for key in keys:
        c = Cell(key, succ.get(key, []))
        if key in runs:
            c.mujoco, c.source, c.also = runs[key][0], runs[key][1], runs[key][2]
        cells.append(c)
    return cells


def _row(c: Cell, root: Path) -> str:
    name = f"{c.key[0]} {c.key[1]} L{c.key[2]}" if c.key[2] else c.key[0].removeprefix("code_")
    mjx = " / ".join(f"{100 * s:.1f}" for s in c.mjx) or "-"
    if c.mujoco is None:
        return f"| {name} | {mjx} | not run | | | | |"
    m = c.mujoco
    edges = " / ".join(f"{m['edge_contacts_per_episode'].get(p, 0.0):.2f}" for p in EDGE_PARTS)
    gap = "-" if c.gap is None else f"{c.gap:+.1f}"
    where = str(Path(c.source).parent.parent.relative_to(root))
    more = f" (+{len(c.also)} more)" if c.also else ""
    return (f"| {name} | {mjx} | {100 * m['success']:.1f} ({m['episodes']}) | "
            f"{100 * m['fell']:.1f} | {gap} | {edges} | `{where}`{more} |")


def markdown(cells: list[Cell], sim2sim_root: str | Path, title: str) -> str:
    """The table, then how many paper cells ran and how many are within 3 points."""
    root = Path(sim2sim_root)
    lines = [f"# {title}", "",
             "| cell | MJX success % (each evaluation) | MuJoCo itself % (episodes) | falls % "
             "| gap (MJX mean − MuJoCo) | edge touches per episode: calf / thigh / trunk / hip "
             "| folder |", "|---|---|---|---|---|---|---|"]
    lines += [_row(c, root) for c in cells]
    paper = [c for c in cells if c.key[2]]
    run = [c for c in paper if c.gap is not None]
    within = sum(abs(c.gap) <= 3.0 for c in run)
    worst = max(run, key=lambda c: abs(c.gap), default=None)
    lines += ["", f"Paper cells run in both: {len(run)} of {len(paper)}; within 3 points: "
              f"{within} of {len(run)}"
              + (f"; largest gap {worst.gap:+.1f} ({worst.key[0]} {worst.key[1]} "
                 f"L{worst.key[2]})." if worst else ".")]
    code = [c for c in cells if not c.key[2] and c.gap is not None]
    if code:
        lines.append(f"`code` cases run in both: {len(code)}; within 3 points: "
                     f"{sum(abs(c.gap) <= 3.0 for c in code)} (the suite's MJX starts are "
                     "its own: not paired).")
    return "\n".join(lines) + "\n"
