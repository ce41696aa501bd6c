"""Issue 25's sim-to-sim table: a policy, exported to ONNX, in MuJoCo itself (full-geometry Go2,
box stairs, observation from the sidecar; mjx_stairs.tools.sim2sim) on the paper's test levels
of any family (default U-shaped, 1-6), walked up or down, and the `code` suite, N episodes per
cell over a pool of CPU processes.

    python experiments/gpu/sim2sim_table.py --policy experiments/results/stage2_u/policy.npz \\
        --out experiments/results/sim2sim/stage2_u --episodes 200 --workers 16 \\
        --mjx-json experiments/results/ground_truth/mjx/mjx_reference.json --mjx-policy stage2_u
    python experiments/gpu/sim2sim_table.py --policy P --out OUT --cells u_shaped straight \\
        --direction down --mjx \\
        --mjx-column robot=robot.joint_damping=2.0,robot.implicit_damping=true

Every cell's JSON (out/cells/<cell>.json: success, falls, step-edge contacts per episode, every
episode) is written atomically as soon as its episodes are in; a rerun skips the cells already
written (--force redoes them). out/table.md is rewritten after each cell.

Starts: on a family's cells, the robots start where `mjx-stairs eval --family F --direction D
--robots N --seed S` starts them (study.evaluate.success_by_level's resets: two variants per
level), on their own variant's tile, so that `--mjx` (the MJX evaluation of those very starts in
the evaluation physics, run here first; use a GPU host) gives a paired gap. Each `--mjx-column
NAME=KEY=VALUE,...` adds an MJX column of the same starts with those env overrides, e.g. the
sim2sim robot's joints (`robot.joint_damping=2.0,robot.implicit_damping=true`: go2_full.xml's
damping, integrated implicitly as MuJoCo does), which separates the simulator from the robot.
The `code` cases start where the MJX evaluation of --episodes robots per case starts them
(study.cases.case_states), and --mjx / --mjx-column evaluate those very starts in MJX too
(out/mjx*_code.json); `--code-starts own` keeps sim2sim's own seeded starts, uniform on the
spawn area (every code run before 2026-11-30, session 47), with no paired MJX column.
`--mjx-json` / `--mjx-code` read an MJX column from an earlier evaluation instead (not paired:
its own robots).

Robustness and cause-finding: --latency-ms, --noise, --push, --robot FILE.xml pass through to
every episode (write each variant to its own --out).
"""

from __future__ import annotations

import argparse
import functools
import json
import multiprocessing as mp
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from mjx_stairs import atomic  # noqa: E402
from mjx_stairs.tools import sim2sim as s2s  # noqa: E402
from mjx_stairs.tools import sim2sim_world as sw  # noqa: E402

FAMILIES = ("u_shaped", "straight", "l_shaped", "spiral")
SCHEDULE = "test"


def cell_name(family: str, schedule: str, level: int, direction: str = "up") -> str:
    """u_shaped_test_L3 (0-based level 2, up), u_shaped_test_down_L3 (down)."""
    return f"{family}_{schedule}{'' if direction == 'up' else '_' + direction}_L{level + 1}"


@functools.lru_cache(maxsize=8)
def course_of(spec: tuple) -> s2s.Course:
    """("family", family, schedule, level, variant, resolution, tile_size, direction) or
    ("case", suite, case name, resolution) -> the course (cached per worker process)."""
    import terrains
    from terrains.suites import find_case

    if spec[0] == "family":
        _, fam, sched, lv, variant, res, size, direction = spec
        tile = terrains.make_tile(fam, lv, variant, sched, res, size, direction=direction)
        return s2s.tile_course(tile, f"{cell_name(fam, sched, lv, direction)}_{variant}")
    _, suite, name, res = spec
    return s2s.tile_course(find_case(suite, name).tile(res), name)


def run_task(task: tuple) -> tuple[str, list[dict]]:
    """One chunk of a cell's episodes in a worker: (cell, records)."""
    cell, spec, poses, options, onnx, robot = task
    r = s2s.run(onnx, course_of(spec), s2s.Options(**options), robot=robot, start_poses=poses)
    return cell, r["records"]


