"""A policy against the generalist's targets, from its evaluation files alone.

The targets (issue 24, measured with 1000 robots a cell in the evaluation physics): on the
paper's test levels of the four families, going up >= 99 % at levels 1-5 and >= 97 % at level 6,
going down >= 97 % at every level (48 cells); on the `code` suite, >= 95 % on every case at
commercial limits and >= 85 % at residential limits, up and down (24 cases). A policy's
standing is read from what `mjx-stairs eval` wrote (results.json: one record per family and
direction) and what `mjx-stairs eval --suite code` wrote (one JSON, a record per case). Each
evaluation seed is counted apart: two seeds are two counts, not an average.

    mjx-stairs scorecard --eval experiments/results/NAME/eval/up_wallrule \\
        experiments/results/NAME/eval/down_wallrule \\
        --suite experiments/results/code_suite/evaluation_stiff/wall_rule_at_test/code_NAME.json
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from mjx_stairs.atomic import write_text
from terrains.suites import load_suite

# The paper's families and test levels as the `paper` suite holds them (terrains/suites.toml)
_PAPER = load_suite("paper")
FAMILIES = tuple(dict.fromkeys(c.family for c in _PAPER))
LEVELS = tuple(sorted({c.level + 1 for c in _PAPER}))
CODE_BARS = {"commercial": 0.95, "residential": 0.85}  # the targets per code limit
ROBOTS = 1000  # robots a cell the targets are judged with


def paper_bar(direction: str, level: int) -> float:
    """The success a paper test level must reach (1-based level)."""
    return 0.99 if direction == "up" and level <= 5 else 0.97


def code_bar(case: str) -> float:
    """The success a `code` case (code_<limit>_<shape>_<direction>) must reach."""
    limit = case.split("_")[1] if case.startswith("code_") else ""
    if limit not in CODE_BARS:
        raise ValueError(f"{case!r} is not a code-suite case (code_<{'|'.join(CODE_BARS)}>_...)")
    return CODE_BARS[limit]


@dataclass(frozen=True)
class Cell:
    """One measured cell: a paper level ("u_shaped", "up", 6) or a code case (name, dir, 0)."""

    name: str
    direction: str
    level: int
    success: float
    bar: float
    robots: int

    @property
    def met(self) -> bool:
        return self.success >= self.bar - 1e-9

    def label(self) -> str:
        return f"{self.name} {self.direction} L{self.level}" if self.level else self.name


def _read(path: Path):
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as e:
        raise ValueError(f"{path}: not a JSON file ({e})") from e


def paper_cells(paths: list[str | Path]) -> dict[int, dict[tuple, Cell]]:
    """{evaluation seed: {(family, direction, level): Cell}} of the paper's test levels in
    `mjx-stairs eval` results (a results.json or the folder holding it); other schedules and
    the pyramid are left out. A cell measured twice at one seed -> ValueError."""
    out: dict[int, dict[tuple, Cell]] = {}
    for p in map(Path, paths):
        path = p / "results.json" if p.is_dir() else p
        records = _read(path)
        if not isinstance(records, list):
            raise ValueError(f"{path}: not an `mjx-stairs eval` results.json (a list of records)")
        for rec in records:
            try:
                fam, direction, seed = rec["family"], rec.get("direction", "up"), rec["seed"]
                rows = zip(rec["levels"], rec["success"], strict=True)
                robots, schedule = rec["robots_per_level"], rec.get("schedule", "test")
            except (KeyError, TypeError, ValueError) as e:
                raise ValueError(f"{path}: an eval record without {e}") from e
            if schedule != "test" or fam not in FAMILIES:
                continue
            cells = out.setdefault(int(seed), {})
            for level, success in rows:
                key = (fam, direction, int(level))
                if key in cells:
                    raise ValueError(f"{path}: {fam} {direction} L{level} at seed {seed} "
                                     "given twice")
                cells[key] = Cell(fam, direction, int(level), float(success),
                                  paper_bar(direction, int(level)), int(robots))
    return out


def code_cells(path: str | Path) -> list[tuple[str, dict, list[Cell]]]:
    """Per policy in one `code` suite JSON (experiments/gpu/code_suite.py writes one policy a
    file, `mjx-stairs eval --suite code` a record per checkpoint and case): its label, the
    file's facts (seed, robots, env) and its cells."""
    path = Path(path)
    data = _read(path)
    by_policy: dict[str, list[Cell]] = {}
    try:
        for r in data["results"]:
            label = r.get("checkpoint", data.get("policy", path.stem))
            by_policy.setdefault(label, []).append(Cell(
                r["name"], r["direction"], 0, float(r["success"]), code_bar(r["name"]),
                int(r["robots"])))
    except (KeyError, TypeError) as e:
        raise ValueError(f"{path}: not a code suite JSON (missing {e})") from e
    return [(label, data, cells) for label, cells in by_policy.items()]


