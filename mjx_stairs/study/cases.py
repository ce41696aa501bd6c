"""Evaluation on any staircase: a user's mesh (start, goal, optional route), a folder of cases
(a mesh beside a JSON of the same stem, terrains.cases), or a fixed suite (code, paper).

All cases of a run share one atlas, each case a row of one tile padded with wall to the largest
(a staircase bigger than the usual 10 m tile is not cropped), and one compiled program per
policy. Robot k of every case starts from the same key (split from the seed by robot, not by
case), so a case scores the same evaluated with others or alone, up to the float rounding of its
place in the atlas. One record per case: success, falls, timeouts, mean time to the goal.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from mjx_stairs import atomic
from mjx_stairs.rl.policy import Policy, load_policy
from mjx_stairs.study import evaluate
from mjx_stairs.study.specs import EvalSpec

Case = tuple[str, Any]
"""(name, terrains.Tile): one staircase walked one way."""


def suite_cases(suite: str, resolution: float = 0.025) -> list[Case]:
    """The cases of ``suite``: a folder of cases (mesh + JSON each), or the name of a fixed
    suite (terrains/suites.toml: code, paper; every case up and down); else ValueError."""
    from terrains.cases import read_case_folder
    from terrains.suites import load_suite, suite_names

    if os.path.isdir(suite):
        return read_case_folder(suite, resolution)
    if suite not in suite_names():
        raise ValueError(f"unknown suite {suite!r}: not a folder of cases, nor one of "
                         f"{', '.join(suite_names())}")
    return [(c.name, c.tile(resolution)) for c in load_suite(suite)]


def mesh_cases(mesh: str | os.PathLike, start, goal, route: str | os.PathLike | None = None,
               resolution: float = 0.025) -> list[Case]:
    """The one case of a staircase mesh: ``start``, ``goal`` (x, y[, yaw]) and the optional
    route file (x,y per line) in the mesh frame (terrains.cases.mesh_tile)."""
    from terrains.cases import mesh_tile, read_route_csv

    pts = None if route is None else read_route_csv(route)
    tile = mesh_tile(mesh, start, goal, pts, resolution)
    return [(Path(mesh).stem, tile)]


def from_flags(mesh: str | None, start: str | None, goal: str | None, route: str | None,
               suite: str | None, resolution: float = 0.025) -> list[Case] | None:
    """The cases of the command-line flags --mesh FILE --start X,Y[,YAW] --goal X,Y[,YAW]
    [--route FILE] or --suite DIR|NAME; None for neither; flags that do not go together ->
    ValueError."""
    from terrains.cases import parse_pose

    if mesh is None and (start or goal or route):
        raise ValueError("--start, --goal and --route go with --mesh FILE")
    if mesh is not None and suite is not None:
        raise ValueError("--mesh and --suite exclude each other")
    if suite is not None:
        return suite_cases(suite, resolution)
    if mesh is None:
        return None
    if start is None or goal is None:
        raise ValueError("--mesh needs --start x,y[,yaw] and --goal x,y[,yaw] (mesh frame)")
    return mesh_cases(mesh, parse_pose(start, "start"), parse_pose(goal, "goal"), route,
                      resolution)


def case_atlas(cases: Sequence[Case], border: float = 2.0):
    """The atlas of ``cases``: row r is case r's tile, padded with wall to the largest."""
    import terrains

    if not cases:
        raise ValueError("no cases to evaluate")
    return terrains.build_tile_atlas([[tile] for _, tile in cases], border)


def case_states(env, n_cases: int, robots: int, seed: int):
    """[n_cases * robots] robots on their cases' spawns (row-major by case); robot k of every
    case has key k of split(PRNGKey(seed), robots)."""
    keys = jax.random.split(jax.random.PRNGKey(seed), robots)
    keys = jnp.tile(keys, (n_cases, 1))
    row = jnp.repeat(jnp.arange(n_cases, dtype=jnp.int32), robots)
    return jax.jit(jax.vmap(env.reset_at))(keys, row, jnp.zeros_like(row))


