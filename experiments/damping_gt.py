"""Issue 25: a policy at the Go2 description's joint damping, MJX against MuJoCo itself.

    JAX_PLATFORMS=cpu PYTHONPATH=. python experiments/damping_gt.py OUT \
        --policy experiments/results/generalist/policy.npz --cell u_shaped:test:6 \
        --robots 200 --configs d0.1,d2,d2i --what mjx,gt

Each config sets the joints' passive damping (d2: 2 N m s/rad) and how it is integrated (a
trailing i: implicitly, `robot.implicit_damping=true`; else explicitly, as go2.xml and training
do). For each config: `mjx` evaluates the policy in MJX, the evaluation physics
(`study.evaluate.success_by_cell`), `gt` in the CPU MuJoCo ground truth (box stairs, default
solver: `study.ground_truth.success_in_ground_truth`), both from the same starts (seed). One JSON
per (what, config) under OUT, skipped when there; each keeps every robot's outcome, so two
configs compare episode by episode. Then OUT/table.md. Every evaluation runs in a process of
its own, --jobs of them at once (one compiled program per process; the committed tables ran
with XLA_FLAGS="--xla_cpu_use_fusion_emitters=false --xla_backend_optimization_level=1", as
make's CPU targets, but for damping/generalist_u_test_6/mjx_d2.json, at XLA's defaults).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

GRID = [f"d{d}i" + (f"_l{ms}" if ms else "") for d in ("0.1", "0.5", "1", "2")
        for ms in (0, 5, 10, 15, 20)]  # docs/deploy.md's grid of damping and action delay


def parse(config: str) -> tuple[tuple[str, ...], int | None]:
    """d<damping>[i][_l<ms>][_n<iterations>][_c<contacts>] -> (env overrides, contacts): e.g. d2
    (explicit), d2i (implicit), d2i_l20 (and a fixed 20 ms action delay, robot.action_delay_s, in
    MJX and the ground truth alike), d2i_n30 (the solver given 30 Newton iterations: MJX's instead
    of the evaluation physics' 8, the ground truth's instead of MuJoCo's default 100, there with
    the evaluation physics' line-search steps too: `gt_solver`), d2i_c3
    (MJX's columns collider with 3 contacts a sphere instead of 2,
    `sim.contact.set_columns_ncon`; the ground truth has one contact per box touched)."""
    base, *parts = config.split("_")
    implicit = base.endswith("i")
    opts = {p[:1]: p[1:] for p in parts}  # l<ms>, n<iterations>, c<contacts>, each at most once
    try:
        if (not base.startswith("d") or len(opts) != len(parts)
                or not set(opts) <= {"l", "n", "c"}):
            raise ValueError
        damping = float(base[1:-1] if implicit else base[1:])
        delay_ms = float(opts["l"]) if "l" in opts else 0.0
        iterations = int(opts["n"]) if "n" in opts else None
        contacts = int(opts["c"]) if "c" in opts else None
        if contacts is not None and contacts < 2:  # sim.contact.NCON, the least
            raise ValueError
    except ValueError:
        raise SystemExit(f"config {config!r}: expected d<damping>[i][_l<ms>][_n<iterations>]"
                         "[_c<contacts>], e.g. d2, d2i, d2i_l20, d2i_n30 or d2i_c3") from None
    out = (f"robot.joint_damping={damping}", f"robot.implicit_damping={str(implicit).lower()}")
    if delay_ms:
        out += (f"robot.action_delay_s={delay_ms / 1000}",)
    if iterations is not None:
        out += (f"robot.solver_iterations={iterations}",)
    return out, contacts


def gt_solver(config: str):
    """The ground truth's solver for a config name: MuJoCo's default, or with _n<iterations> that
    many Newton iterations and the evaluation physics' line-search steps (MJX's budget, e.g.
    d2i_n8: the ground truth run with what MJX's evaluation physics runs)."""
    from mjx_stairs.sim import box_world as bw
    from mjx_stairs.sim.robot import PHYSICS

    n = dict(p.split("=") for p in parse(config)[0]).get("robot.solver_iterations")
    if n is None:
        return bw.DEFAULT_SOLVER
    return bw.SolverConfig(iterations=int(n), ls_iterations=PHYSICS["evaluation"]["ls_iterations"])


def overrides(config: str) -> tuple[str, ...]:
    """The env overrides of a config name (`parse`)."""
    return parse(config)[0]


def run(out: Path, policy_path: str, cell: tuple, robots: int, seed: int, config: str,
        what: str) -> dict:
    from mjx_stairs.rl.policy import load_policy
    from mjx_stairs.study.evaluate import CellSpec, success_by_cell
    from mjx_stairs.study.ground_truth import success_in_ground_truth

    path = out / f"{what}_{config}.json"
    if path.is_file():
        return json.loads(path.read_text())
    env_overrides, contacts = parse(config)
    if contacts is not None:  # this process only (a fresh one per config and what)
        from mjx_stairs.sim import contact
        contact.set_columns_ncon(contacts)
    policy = load_policy(policy_path)
    spec = CellSpec(cells=(cell,), robots_per_cell=robots, seed=seed,
                    env_overrides=env_overrides)
    t0 = time.time()
    rec = (success_by_cell({"p": policy}, spec)["p"] if what == "mjx"
           else success_in_ground_truth(policy, spec, solver=gt_solver(config)))
    rec.update(policy=policy_path, config=config, overrides=list(env_overrides),
               columns_contacts=contacts,
               wall_s_total=time.time() - t0)
    from mjx_stairs.atomic import write_text

    write_text(path, json.dumps(rec, indent=1))
    return rec


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--policy", required=True)
    ap.add_argument("--cell", default="u_shaped:test:6", help="family:schedule:level (1-based)")
    ap.add_argument("--robots", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--configs", default="d0.1,d2,d2i",
                    help="comma-separated d<damping>[i][_l<ms>], or 'grid': damping 0.1 / 0.5 / "
                         "1 / 2 (implicit) x delay 0 / 5 / 10 / 15 / 20 ms")
    ap.add_argument("--what", default="mjx,gt")
    ap.add_argument("--jobs", type=int, default=1,
                    help="configs run at once, each in its own process (a host's spare cores)")
    a = ap.parse_args()
    family, schedule, level = a.cell.split(":")
    cell = (family, schedule, int(level) - 1)
    a.out.mkdir(parents=True, exist_ok=True)
    rows = ["| config | " + " | ".join(a.what.split(",")) + " |",
            "|---|" + "---|" * len(a.what.split(","))]
    configs = GRID if a.configs == "grid" else a.configs.split(",")
    for config in configs:
        overrides(config)  # a bad name fails here, before anything runs
    whats = a.what.split(",")
    # a fresh process for each (config, what), --jobs at once (a JAX process keeps what it
    # compiled); results are printed in the table's order
    with ProcessPoolExecutor(a.jobs, mp_context=multiprocessing.get_context("spawn"),
                             max_tasks_per_child=1) as pool:
        futures = {(c, w): pool.submit(run, a.out, a.policy, cell, a.robots, a.seed, c, w)
                   for c in configs for w in whats}
        for config in configs:
            row = []
            for what in whats:
                r = futures[config, what].result()
                s, f = 100 * r["success"][0], 100 * r["fell"][0]
                print(f"{what} {config}: {s:.1f} % success, {f:.1f} % falls "
                      f"({r['wall_s_total']:.0f} s)", flush=True)
                row.append(f"{s:.1f} ({f:.1f})")
            rows.append(f"| {config} | " + " | ".join(row) + " |")
    note = (f"\nsuccess % (falls %), {a.robots} robots, seed {a.seed}, {a.cell}, policy "
            f"{a.policy}; mjx: the evaluation physics; gt: CPU MuJoCo on box stairs. d<x>: joint "
            f"damping x N m s/rad integrated explicitly, d<x>i: implicitly; _l<ms>: a fixed action "
            f"delay.\n")
    (a.out / "table.md").write_text("\n".join(rows) + "\n" + note)
    print("\n".join(rows) + note)


if __name__ == "__main__":
    main()
