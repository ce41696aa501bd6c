"""Issue 23's baseline and checks: the committed policies on the `code` suite (building-code
stairs, every shape up and down, one atlas, 1000 robots per case), and `eval --mesh` against
`eval --family` on the same staircase.

  python experiments/gpu/code_suite.py OUT [--steps suite,mesh,alone] [--policies a,b]
      [--robots 1000] [--episode-s 30] [--env KEY=VALUE ...]
  smoke test on a CPU: JAX_PLATFORMS=cpu python experiments/gpu/code_suite.py /tmp/cs
      --robots 4 --episode-s 2 --resolution 0.1

Steps, each writing JSON under OUT as soon as it is complete and skipped when its file exists
(so a command cut short is continued by running it again):
  suite  every policy on the code suite: OUT/code_<policy>.json (one record per case)
  mesh   U-shaped test level 3 (left) and the code suite's commercial U (left, up and down)
         exported to STL (OUT/u3/), then for each of --mesh-policies: eval --family u_shaped
         --levels 3 (the same starts, left and right tiles; OUT/u3_family_<policy>.json);
         eval --mesh of every export with the importer's route, and of U level 3 with that
         route shifted a third of the stair's width to the left and to the right, back to the
         goal over the last metre
         (terrains.cases.offset_route; OUT/u3_mesh_<policy>.json, one record per case); eval
         --suite of the exported cases, whose JSON carry the procedural route and spawn area
         (OUT/u3_case_<policy>.json). Files written by an earlier version with U level 3 only
         are kept (the step is skipped where the file exists).
  offset only the mesh step's two offset-route cases for each of --mesh-policies:
         OUT/u3_offset_<policy>.json (not in the default steps)
  alone  stage2_u on four code cases one at a time (OUT/code_alone_stage2_u.json), to compare
         with the same cases in code_stage2_u.json
  table  (no GPU) OUT/code_suite.md from the files present: success / falls per case and policy,
         the U level 3 comparison and the together-or-alone comparison
Every evaluation runs in the evaluation env of mjx_stairs.study.evaluate.eval_env: the
evaluation physics (specs.EVAL_PHYSICS, issue 19), with --env added.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

RESULTS = Path("experiments/results")
POLICIES = {  # the committed policies the README cites
    "stage1": RESULTS / "stage1/policy.npz",
    "stage2_u": RESULTS / "stage2_u/policy.npz",
    "stage2_u_lean": RESULTS / "stage2_u_lean/policy.npz",
    "straight_lean": RESULTS / "transfer_lean/straight/policy.npz",
    "l_shaped_lean": RESULTS / "transfer_lean/l_shaped/policy.npz",
    "spiral_lean": RESULTS / "transfer_lean/spiral/policy.npz",
    "generalist": RESULTS / "generalist/policy.npz",
    "generalist_line": RESULTS / "generalist_line/policy.npz",  # + 480 it with env.low_line_m
    "generalist_robot": RESULTS / "generalist_robot/policy.npz",  # implicit damping, head
    "generalist_history": RESULTS / "generalist_history/policy.npz",  # + 3 steps of history
    "stage2_u_robot": RESULTS / "stage2_u_robot/policy.npz",
    "generalist_noent": RESULTS / "generalist_noent/policy.npz",  # no entropy bonus
    "generalist_std05": RESULTS / "generalist_std05/policy.npz",  # std bound 0.5
}
MESH_POLICIES = ("stage2_u", "stage2_u_lean")  # the default of --mesh-policies
CODE_EXPORTS = ("code_commercial_u_left_up", "code_commercial_u_left_down")
OFFSET = 1.0 / 3.0  # of the stair's clear width
# The shift fades over the route's last metre (mjx_stairs.env.routes.TAPER_M, as training's
# routes): a route ends on its goal. Without it (first run, H100, 2026-11-24) the robots stopped
# at the route's end 0.67 m beside the goal: 44-49 % time-outs.
ALONE = ("code_commercial_straight_up", "code_commercial_u_left_down",
         "code_residential_spiral_ccw_up", "code_residential_winder_left_down")
EVAL_PHYSICS: tuple[str, ...] = ()  # none: the evaluation physics preset (specs.EVAL_PHYSICS)


def write(path: Path, record: dict) -> None:
    from mjx_stairs.atomic import write_text

    write_text(path, json.dumps(record, indent=1))
    print(f"[code_suite] wrote {path}", flush=True)


def facts(spec, t0: float, **extra) -> dict:
    import jax

    return {"robots_per_case": spec.robots_per_level, "episode_length_s": spec.episode_length_s,
            "seed": spec.seed, "resolution": spec.resolution,
            "eval_physics": spec.physics, "env_overrides": list(spec.env_overrides),
            "device": jax.devices()[0].device_kind,
            "wall_s_with_compile": time.time() - t0, **extra}


def run_suite(out: Path, names: list[str], spec) -> None:
    """Policies that share an evaluation env share one compiled program (cases.by_env)."""
    from mjx_stairs.rl.policy import load_policy
    from mjx_stairs.study import cases, evaluate

    code = cases.suite_cases("code", spec.resolution)
    todo = {n: load_policy(POLICIES[n]) for n in names if not (out / f"code_{n}.json").exists()}
    for group in cases.by_env(todo, spec) if todo else []:
        t0 = time.time()
        for name, recs in cases.success_by_case(group, code, spec).items():
            print(f"\n{name}, code suite\n" + cases.case_table(recs), flush=True)
            env_config = evaluate.env_config_of(todo[name], evaluate.physics_overrides(spec))
            write(out / f"code_{name}.json", facts(
                spec, t0, policy=str(POLICIES[name]), suite="code",
                physics_settings=evaluate.physics_settings(env_config), results=recs))


def run_alone(out: Path, spec) -> None:
    from mjx_stairs.rl.policy import load_policy
    from mjx_stairs.study import cases

    path = out / "code_alone_stage2_u.json"
    if path.exists():
        return
    t0 = time.time()
    policy = {"stage2_u": load_policy(POLICIES["stage2_u"])}
    code = dict(cases.suite_cases("code", spec.resolution))
    recs = [cases.success_by_case(policy, [(n, code[n])], spec)["stage2_u"][0] for n in ALONE]
    print("\nstage2_u, code cases one at a time\n" + cases.case_table(recs), flush=True)
    write(path, facts(spec, t0, policy=str(POLICIES["stage2_u"]), results=recs))


def export_u3(out: Path, resolution: float) -> Path:
    """U-shaped test level 3 (left) as OUT/u3/u3.stl + u3.json (the procedural route), and the
    code suite's CODE_EXPORTS beside it."""
    import terrains
    from mjx_stairs.study import cases
    from terrains.suites import write_case

    folder = out / "u3"
    if not (folder / "u3.json").exists():
        tile = terrains.make_tile("u_shaped", 2, "left", "test", resolution)
        write_case(tile, folder, "u3")
    if not all((folder / f"{n}.json").exists() for n in CODE_EXPORTS):
        code = dict(cases.suite_cases("code", resolution))
        for name in CODE_EXPORTS:
            write_case(code[name], folder, name)
    return folder


