"""The fidelity table of issue 19: published policies in each MJX physics option (GPU) and in the
CPU MuJoCo ground truth (box stairs, default solver), from the same starting states.

  python experiments/gpu/fidelity.py mjx OUT [--robots 1000]           # GPU: every option
  JAX_PLATFORMS=cpu python experiments/gpu/fidelity.py gt OUT [--robots 200] [--workers 12]
  JAX_PLATFORMS=cpu python experiments/gpu/fidelity.py first OUT --robots 32 --cells 3,8,15 \
      --options reference,lean,nearest_full,mjx_converged,columns,evaluation
All take --resolution (grid, m) and --cells (indices into CELLS); gt takes --terrain
boxes|heightfield (heightfield: CPU MuJoCo on the very heightfield MJX sees) and --timeconst
(every geom's contact solref time constant: by default the evaluation physics's 0.01, the option
evaluation_stiff; 0 for go2.xml's 0.02, the option evaluation_exit). `first`: from the
same states on the stairs (the policy's, after 2 s in the ground truth) the same actions for one
second in the ground truth and, replayed open-loop, in each option (study.ground_truth.
first_second): base position error and net vertical contact force, per cell and policy.

Both write JSON under OUT (one file per MJX option, one per ground-truth cell), each file as soon
as it is complete, so a run cut short keeps what it finished.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import time
from pathlib import Path

POLICIES = {
    "stage2_u": "experiments/results/stage2_u/policy.npz",
    "stage2_u_lean": "experiments/results/stage2_u_lean/policy.npz",
}
RQ1_POLICIES = {n: f"experiments/results/{n}/policy.npz" for n in (
    "stage2_u_paper", "stage2_u_paper_s1", "stage2_u_paper_s2", "stage2_u_paper_no_stall_s0",
    "stage2_u_paper_no_stall_s1", "stage2_u_paper_no_stall_s2")}
"""Issue 21's paper-setting policies: for `gt --policies` (not in the fidelity table)."""
OTHER_POLICIES = {  # for `gt --policies` (not in the fidelity table)
    "time_to_climber": "experiments/results/time_to_climber/stage2/policy.npz",  # issue 22
    "stage2_u_evaluation_exit_s0": "experiments/results/stage2_u_evaluation_exit_s0/policy.npz",
    # issue 19's next step (docs/results.md 8q): stage 2 trained at the stiffer contact (run.sh
    # PHYSICS_OPTION=evaluation_stiff,stage2-physics, SEED 0 and 1), for `gt --timeconst 0.01`
    **{f"stage2_u_evaluation_stiff_s{s}": f"experiments/results/stage2_u_evaluation_stiff_s{s}/"
       "policy.npz" for s in (0, 1)},
}
KNOWN_POLICIES = {**POLICIES, **RQ1_POLICIES, **OTHER_POLICIES}
OPTIONS = {  # env overrides of each physics option
    "reference": ("robot.terrain_contacts=mjx", "robot.shin_collision=true",
                  "robot.ls_iterations=5"),
    "lean": ("robot.terrain_contacts=nearest", "robot.shin_collision=false",
             "robot.ls_iterations=3"),
    "nearest_full": ("robot.terrain_contacts=nearest", "robot.shin_collision=true",
                     "robot.ls_iterations=5"),
    # MJX's collider with a solver run near convergence: tells the solver from the collider
    "mjx_converged": ("robot.terrain_contacts=mjx", "robot.shin_collision=true",
                      "robot.solver_iterations=8", "robot.ls_iterations=10"),
    # the ground truth's own geometry (grid cells as flat-topped columns, vertical risers)
    "columns": ("robot.terrain_contacts=columns", "robot.shin_collision=true",
                "robot.ls_iterations=5"),
    "columns_converged": ("robot.terrain_contacts=columns", "robot.shin_collision=true",
                          "robot.solver_iterations=8", "robot.ls_iterations=10"),
    # the evaluation physics as published to 2026-11-24 (mjx_eval/): columns_converged
    "evaluation": ("robot.physics=evaluation_top",),
    # the same, a sunk sphere centre pushed out through the nearest exposed face of its column
    # (issue 19, experiments/gt_sunk_exit.py): the evaluation physics 2026-11-25 to 11-28
    # (mjx_evaluation_exit/), the preset robot.physics=evaluation_soft
    "evaluation_exit": ("robot.physics=evaluation_soft",),
    # the same with every geom's contact solref time constant at 0.01 s in place of go2.xml's
    # 0.02 (robot.contact_timeconst; issue 19's spiral study): judged against the ground truth
    # run with the same contact (`gt --timeconst 0.01`), not the default one; the evaluation
    # physics since 2026-11-28 (mjx_evaluation_stiff/), the preset robot.physics=evaluation
    "evaluation_stiff": ("robot.physics=evaluation", "robot.contact_timeconst=0.01"),
    # issue 22's "faster collision for what is missing": the calves as collision geometry
    # (robot.calf_collision, eleven spheres more per calf along its bow; sim.geoms; eight along
    # the axis when bench-options measured it, 2026-11-29), in the evaluation physics
    # and in the fastest physics that kept the shin spheres (bench-options, stage2-physics)
    "evaluation_stiff_calf": ("robot.physics=evaluation", "robot.contact_timeconst=0.01",
                              "robot.calf_collision=true"),
    "nearest_full_calf": ("robot.terrain_contacts=nearest", "robot.shin_collision=true",
                          "robot.ls_iterations=5", "robot.calf_collision=true"),
    # the calves and thighs as the full robot's capsules, two contacts each (robot.limb_capsules,
    # sim.capsule; 2026-12-01), against the same limbs as sphere chains (two contacts a sphere)
    "evaluation_stiff_limbs": ("robot.physics=evaluation", "robot.contact_timeconst=0.01",
                               "robot.calf_collision=true", "robot.thigh_collision=true",
                               "robot.limb_capsules=true"),
    "evaluation_stiff_limb_chains": ("robot.physics=evaluation", "robot.contact_timeconst=0.01",
                                     "robot.calf_collision=true", "robot.thigh_collision=true"),
    "nearest_full_limbs": ("robot.terrain_contacts=nearest", "robot.shin_collision=true",
                           "robot.ls_iterations=5", "robot.calf_collision=true",
                           "robot.thigh_collision=true", "robot.limb_capsules=true"),
    # issue 22's candidates between "columns" (1 Newton iteration) and the evaluation physics
    # (8): is a few iterations' convergence enough? With today's evaluation physics's sunk rule
    # (nearest face; their speed, run.sh step bench-options, was measured 2026-11-25 with the
    # top rule, which costs the same: bench/h100_4096_options_*.json)
    "columns_n2": ("robot.terrain_contacts=columns", "robot.shin_collision=true",
                   "robot.solver_iterations=2", "robot.ls_iterations=5",
                   "robot.sunk_exit=nearest"),
    "columns_n3": ("robot.terrain_contacts=columns", "robot.shin_collision=true",
                   "robot.solver_iterations=3", "robot.ls_iterations=5",
                   "robot.sunk_exit=nearest"),
    "columns_n4": ("robot.terrain_contacts=columns", "robot.shin_collision=true",
                   "robot.solver_iterations=4", "robot.ls_iterations=8",
                   "robot.sunk_exit=nearest"),
    "columns_noshin_n3": ("robot.terrain_contacts=columns", "robot.shin_collision=false",
                          "robot.solver_iterations=3", "robot.ls_iterations=5",
                          "robot.sunk_exit=nearest"),
    # fewer line-search steps: under vmap MJX runs every one of them for every robot (a scan of
    # lax.cond, which vmap turns into both branches), so a Newton iteration costs about
    # ls_iterations line-search bodies whether or not the search has converged
    "columns_n4_ls3": ("robot.physics=evaluation_soft", "robot.solver_iterations=4",
                       "robot.ls_iterations=3"),
    "columns_n6_ls3": ("robot.physics=evaluation_soft", "robot.solver_iterations=6",
                       "robot.ls_iterations=3"),
    "columns_n8_ls3": ("robot.physics=evaluation_soft", "robot.solver_iterations=8",
                       "robot.ls_iterations=3"),
    # ... and with a 10 ms physics step (PD and contacts at 100 Hz, 2 steps per 20 ms policy
    # step, half the physics of every candidate above; issue 22)
    "evaluation_dt10": ("robot.physics=evaluation_soft", "robot.timestep=0.01", "decimation=2"),
    "columns_n4_dt10": ("robot.terrain_contacts=columns", "robot.shin_collision=true",
                        "robot.solver_iterations=4", "robot.ls_iterations=8",
                        "robot.sunk_exit=nearest", "robot.timestep=0.01", "decimation=2"),
    "columns_n3_dt10": ("robot.terrain_contacts=columns", "robot.shin_collision=true",
                        "robot.solver_iterations=3", "robot.ls_iterations=5",
                        "robot.sunk_exit=nearest", "robot.timestep=0.01", "decimation=2"),
}
CELLS = (
    [("u_shaped", "test", lv) for lv in range(6)]
    + [("u_shaped", "extended", lv) for lv in range(6)]
    + [("straight", "extended", lv) for lv in range(6)]
)