def _pct(x: float) -> str:
    return f"{100 * x:.1f}"


def paper_lines(seed: int, cells: dict[tuple, Cell]) -> list[str]:
    """One seed's table of the paper levels: a row per family and direction, misses in bold."""
    n_all = len(FAMILIES) * 2 * len(LEVELS)
    met = sum(c.met for c in cells.values())
    lines = [f"**Paper test levels, evaluation seed {seed}: {met} of {n_all} at the bar** "
             f"({len(cells)} measured; up >= 99 % at L1-L5, >= 97 % at L6; down >= 97 %)", "",
             "| family | direction | " + " | ".join(f"L{lv}" for lv in LEVELS) + " |",
             "|---|---|" + "---|" * len(LEVELS)]
    for direction in ("up", "down"):
        for fam in FAMILIES:
            row = [cells.get((fam, direction, lv)) for lv in LEVELS]
            if not any(row):
                continue
            shown = ["-" if c is None else (_pct(c.success) if c.met else f"**{_pct(c.success)}**")
                     for c in row]
            lines.append(f"| {fam} | {direction} | " + " | ".join(shown) + " |")
    return lines


def code_lines(label: str, data: dict, cells: list[Cell]) -> list[str]:
    """One policy's `code` suite: per limit and direction the mean, the cases at the bar and
    the lowest case; then the cases that meet their bar."""
    met = [c for c in cells if c.met]
    mean = sum(c.success for c in cells) / max(len(cells), 1)
    lines = [f"**`code` suite ({label}, seed {data.get('seed', '?')}): {len(met)} of "
             f"{len(cells)} cases at the bar, mean {_pct(mean)} %** (commercial >= 95 %, "
             "residential >= 85 %)", "",
             "| limit | direction | mean | at the bar | lowest |", "|---|---|---|---|---|"]
    for limit in CODE_BARS:
        for direction in ("up", "down"):
            group = [c for c in cells if c.name.startswith(f"code_{limit}_")
                     and c.direction == direction]
            if not group:
                continue
            low = min(group, key=lambda c: c.success)
            short = low.name.removeprefix(f"code_{limit}_").removesuffix(f"_{direction}")
            lines.append(f"| {limit} | {direction} | "
                         f"{_pct(sum(c.success for c in group) / len(group))} | "
                         f"{sum(c.met for c in group)} of {len(group)} | {short} "
                         f"{_pct(low.success)} |")
    if met:
        lines += ["", "At the bar: " + ", ".join(f"{c.name} {_pct(c.success)}" for c in met)]
    return lines


def scorecard(evals: list[str | Path], suites: list[str | Path]) -> str:
    """The markdown scorecard: the paper levels per evaluation seed, then each `code`
    suite file, then the cells judged with fewer robots than the targets ask for."""
    if not evals and not suites:
        raise ValueError("nothing to score: give --eval and/or --suite")
    lines = ["# Scorecard against the generalist's targets (issue 24)", ""]
    few: list[Cell] = []
    for seed, cells in sorted(paper_cells(evals).items()):
        lines += paper_lines(seed, cells) + [""]
        misses = [c for c in cells.values() if not c.met]
        if misses:
            lines += ["Misses: " + ", ".join(f"{c.label()} {_pct(c.success)} (bar "
                                             f"{_pct(c.bar)})" for c in misses), ""]
        few += [c for c in cells.values() if c.robots < ROBOTS]
    for path in suites:
        for label, data, cells in code_cells(path):
            lines += code_lines(label, data, cells) + [""]
            few += [c for c in cells if c.robots < ROBOTS]
    if few:
        lines.append(f"Judged with fewer than {ROBOTS} robots a cell (not a measurement of the "
                     f"targets): {len(few)} cells, as few as {min(c.robots for c in few)}.")
    return "\n".join(lines).rstrip() + "\n"


def add_parser(sub) -> None:
    """The scorecard subcommand of `mjx-stairs`."""
    s = sub.add_parser("scorecard", help="a policy's evaluations against the generalist's "
                       "targets (paper levels, code suite)")
    s.add_argument("--eval", nargs="*", default=[], dest="evals", metavar="RESULTS",
                   help="`mjx-stairs eval` results.json files or their folders (up and down)")
    s.add_argument("--suite", nargs="*", default=[], dest="suites", metavar="JSON",
                   help="`mjx-stairs eval --suite code` JSON files")
    s.add_argument("--out", default=None, help="also write the markdown here")
    s.set_defaults(fn=cmd_scorecard)


def cmd_scorecard(args) -> int:
    text = scorecard(args.evals, args.suites)
    if args.out:
        write_text(Path(args.out), text)
    print(text, end="")
    return 0