def mesh_routes(folder: Path, resolution: float) -> list:
    """eval --mesh's cases: every export with the importer's route (named as the export), and
    U level 3 with its procedural route shifted OFFSET of the width left and right."""
    from mjx_stairs.env.routes import TAPER_M
    from mjx_stairs.study.cases import mesh_cases
    from terrains.cases import mesh_tile, offset_route

    recs = {n: json.loads((folder / f"{n}.json").read_text()) for n in ("u3", *CODE_EXPORTS)}
    found = [case for rec in recs.values()
             for case in mesh_cases(folder / rec["mesh"], rec["start"][:2], rec["goal"][:2],
                                    None, resolution)]
    u3 = recs["u3"]
    for side, sign in (("left", 1.0), ("right", -1.0)):
        route = offset_route(u3["route"], sign * OFFSET * u3["spec"]["width"], TAPER_M)
        found.append((f"u3_offset_{side}", mesh_tile(folder / u3["mesh"], u3["start"][:2],
                                                     u3["goal"][:2], route, resolution)))
    return found


def run_mesh(out: Path, spec, names: tuple[str, ...] = MESH_POLICIES) -> None:
    """The family (evaluate.success_by_cell: the starts of eval --family), the meshes and the
    cases, each one program per evaluation env (cases.by_env: a history policy needs its own)."""
    from mjx_stairs.rl.policy import load_policy
    from mjx_stairs.study import cases, evaluate

    folder = export_u3(out, spec.resolution)
    policies = {n: load_policy(POLICIES[n]) for n in names}
    todo = {n: p for n, p in policies.items() if not (out / f"u3_family_{n}.json").exists()}
    if todo:
        t0 = time.time()
        cell = evaluate.CellSpec(cells=(("u_shaped", "test", 2),),
                                 robots_per_cell=spec.robots_per_level,
                                 episode_length_s=spec.episode_length_s, seed=spec.seed,
                                 resolution=spec.resolution, physics=spec.physics,
                                 env_overrides=spec.env_overrides)
        for group in cases.by_env(todo, cell):
            for name, r in evaluate.success_by_cell(group, cell).items():
                print(f"{name} eval --family u_shaped --levels 3: {100 * r['success'][0]:.1f} %")
                write(out / f"u3_family_{name}.json",
                      facts(spec, t0, policy=str(POLICIES[name]), result=r))
    run_cases(out, "mesh", "eval --mesh u3", policies, lambda: mesh_routes(folder, spec.resolution),
              spec)
    run_cases(out, "case", "eval --suite u3", policies,
              lambda: cases.suite_cases(str(folder), spec.resolution), spec)