def write(path: Path, record: dict) -> None:
    from mjx_stairs.atomic import write_text

    write_text(path, json.dumps(record, indent=1))


def run_mjx(out: Path, robots: int, options: list[str], cells: list, res: float) -> None:
    """Every option on every cell; under JAX_ENABLE_X64=1 the physics runs in float64 (the
    policy in float32) and each option is recorded as '<option>_x64'."""
    import jax

    from mjx_stairs.rl.policy import load_policy
    from mjx_stairs.study.evaluate import CellSpec, success_by_cell

    policies = {k: load_policy(v) for k, v in POLICIES.items()}
    for name in options:
        t0 = time.time()
        spec = CellSpec(cells=tuple(cells), robots_per_cell=robots, env_overrides=OPTIONS[name],
                        resolution=res, physics="trained")
        result = success_by_cell(policies, spec)
        tag = "_x64" if jax.config.jax_enable_x64 else ""
        record = {"option": name + tag, "device": jax.devices()[0].device_kind,
                  "wall_s_with_compile": time.time() - t0, "policies": result}
        write(out / f"mjx_{name}{tag}.json", record)
        print(f"[fidelity] {name}: {time.time() - t0:.0f} s", flush=True)
        for p, r in result.items():
            print(p, name, [round(100 * s, 1) for s in r["success"]], flush=True)


