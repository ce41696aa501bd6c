"""The paper's EXP1 from trained policies: Figure 2, the stall-penalty ablation, Figure 4.

- Figure 2: U-shaped success against the 6 test levels, the paper's points overlaid.
- Ablation (RQ1): stage 2 with and without the stall penalty, success per level side by side.
- Figure 4: the critic's value over the U-shaped tile on an x-y grid.
Writes exp1.json, exp1.md and the PNGs into one directory (atomically, file by file).
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path
from typing import Any

from mjx_stairs import atomic
from mjx_stairs.rl.policy import load_policy
from mjx_stairs.study import evaluate, plots
from mjx_stairs.study.critic_map import critic_map

PAPER_U_SUCCESS = {3: 91.3, 4: 87.7}
"""Paper, Table 1: U-shaped model on U-shaped stairs, test levels 3 and 4 (%)."""


def report(
    stage2: str | os.PathLike,
    out_dir: str | os.PathLike,
    ablation: str | os.PathLike | None = None,
    spec: evaluate.EvalSpec | None = None,
    critic_level: int = 3,
) -> dict[str, Any]:
    """Evaluate the stage-2 policy (and the no-stall ablation) on the U-shaped test levels."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    spec = dataclasses.replace(spec or evaluate.EvalSpec(), family="u_shaped", schedule="test")
    policies = {"stage 2 (stall penalty)": stage2}
    if ablation:
        policies["stage 2, no stall penalty"] = ablation
    results = {}
    for name, path in policies.items():
        policy = load_policy(path)
        if evaluate.env_config_of(policy).goal_mode == "waypoint":
            name += ", waypoint goal"
        r = evaluate.success_by_level(policy, spec)
        r["checkpoint"] = str(path)
        results[name] = r
    plots.plot_success(results, out / "fig2_u_success.png", paper=PAPER_U_SUCCESS)
    m = critic_map(
        load_policy(stage2),
        "u_shaped",
        critic_level - 1,
        resolution=spec.resolution,
        tile_size=spec.tile_size,
    )
    plots.plot_critic_map(
        m, out / "fig4_critic_u.png", f"critic value, U-shaped test level {critic_level}"
    )
    summary = {"spec": dataclasses.asdict(spec), "results": results, "paper": PAPER_U_SUCCESS}
    atomic.write_text(out / "exp1.json", json.dumps(summary, indent=2))
    atomic.write_text(out / "exp1.md", markdown(results))
    print(markdown(results), flush=True)
    return summary


def markdown(results: dict[str, dict[str, Any]]) -> str:
    """Success per level (%) for each policy, with the paper's figures where it gives them."""
    levels = next(iter(results.values()))["levels"]
    head = "| policy | " + " | ".join(f"L{lv}" for lv in levels) + " |"
    rows = [head, "|---|" + "---|" * len(levels)]
    for name, r in results.items():
        rows.append(f"| {name} | " + " | ".join(f"{100 * s:.1f}" for s in r["success"]) + " |")
    rows.append(
        "| paper (Table 1) | "
        + " | ".join(f"{PAPER_U_SUCCESS[lv]:.1f}" if lv in PAPER_U_SUCCESS else "" for lv in levels)
        + " |"
    )
    n = next(iter(results.values()))["robots_per_level"]
    rows.append(
        f"\nU-shaped test levels (risers 4-14 cm, width 2.0 m, landing 1.4 m); "
        f"{n} robots per cell, one episode each."
    )
    return "\n".join(rows) + "\n"


STAGES = ("stage1", "stage2_u", "stage2_u_no_stall")


def ablation_budget(stage2_run: str | os.PathLike) -> tuple[str, ...]:
    """Overrides that give the ablation the budget stage 2 actually had: the iteration count of
    its published run (a time-budgeted run stops before its config's total). None when stage 2
    has no run record, or when its run stopped at its config's own total."""
    p = Path(stage2_run)
    if not p.is_file():
        return ()
    facts = json.loads(p.read_text())
    if facts.get("stop_reason") == "total_iterations" or not facts.get("iterations"):
        return ()
    return (f"train.total_iterations={int(facts['iterations'])}",)


def run_pipeline(
    force: bool = False, robots: int | None = None, overrides: tuple[str, ...] = ()
) -> None:
    """The main job: train stage 1, stage 2 and the no-stall ablation (each skipped when its
    published policy exists, unless `force`), then write the EXP1 report.

    On the CPU every stage runs its [cpu] preset and the report uses 8 robots per level; the
    outputs then go under experiments/results/cpu_preset/ so they never mix with GPU results.
    """
    import jax

    from mjx_stairs.rl import runner
    from mjx_stairs.study import experiment

    cpu = jax.default_backend() == "cpu"
    published = {}
    for name in STAGES:
        extra = ()
        if name == "stage2_u_no_stall":
            extra = ablation_budget(published["stage2_u"].parent / "run.json")
        config, _ = experiment.load(f"experiments/{name}.toml", (*overrides, *extra))
        dest = Path(config.publish_dir)
        published[name] = dest / "policy.npz"
        if published[name].exists() and not force:
            print(f"[exp1] {name}: using {published[name]}", flush=True)
            continue
        print(f"[exp1] {name}: training{' (CPU preset)' if cpu else ''}", flush=True)
        result = runner.run(config, experiment.make_env(config))
        experiment.publish(result.run_dir, dest, result.metrics, result.stop_reason)
    out = published["stage2_u"].parent.parent / "exp1"
    n = robots or (8 if cpu else 1000)
    spec = evaluate.EvalSpec(robots_per_level=n, resolution=0.05 if cpu else 0.025)
    report(published["stage2_u"], out, published["stage2_u_no_stall"], spec)
    print(f"[exp1] report in {out}", flush=True)