def run_offset(out: Path, spec, names: tuple[str, ...] = MESH_POLICIES) -> None:
    """Only the mesh step's two offset-route cases (U level 3, the route shifted a third of the
    width left and right) for each policy: OUT/u3_offset_<policy>.json (a quick re-measure,
    e.g. after terrains.cases.offset_route's swallowtail fix of 2026-11-27)."""
    from mjx_stairs.rl.policy import load_policy

    run_cases(out, "offset", "eval --mesh u3, offset routes",
              {n: load_policy(POLICIES[n]) for n in names},
              lambda: [c for c in mesh_routes(export_u3(out, spec.resolution), spec.resolution)
                       if c[0].startswith("u3_offset_")], spec)


def run_cases(out: Path, kind: str, label: str, policies: dict, make, spec) -> None:
    """The cases `make()` for each policy without its OUT/u3_<kind>_<policy>.json yet, one
    program per evaluation env (cases.by_env), each policy's records written there."""
    from mjx_stairs.study import cases

    todo = {n: p for n, p in policies.items() if not (out / f"u3_{kind}_{n}.json").exists()}
    if not todo:
        return
    t0, found = time.time(), make()
    for group in cases.by_env(todo, spec):
        for name, recs in cases.success_by_case(group, found, spec).items():
            print(f"{name} {label}\n" + cases.case_table(recs), flush=True)
            write(out / f"u3_{kind}_{name}.json", facts(spec, t0, policy=str(POLICIES[name]),
                                                         results=recs))


def write_table(out: Path) -> None:
    """Long: three markdown tables, each only from the files present."""
    from mjx_stairs.atomic import write_text

    runs = {p.stem[len("code_"):]: json.loads(p.read_text())
            for p in sorted(out.glob("code_*.json")) if p.stem != "code_alone_stage2_u"}
    lines = []
    if runs:
        first = next(iter(runs.values()))
        lines += [f"Success / falls in % of {first['robots_per_case']} robots per case, one "
                  f"{first['episode_length_s']:g} s episode, env {first['env_overrides']}, "
                  f"{first['device']}.", "",
                  "| case | " + " | ".join(runs) + " |", "|---|" + "---|" * len(runs)]
        for i, rec in enumerate(first["results"]):
            cells = [f"{100 * r['results'][i]['success']:.1f} / {100 * r['results'][i]['fell']:.1f}"
                     for r in runs.values()]
            lines.append(f"| {rec['name']} | " + " | ".join(cells) + " |")
    lines += mesh_table(out, runs)
    alone = out / "code_alone_stage2_u.json"
    if alone.exists() and "stage2_u" in runs:
        together = {r["name"]: r for r in runs["stage2_u"]["results"]}
        lines += ["", "stage2_u, success / falls in %: the case in the suite's atlas, alone", "",
                  "| case | together | alone |", "|---|---|---|"]
        for r in json.loads(alone.read_text())["results"]:
            t = together[r["name"]]
            lines.append(f"| {r['name']} | {100 * t['success']:.1f} / {100 * t['fell']:.1f} | "
                         f"{100 * r['success']:.1f} / {100 * r['fell']:.1f} |")
    write_text(out / "code_suite.md", "\n".join(lines) + "\n")
    print("\n".join(lines), flush=True)


