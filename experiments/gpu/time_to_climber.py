"""Issue 22's end-to-end row: the wall time from nothing to a stage-2 climber, as a user runs it.

  python experiments/gpu/time_to_climber.py OUT [--stage1 experiments/stage1_lean.toml]
      [--stage2 experiments/stage2_u_lean.toml] [--stage1-iterations 600]
      [--stage2-iterations 290] [--set KEY=VALUE ...] [--robots 1000] [--log-dir DIR]

Runs, one after the other, each as its own `python -m mjx_stairs` process (so every compile, the
atlas builds and the interpreter starts are inside the time):
  1. train stage 1 (--stage1, --stage1-iterations) into OUT/stage1/;
  2. train stage 2 (--stage2, --stage2-iterations) from that stage-1 policy into OUT/stage2/;
  3. eval the stage-2 policy on the U-shaped test levels, --robots per level, in the evaluation
     physics (every eval's default) into OUT/eval/.
OUT/time_to_climber.json records the wall time of each step, the total of 1 + 2 (the time to a
trained climber) and of 1 + 2 + 3, the commands, the success per level and whether levels 1-4
reach --target (0.99, the issue's bar). --set adds overrides to both trainings (e.g.
network.conv_impl=fused_bf16). A CPU smoke run: JAX_PLATFORMS=cpu with the configs' [cpu] preset,
--stage1-iterations 2 --stage2-iterations 2 --robots 4.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

from mjx_stairs.atomic import write_text


def _run(cmd: list[str], log: Path) -> float:
    """Run ``cmd``, its output to ``log``; its wall time in seconds. A failure is fatal."""
    t0 = time.time()
    with open(log, "w") as f:
        rc = subprocess.run(cmd, stdout=f, stderr=subprocess.STDOUT).returncode
    if rc != 0:
        sys.exit(f"time_to_climber: {' '.join(cmd[:4])} ... failed (exit {rc}); see {log}")
    return time.time() - t0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--stage1", default="experiments/stage1_lean.toml")
    ap.add_argument("--stage2", default="experiments/stage2_u_lean.toml")
    ap.add_argument("--stage1-iterations", type=int, default=600)
    ap.add_argument("--stage2-iterations", type=int, default=290)
    ap.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE")
    ap.add_argument("--robots", type=int, default=1000)
    ap.add_argument("--target", type=float, default=0.99)
    ap.add_argument("--log-dir", type=Path, help="the trainings' run folders (default OUT/runs)")
    args = ap.parse_args(argv)
    out = args.out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    py = [sys.executable, "-m", "mjx_stairs"]
    common = ["train.progress=false", "train.console=false", "train.checkpoint_every=0",
              f"train.log_dir={args.log_dir or out / 'runs'}", *args.set]
    steps = {
        "stage1": py + ["train", args.stage1, f"train.total_iterations={args.stage1_iterations}",
                        f"publish_dir={out / 'stage1'}", "train.experiment=ttc_stage1", *common],
        "stage2": py + ["train", args.stage2, f"train.total_iterations={args.stage2_iterations}",
                        f"init_from={out / 'stage1' / 'policy.npz'}",
                        f"publish_dir={out / 'stage2'}", "train.experiment=ttc_stage2", *common],
        "eval": py + ["eval", "--checkpoint", str(out / "stage2" / "policy.npz"),
                      "--family", "u_shaped", "--robots", str(args.robots),
                      "--out", str(out / "eval")],
    }
    wall = {}
    for name, cmd in steps.items():
        print(f"== {name}: {' '.join(cmd[2:])}", flush=True)
        wall[name] = round(_run(cmd, out / f"{name}.log"), 1)
        print(f"   {wall[name]} s", flush=True)
    (result,) = json.loads((out / "eval" / "results.json").read_text())
    success = result["success"]
    runs = {n: json.loads((out / n / "run.json").read_text()) for n in ("stage1", "stage2")}
    record = {
        "wall_s": wall,
        "time_to_climber_s": round(wall["stage1"] + wall["stage2"], 1),
        "with_eval_s": round(sum(wall.values()), 1),
        "success": success,
        "levels": result["levels"],
        "target": args.target,
        "levels_1_4_reach_target": all(s >= args.target for s in success[:4]),
        "train": {n: {k: r.get(k) for k in ("iterations", "env_steps", "wall_time_s", "compile_s",
                                             "steps_per_s_median", "device")}
                  for n, r in runs.items()},
        "eval_physics": result.get("eval_physics"),
        "physics_settings": result.get("physics_settings"),
        "commands": {n: " ".join(c[2:]) for n, c in steps.items()},
    }
    write_text(out / "time_to_climber.json", json.dumps(record, indent=1) + "\n")
    print(json.dumps({k: record[k] for k in ("wall_s", "time_to_climber_s", "success",
                                             "levels_1_4_reach_target")}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