def case_record(name: str, tile: Any, succeeded, fell, goal_step, dt: float) -> dict[str, Any]:
    """One case's outcome over its robots ([robots] arrays) as a JSON-ready dict; timeout: the
    robots that neither reached the goal nor fell; mean time to goal (s) over those that
    reached it, None if none did."""
    succeeded, fell = np.asarray(succeeded, bool), np.asarray(fell, bool)
    t = np.asarray(goal_step)[succeeded] * dt
    return {"name": name, "direction": tile.direction, "robots": int(succeeded.size),
            "success": float(succeeded.mean()), "fell": float(fell.mean()),
            "timeout": float((~succeeded & ~fell).mean()),
            "mean_time_to_goal_s": float(t.mean()) if t.size else None}


def success_by_case(policies: dict[str, Policy], cases: Sequence[Case],
                    spec: EvalSpec) -> dict[str, list[dict[str, Any]]]:
    """Every policy on every case, ``spec.robots_per_level`` robots per case, one episode each,
    in the evaluation env that ``spec`` decides (evaluate.eval_env; the policies' env configs
    with the overrides must agree). Returns {policy name: [record per case]}."""
    evaluate.check_same_env(policies, spec)
    env = evaluate.eval_env(next(iter(policies.values())), case_atlas(cases), spec)
    robots = spec.robots_per_level
    state = case_states(env, len(cases), robots, spec.seed)
    out = {}
    for name, _, succeeded, fell, goal_step, wall in evaluate.run_policies(policies, env, state):
        split = lambda a: np.asarray(a).reshape(len(cases), robots)
        s, f, g = split(succeeded), split(fell), split(goal_step)
        out[name] = [dict(case_record(n, t, s[i], f[i], g[i], env.dt), wall_s=wall)
                     for i, (n, t) in enumerate(cases)]
    return out


def evaluate_cases(checkpoints: Sequence[str | os.PathLike], cases: Sequence[Case],
                   spec: EvalSpec, out: str | os.PathLike | None = None,
                   source: str = "") -> dict[str, Any]:
    """Load the checkpoints, evaluate them on ``cases`` (policies that need another env than
    the first run in a program of their own), print a table per checkpoint and write the JSON
    to ``out`` atomically: {"results": [record per checkpoint and case], ...run facts}."""
    policies = {str(p): load_policy(p) for p in checkpoints}
    records = []
    for group in by_env(policies, spec):
        for ck, recs in success_by_case(group, cases, spec).items():
            print(f"\n{_label(ck)}\n" + case_table(recs), flush=True)
            records += [{"checkpoint": ck, **r} for r in recs]
    atlas_side = max(max(t.heights.shape) for _, t in cases) * spec.resolution
    result = {"source": source, "cases": len(cases), "robots_per_case": spec.robots_per_level,
              "episode_length_s": spec.episode_length_s, "seed": spec.seed,
              "resolution": spec.resolution, "tile_size": atlas_side,
              "eval_physics": spec.physics, "env_overrides": list(spec.env_overrides),
              "device": jax.devices()[0].device_kind, "results": records}
    if out is not None:
        atomic.write_text(out, json.dumps(result, indent=1))
        print(f"wrote {out}", flush=True)
    return result


def by_env(policies: dict[str, Policy], spec: EvalSpec) -> list[dict[str, Policy]]:
    """The policies grouped by their evaluation env config (in order of first appearance)."""
    groups: list[tuple[Any, dict[str, Policy]]] = []
    for name, p in policies.items():
        cfg = evaluate.env_config_of(p, evaluate.physics_overrides(spec))
        for c, g in groups:
            if c == cfg:
                g[name] = p
                break
        else:
            groups.append((cfg, {name: p}))
    return [g for _, g in groups]


def _label(checkpoint: str) -> str:
    p = Path(checkpoint)
    return p.parent.name if p.name == "policy.npz" else p.stem


def case_table(records: Sequence[dict[str, Any]]) -> str:
    """One markdown row per case: success, falls and timeouts in %, mean time to goal."""
    rows = ["| case | direction | robots | success % | fell % | timeout % | time to goal (s) |",
            "|---|---|---|---|---|---|---|"]
    for r in records:
        t = r["mean_time_to_goal_s"]
        rows.append(f"| {r['name']} | {r['direction']} | {r['robots']} | "
                    f"{100 * r['success']:.1f} | {100 * r['fell']:.1f} | "
                    f"{100 * r['timeout']:.1f} | {'-' if t is None else f'{t:.1f}'} |")
    return "\n".join(rows) + "\n"