def mesh_table(out: Path, runs: dict) -> list[str]:
    """U level 3 (family, mesh, case, offset routes) and the exported code cases (suite, mesh,
    case) per policy with a u3_family file; '-' where an older file lacks a case."""
    u3, code = [], []
    for path in sorted(out.glob("u3_family_*.json")):
        name = path.stem[len("u3_family_"):]
        got = {k: out / f"u3_{k}_{name}.json" for k in ("mesh", "case")}
        fam = json.loads(path.read_text())["result"]  # a cell record
        m, c = ({r["name"]: r for r in json.loads(got[k].read_text())["results"]}
                if got[k].exists() else {} for k in ("mesh", "case"))
        suite = {r["name"]: r for r in runs.get(name, {}).get("results", [])}
        off = out / f"u3_offset_{name}.json"  # the offset step's re-measure wins over the mesh's
        off = {r["name"]: r for r in json.loads(off.read_text())["results"]} if off.exists() else m

        def pct(recs: dict, key: str) -> str:
            return f"{100 * recs[key]['success']:.1f}" if key in recs else "-"
        u3.append(f"| {name} | {100 * fam['success'][0]:.1f} | {pct(m, 'u3')} | {pct(c, 'u3')} "
                  f"| {pct(off, 'u3_offset_left')} | {pct(off, 'u3_offset_right')} |")
        code += [f"| {name} | {case} | {pct(suite, case)} | {pct(m, case)} | {pct(c, case)} |"
                 for case in CODE_EXPORTS if case in m]
    lines = []
    if u3:
        lines += ["", "U-shaped test level 3, success in %: eval --family (left and right tiles), "
                  "eval --mesh of the exported left tile (importer's route), eval --suite of it "
                  "(procedural route and spawn), eval --mesh with the procedural route shifted a "
                  "third of the width left / right (u3_offset_<policy>.json where the offset step "
                  "ran, else the mesh step's)", "",
                  "| policy | family | mesh | case | offset left | offset right |",
                  "|---|---|---|---|---|---|", *u3]
    if code:
        lines += ["", "Code-suite staircases exported to STL, success in %: in the suite's atlas, "
                  "eval --mesh (importer's route), eval --suite of the export", "",
                  "| policy | case | suite | mesh | case alone |", "|---|---|---|---|---|", *code]
    return lines


def policy_names(arg: str) -> list[str]:
    """The names in a --policies / --mesh-policies list, each entered in POLICIES: NAME=FILE, a
    committed policy's name, or a folder under experiments/results/ (its policy.npz). A bare name
    that is none of these (an uncommitted run: 2026-11-28's mesh step found nothing and did not
    run) still fails main's check, naming it."""
    names = []
    for n in filter(None, arg.split(",")):
        name, sep, file = n.partition("=")
        if sep:
            POLICIES[name] = Path(file)
        elif name not in POLICIES:
            POLICIES[name] = RESULTS / name / "policy.npz"
        names.append(name)
    return names


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--steps", default="suite,mesh,alone,table")
    ap.add_argument("--policies", default=",".join(POLICIES),
                    help="for the suite step: names of committed policies or of folders under "
                    "experiments/results/ holding policy.npz, or NAME=FILE for another (e.g. one "
                    "trained in the same GPU command)")
    ap.add_argument("--mesh-policies", default=",".join(MESH_POLICIES), help="for the mesh step")
    ap.add_argument("--robots", type=int, default=1000, help="robots per case")
    ap.add_argument("--episode-s", type=float, default=30.0)
    ap.add_argument("--resolution", type=float, default=0.025)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--env", nargs="*", default=list(EVAL_PHYSICS), metavar="KEY=VALUE",
                    help="env overrides of every evaluation (default: %(default)s)")
    a = ap.parse_args()
    from mjx_stairs.study.specs import EvalSpec

    spec = EvalSpec(robots_per_level=a.robots, episode_length_s=a.episode_s, seed=a.seed,
                    resolution=a.resolution, env_overrides=tuple(a.env))
    a.out.mkdir(parents=True, exist_ok=True)
    names, mesh_names = policy_names(a.policies), tuple(policy_names(a.mesh_policies))
    steps = a.steps.split(",")
    # only the policies the chosen steps run (the default --policies list names every committed
    # one: a call that moved a results folder out of the tree to fit what it carries ran no
    # offset step for a missing suite policy, 2026-11-27)
    wanted = [*(names if "suite" in steps else ()),
              *(mesh_names if {"mesh", "offset"} & set(steps) else ())]
    missing = [f"{n} ({POLICIES[n]})" for n in wanted if not POLICIES[n].exists()]
    if missing:
        raise SystemExit(f"code_suite: no policy file for {', '.join(missing)}")
    t0 = time.time()
    for step, fn in (("suite", lambda: run_suite(a.out, names, spec)),
                     ("mesh", lambda: run_mesh(a.out, spec, mesh_names)),
                     ("alone", lambda: run_alone(a.out, spec)),
                     ("offset", lambda: run_offset(a.out, spec, mesh_names)),
                     ("table", lambda: write_table(a.out))):
        if step in steps:
            fn()
            print(f"[code_suite] {step} done at {time.time() - t0:.0f} s", flush=True)


if __name__ == "__main__":
    main()