def eval_spec(args, family: str, overrides: tuple[str, ...] = ()):
    from mjx_stairs.study.specs import EvalSpec

    return EvalSpec(family=family, schedule=SCHEDULE, direction=args.direction,
                    levels=tuple(args.levels), robots_per_level=args.episodes, seed=args.seed,
                    resolution=args.resolution, tile_size=10.0, env_overrides=overrides)


def tile_poses(qpos: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """[n, 3] x, y, yaw of robots' reset qpos [n, >= 7] in the frame of a tile at `origin`
    (the reset's base quaternion is a yaw alone)."""
    return np.column_stack([qpos[:, :2] - origin, 2 * np.arctan2(qpos[:, 6], qpos[:, 3])])


def family_starts(policy_path: Path, spec) -> dict[str, list[tuple[str, np.ndarray]]]:
    """{cell: [(variant, poses [n, 3] x, y, yaw in its tile frame)]}: the starts of `mjx-stairs
    eval` (study.evaluate.success_by_level's resets of the EvalSpec `spec`) on each level of its
    family, grouped by the variant tile each robot is on."""
    import terrains
    from mjx_stairs.rl.policy import load_policy
    from mjx_stairs.study.evaluate import level_states, make_eval_env

    env, levels = make_eval_env(load_policy(policy_path), spec)
    n = spec.robots_per_level
    state = level_states(env, len(levels), spec)
    qpos, tile = np.asarray(state.pipeline_state.qpos), np.asarray(state.info["tile"])
    origin = np.asarray(env.tile_origin)
    cols = len(origin) // len(levels)  # variants per level
    names = terrains.variants(spec.family)
    out: dict[str, list[tuple[str, np.ndarray]]] = {}
    for i, lv in enumerate(levels):
        rows = slice(i * n, (i + 1) * n)
        groups = []
        for col in range(cols):
            mine = tile[rows] == i * cols + col
            poses = tile_poses(qpos[rows][mine], origin[i * cols + col])
            groups.append((names[col % len(names)], poses))
        out[cell_name(spec.family, SCHEDULE, lv, spec.direction)] = groups
    return out


def code_spec(args, overrides: tuple[str, ...] = ()):
    """The MJX evaluation of the `code` cases that sim2sim pairs with: --episodes robots per
    case, --episode-s, --seed (code_suite.py's spec at those numbers)."""
    from mjx_stairs.study.specs import EvalSpec

    return EvalSpec(robots_per_level=args.episodes, episode_length_s=args.episode_s,
                    seed=args.seed, resolution=args.resolution, env_overrides=overrides)


def code_cases(args) -> list[tuple]:
    """[(name, tile)] of the `code` cases asked for (--cases, default all 24)."""
    return list(_code_cases(args.resolution, tuple(args.cases)))


@functools.lru_cache(maxsize=4)
def _code_cases(resolution: float, names: tuple[str, ...]) -> tuple:
    """The tiles built once per process (starts, tasks and the MJX column all ask for them)."""
    from mjx_stairs.study.cases import suite_cases

    return tuple(c for c in suite_cases("code", resolution) if not names or c[0] in names)


def code_starts(policy_path: Path, args) -> dict[str, np.ndarray]:
    """{case: poses [n, 3] x, y, yaw in the case's own tile frame}: where the MJX evaluation of
    `code_spec` starts its robots (study.cases.case_states on the cases' atlas), so that the
    `code` cells are paired with --mjx as the family cells are. The atlas pads every case to
    the largest, centred (terrains.tile.pad_tile): that shift is taken off."""
    from mjx_stairs.rl.policy import load_policy
    from mjx_stairs.study import cases as cs
    from mjx_stairs.study.evaluate import eval_env
    from terrains.tile import pad_tile

    found, n = code_cases(args), args.episodes
    env = eval_env(load_policy(policy_path), cs.case_atlas(found), code_spec(args))
    state = cs.case_states(env, len(found), n, args.seed)
    qpos, tile = np.asarray(state.pipeline_state.qpos), np.asarray(state.info["tile"])
    origin = np.asarray(env.tile_origin)
    points = max(max(t.heights.shape) for _, t in found)
    out = {}
    for i, (name, t) in enumerate(found):
        rows = slice(i * n, (i + 1) * n)
        shift = pad_tile(t, points).spawn[:2] - t.spawn[:2]
        out[name] = tile_poses(qpos[rows], origin[tile[rows]] + shift)
    return out


def tasks_for(args, onnx: Path, done: set[str]) -> list[tuple]:
    """Every chunk of every cell not written yet."""
    opts = dict(episode_s=args.episode_s, latency_ms=args.latency_ms, noise=args.noise,
                push=args.push, seed=args.seed, contact_timeconst=args.contact_timeconst)
    out = []

    def chunks(cell, spec, poses):
        for k in range(0, len(poses), args.chunk):
            out.append((cell, spec, poses[k:k + args.chunk], {**opts, "seed": args.seed + k},
                        str(onnx), args.robot))

    for fam in (c for c in args.cells if c in FAMILIES):
        starts = family_starts(args.policy, eval_spec(args, fam))
        for cell, groups in starts.items():
            lv = int(cell.rsplit("_L", 1)[1]) - 1
            for variant, poses in ([] if cell in done else groups):
                chunks(cell, ("family", fam, SCHEDULE, lv, variant, args.resolution, 10.0,
                              args.direction), poses)
    if "code" in args.cells:
        from mjx_stairs.tools import contract as ct

        c = ct.load_contract(onnx)
        todo = [name for name, _ in code_cases(args) if name not in done]
        paired = code_starts(args.policy, args) if todo and args.code_starts == "mjx" else {}
        for name in todo:
            spec = ("case", "code", name, args.resolution)
            chunks(name, spec, paired[name] if paired else
                   s2s.starts(course_of(spec), c, args.episodes, args.seed))
    return out


def mjx_columns(args, out: Path) -> dict[str, dict[str, float]]:
    """{column: {cell: MJX success}}: "MJX" in the evaluation physics (--mjx) and one column per
    --mjx-column, each on the same starts (run here, cached in out/mjx*.json), or "MJX" read from
    an earlier evaluation (--mjx-json)."""
    cols: dict[str, dict[str, float]] = {}
    runs = ([("MJX", ())] if args.mjx else []) + [
        (name, tuple(o for o in rest.split(",") if o)) for name, _, rest in
        (c.partition("=") for c in args.mjx_column)]
    policy = None
    for name, overrides in runs:
        col = cols.setdefault(name, {})
        tag = "" if name == "MJX" else f"_{name}"
        for fam in (c for c in args.cells if c in FAMILIES):
            path = out / f"mjx{tag}_{fam}_{args.direction}.json"
            if not path.exists():
                from mjx_stairs.rl.policy import load_policy
                from mjx_stairs.study.evaluate import success_by_level

                policy = policy or load_policy(args.policy)
                r = success_by_level(policy, eval_spec(args, fam, overrides))
                atomic.write_text(path, json.dumps(r, indent=1) + "\n")
            r = json.loads(path.read_text())
            col.update({cell_name(fam, SCHEDULE, lv - 1, args.direction): s
                        for lv, s in zip(r["levels"], r["success"], strict=True)})
        if "code" in args.cells and args.code_starts == "mjx":
            path = out / f"mjx{tag}_code.json"
            want = {name for name, _ in code_cases(args)}
            if not path.exists() or want != {r["name"] for r in json.loads(
                    path.read_text())["results"]}:  # none yet, or of other cases
                from mjx_stairs.rl.policy import load_policy

                policy = policy or load_policy(args.policy)
                mjx_code(path, policy, args, overrides)
            col.update({r["name"]: r["success"] for r in json.loads(path.read_text())["results"]})
    if args.mjx_json:
        r = json.loads(Path(args.mjx_json).read_text())
        r = r["policies"][args.mjx_policy] if "policies" in r else r
        cols["MJX"] = {cell_name(c["family"], c["schedule"], c["level"] - 1): s
                       for c, s in zip(r["cells"], r["success"], strict=True)}
    for name, _, path in (c.partition("=") for c in args.mjx_code):  # code_suite.py's files
        if not (name and Path(path).is_file()):
            raise SystemExit(f"--mjx-code {name}={path}: expected NAME=FILE of an existing "
                             "code_suite.py result")
        results = json.loads(Path(path).read_text())["results"]
        cols[name] = {r["name"]: r["success"] for r in results}
    return cols


def mjx_code(path: Path, policy, args, overrides: tuple[str, ...]) -> None:
    """The MJX evaluation of the `code` cases on `code_starts`'s starts, written to `path`:
    {"results": [case records of study.cases], run facts}."""
    from mjx_stairs.study import cases as cs
    from mjx_stairs.study.evaluate import eval_config, physics_settings

    spec = code_spec(args, overrides)
    records = cs.success_by_case({"policy": policy}, code_cases(args), spec)["policy"]
    env_cfg = eval_config(policy, spec)
    atomic.write_text(path, json.dumps({
        "robots_per_case": args.episodes, "episode_length_s": args.episode_s, "seed": args.seed,
        "env_overrides": list(overrides), "physics_settings": physics_settings(env_cfg),
        "policy": str(args.policy), "results": records}, indent=1) + "\n")


def cell_direction(cell: str, direction: str) -> str:
    """A `code` case's own direction (its name ends in _up or _down), else the families' one."""
    return cell.rsplit("_", 1)[1] if cell.startswith("code_") else direction


def write_cell(out: Path, cell: str, records: list[dict], args) -> None:
    records = sorted(records, key=lambda r: r["start"])
    result = {"cell": cell, **s2s.summarise(records), "policy": str(args.policy),
              "robot": args.robot or "go2_full.xml (ours)",
              "robot_sha256": sw.file_sha256(args.robot or sw.OUR_ROBOT),
              "direction": cell_direction(cell, args.direction),
              "latency_ms": args.latency_ms, "contact_timeconst": args.contact_timeconst,
              "noise": args.noise, "push": args.push, "episode_s": args.episode_s,
              "seed": args.seed, "resolution": args.resolution, "records": records}
    atomic.write_text(out / "cells" / f"{cell}.json", json.dumps(result, indent=1) + "\n")


def write_table(out: Path, mjx: dict[str, dict[str, float]]) -> None:
    """out/table.md: every cell file, with each MJX column and the gap to the first of them."""
    names = list(mjx)
    head = ["cell", "episodes", "sim2sim success", "fell"] + [f"{n} success" for n in names]
    if names:
        head.append(f"gap ({names[0]} - sim2sim)")
    head += ["trunk", "hip", "thigh", "calf"]
    rows = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for f in sorted((out / "cells").glob("*.json")):
        r = json.loads(f.read_text())
        s = r["success"]
        vals = [mjx[n].get(r["cell"]) for n in names]
        cells = [r["cell"], str(r["episodes"]), f"{100 * s:.1f}", f"{100 * r['fell']:.1f}"]
        cells += ["–" if m is None else f"{100 * m:.1f}" for m in vals]
        if names:
            cells.append("–" if vals[0] is None else f"{100 * (vals[0] - s):+.1f}")
        e = r["edge_contacts_per_episode"]
        cells += [f"{e[k]:.2f}" for k in ("trunk", "hip", "thigh", "calf")]
        rows.append("| " + " | ".join(cells) + " |")
    rows.append("\nSuccess and falls in % of the episodes; trunk/hip/thigh/calf: touches of a "
                "step edge per episode (mjx_stairs.tools.sim2sim).")
    atomic.write_text(out / "table.md", "\n".join(rows) + "\n")


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--policy", type=Path, default=ROOT / "experiments/results/stage2_u/policy.npz")
    p.add_argument("--out", type=Path, default=ROOT / "experiments/results/sim2sim/stage2_u")
    p.add_argument("--cells", nargs="+", default=["u_shaped", "code"],
                   choices=[*FAMILIES, "code"], help="families (their test levels) and/or code")
    p.add_argument("--direction", default="up", choices=["up", "down"],
                   help="the families' staircases walked up or down")
    p.add_argument("--levels", type=lambda v: [int(x) - 1 for x in v.split(",")], default=[],
                   help="1-based test levels, e.g. 4,5,6 (default all)")
    p.add_argument("--cases", nargs="+", default=[],
                   help="of the code suite only these cases (default all 24)")
    p.add_argument("--episodes", type=int, default=200, help="episodes per cell")
    p.add_argument("--workers", type=int, default=16)
    p.add_argument("--chunk", type=int, default=10, help="episodes per task")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--episode-s", type=float, default=20.0)
    p.add_argument("--resolution", type=float, default=0.025)
    p.add_argument("--latency-ms", type=float, default=0.0)
    p.add_argument("--noise", action="store_true")
    p.add_argument("--push", action="store_true")
    p.add_argument("--contact-timeconst", type=float, default=0.0, help="every geom's contact "
                   "solref time constant in MuJoCo (0: the MJCF's 0.02 s; 0.01: today's MJX "
                   "evaluation physics, whose --mjx columns these are)")
    p.add_argument("--robot", default=None, help="a Go2 MJCF (default: ours, full geometry)")
    p.add_argument("--mjx", action="store_true", help="run the MJX evaluation of the same "
                   "starts first (a GPU host for many cells)")
    p.add_argument("--code-starts", default="mjx", choices=["mjx", "own"],
                   help="the code cases' starts: the MJX evaluation's of --episodes robots per "
                   "case (paired with --mjx and --mjx-column), or sim2sim's own (seeded, "
                   "uniform on the spawn area: the runs before 2026-11-30 session 47)")
    p.add_argument("--mjx-column", action="append", default=[], metavar="NAME=KEY=VALUE,...",
                   help="another MJX column of the same starts with these env overrides")
    p.add_argument("--mjx-only", action="store_true", help="compute the MJX columns (cached in "
                   "--out) and stop: a GPU host runs them, then sim2sim on its CPUs")
    p.add_argument("--mjx-json", default=None, help="MJX success from an earlier evaluation")
    p.add_argument("--mjx-policy", default="stage2_u", help="its policy name")
    p.add_argument("--mjx-code", action="append", default=[], metavar="NAME=FILE",
                   help="an MJX column of the code cases from a code_suite.py file (its own "
                   "1000 robots per case, not these starts)")
    p.add_argument("--force", action="store_true", help="redo cells already written")
    args = p.parse_args(argv)
    if args.cases:
        from terrains.suites import find_case

        for name in args.cases:
            try:
                find_case("code", name)
            except ValueError as e:  # an unknown case: one line naming the known ones
                raise SystemExit(f"--cases: {e}") from None
    out = args.out
    (out / "cells").mkdir(parents=True, exist_ok=True)
    onnx = out / "policy.onnx"
    if args.force or not onnx.exists():
        from mjx_stairs.tools import export

        export.export(args.policy, onnx)
    done = set() if args.force else {f.stem for f in (out / "cells").glob("*.json")}
    mjx = mjx_columns(args, out)
    if args.mjx_only:
        return
    tasks = tasks_for(args, onnx, done)
    left: dict[str, int] = {}
    for t in tasks:
        left[t[0]] = left.get(t[0], 0) + 1
    got: dict[str, list[dict]] = {c: [] for c in left}
    t0 = time.time()
    print(f"{len(left)} cells, {len(tasks)} tasks, {args.workers} workers", flush=True)
    with mp.get_context("spawn").Pool(args.workers) as pool:
        for cell, records in pool.imap_unordered(run_task, tasks):
            got[cell] += records
            left[cell] -= 1
            if left[cell] == 0:
                write_cell(out, cell, got.pop(cell), args)
                write_table(out, mjx)
                print(f"{cell} done ({time.time() - t0:.0f} s)", flush=True)
    write_table(out, mjx)
    print((out / "table.md").read_text(), flush=True)


if __name__ == "__main__":
    main()