def _gt_task(args) -> str:
    policy_name, cell, robots, out, res, terrain, seed, nthread, timeconst = args
    from mjx_stairs.rl.policy import load_policy
    from mjx_stairs.study.evaluate import CellSpec
    from mjx_stairs.study.ground_truth import success_in_ground_truth

    path = Path(out) / f"gt_{policy_name}_{cell[0]}_{cell[1]}_{cell[2] + 1}.json"
    if path.exists():
        return f"{path.name} (kept)"
    extra = (f"robot.contact_timeconst={timeconst}",)  # 0: go2.xml's (the preset's is 0.01)
    spec = CellSpec(cells=(cell,), robots_per_cell=robots, resolution=res, seed=seed,
                    env_overrides=OPTIONS["reference"] + extra)
    rec = success_in_ground_truth(load_policy(KNOWN_POLICIES[policy_name]), spec,
                                  nthread=nthread, terrain=terrain)
    rec.update(policy=policy_name, contact_timeconst=timeconst)
    write(path, rec)
    return f"{path.name}: {100 * rec['success'][0]:.1f} % ({rec['wall_s']:.0f} s)"


def run_gt(out: Path, robots: int, workers: int, cells: list, res: float, terrain: str,
           seed: int = 0, policies: tuple[str, ...] = tuple(POLICIES),
           timeconst: float = 0.0) -> None:
    """Each policy on each cell in CPU MuJoCo, one task per process; fewer tasks than workers:
    the spare workers become MuJoCo threads of each task. `timeconst`: every geom's contact
    solref time constant (robot.contact_timeconst; 0: go2.xml's 0.02, MJX's evaluation_exit;
    0.01: the evaluation physics's, MJX's evaluation_stiff)."""
    n = len(cells) * len(policies)
    nthread = max(1, workers // max(1, n))
    tasks = [(p, c, robots, str(out), res, terrain, seed, nthread, timeconst) for c in cells
             for p in policies]
    ctx = multiprocessing.get_context("spawn")
    with ctx.Pool(workers) as pool:
        for line in pool.imap_unordered(_gt_task, tasks):
            print("[gt]", line, flush=True)


def run_first(out: Path, robots: int, options: list[str], cells: list, res: float,
              policies: list[str]) -> None:
    from mjx_stairs.rl.policy import load_policy
    from mjx_stairs.study.evaluate import CellSpec
    from mjx_stairs.study.ground_truth import first_second

    for name in policies:
        policy = load_policy(POLICIES[name])
        for cell in cells:
            path = out / f"first_{name}_{cell[0]}_{cell[1]}_{cell[2] + 1}.json"
            if path.exists():
                continue
            t0 = time.time()
            spec = CellSpec(cells=(cell,), robots_per_cell=robots, resolution=res,
                            env_overrides=OPTIONS["reference"], physics="trained")
            rec = first_second(policy, spec, {o: OPTIONS[o] for o in options})
            rec.update(policy=name, wall_s=time.time() - t0)
            write(path, rec)
            print(f"[first] {path.name} ({time.time() - t0:.0f} s)", flush=True)
            for o, r in rec["options"].items():
                print(f"  {o}: base error at 1 s mean {100 * r['pos_error_at_horizon_mean_m']:.2f}"
                      f" cm, p90 {100 * r['pos_error_at_horizon_p90_m']:.2f} cm; |force diff| "
                      f"{r['force_abs_diff_mean_n']:.1f} N (GT mean "
                      f"{rec['gt_mean_vertical_force_n']:.1f} N)", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", choices=("mjx", "gt", "first"))
    ap.add_argument("out", type=Path)
    ap.add_argument("--robots", type=int, default=None)
    ap.add_argument("--workers", type=int, default=max(1, (os.cpu_count() or 2) - 2))
    ap.add_argument("--options", default="reference,lean,nearest_full")
    ap.add_argument("--resolution", type=float, default=0.025)
    ap.add_argument("--cells", default="", help="comma-separated indices into CELLS; '' = all")
    ap.add_argument("--policies", default=",".join(POLICIES), help="for first and gt")
    ap.add_argument("--seed", type=int, default=0, help="for gt: the robots' starts (as eval's)")
    ap.add_argument("--terrain", default="boxes", choices=("boxes", "heightfield"))
    ap.add_argument("--timeconst", type=float, default=None,
                    help="for gt: every geom's contact solref time constant (default: the "
                         "evaluation physics's, 0.01; 0: go2.xml's 0.02, evaluation_exit's)")
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    cells = [CELLS[int(i)] for i in a.cells.split(",")] if a.cells else CELLS
    if a.what == "first":
        run_first(a.out, a.robots or 32, a.options.split(","), cells, a.resolution,
                  a.policies.split(","))
    elif a.what == "mjx":
        run_mjx(a.out, a.robots or 1000, a.options.split(","), cells, a.resolution)
    else:
        os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false")
        if a.timeconst is None:
            from mjx_stairs.sim.robot import PHYSICS

            a.timeconst = PHYSICS["evaluation"]["contact_timeconst"]
        run_gt(a.out, a.robots or 200, a.workers, cells, a.resolution, a.terrain, a.seed,
               a.policies.split(","), a.timeconst)


if __name__ == "__main__":
    main()
