"""Evaluation: success rate per (policy, family, level).

Success (the protocol's rule, authors' code): planar distance to the goal < 0.5 m and speed
< 0.3 m/s, held 0.5 s, at any time within the evaluation episode. Evaluation runs the policy's
mean action with no observation noise, no domain randomisation and no trunk-contact ending (a
fall still ends the episode and fails). Every robot runs exactly one episode.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import os
import time
from pathlib import Path
from typing import Any, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from mjx_stairs import atomic
from mjx_stairs.config import ConfigError
from mjx_stairs.env.config import EnvConfig, env_config_from, evaluation_config
from mjx_stairs.env.stair_env import StairEnv
from mjx_stairs.rl.policy import Policy, load_policy, policy_action, saved_config
from mjx_stairs.sim.robot import PHYSICS
from mjx_stairs.study.specs import EVAL_PHYSICS, EvalSpec


def env_config_of(policy: Policy, overrides: Sequence[str] = ()) -> EnvConfig:
    """The EnvConfig the policy was trained with (robot, PD, obs layout), from its metadata,
    with ``overrides`` ("robot.physics=reference", ...) applied."""
    return env_config_from(saved_config(policy, "env"), overrides)


def eval_env(policy: Policy, atlas: Any, spec: Any) -> StairEnv:
    """The evaluation env of `policy` on `atlas`: the one place that decides it (for eval,
    transfer, exp1, cells, cases, the critic map and play). The policy's trained env config with
    `spec.env_overrides` applied, in evaluation settings (no noise, no randomisation, no
    trunk-contact ending, no curriculum), episodes of `spec.episode_length_s`; `spec` is an
    EvalSpec, CellSpec or tools' PlaySpec."""
    return StairEnv(atlas, eval_config(policy, spec))


def eval_config(policy: Policy, spec: Any) -> EnvConfig:
    """The env config `eval_env` builds its env from (`physics_settings` of it says what physics
    an evaluation of `policy` under `spec` runs in, before any env is built)."""
    overrides = physics_overrides(spec)
    cfg = keep_control_period(env_config_of(policy, overrides), env_config_of(policy), overrides)
    return evaluation_config(cfg, spec.episode_length_s)


def keep_control_period(cfg: EnvConfig, trained: EnvConfig,
                        overrides: Sequence[str] = ()) -> EnvConfig:
    """`cfg` with the physics steps per policy step (`decimation`) that keep `trained`'s control
    period (timestep x decimation), where a preset or override changed the physics step and no
    override names `decimation`: a policy trained at 10 ms x 2 runs at 5 ms x 4 in the
    evaluation physics, still at 50 Hz."""
    if any(o.split("=", 1)[0].strip() == "decimation" for o in overrides):
        return cfg
    period = trained.robot.timestep * trained.decimation
    steps = period / cfg.robot.timestep
    if abs(steps - round(steps)) > 1e-6 or round(steps) < 1:
        raise ConfigError(f"the policy's control period {period} s is not a whole number of "
                          f"{cfg.robot.timestep} s physics steps")
    return dataclasses.replace(cfg, decimation=int(round(steps)))


def physics_overrides(spec: Any) -> tuple[str, ...]:
    """The env overrides an evaluation runs with: the spec's physics preset (default
    specs.EVAL_PHYSICS; "trained": the policy's own), then `spec.env_overrides`."""
    physics = getattr(spec, "physics", EVAL_PHYSICS)
    preset = () if physics == "trained" else (f"robot.physics={physics}",)
    return preset + tuple(spec.env_overrides)


def make_eval_env(policy: Policy, spec: EvalSpec) -> tuple[StairEnv, Any]:
    """An evaluation env over an atlas of the spec's family: rows = levels, 2 columns, walked
    `spec.direction`."""
    import terrains

    levels = list(spec.levels) or list(range(len(terrains.levels(spec.family, spec.schedule))))
    atlas = terrains.build_atlas([spec.family], spec.schedule, levels, variants_per_family=2,
                                 resolution=spec.resolution, tile_size=spec.tile_size,
                                 direction=spec.direction)
    return eval_env(policy, atlas, spec), levels


def first_episodes(env: StairEnv, policy: Policy, state) -> tuple[jax.Array, ...]:
    """(finished, succeeded, fell, goal_step, end_step) [B] of each robot's first episode from
    `state`, the policy's mean action, over `env.episode_steps` steps (traceable: jit it).
    goal_step: the step (1-based) at which the success condition had held long enough, -1 if
    never; end_step: the step (1-based) that ended the first episode, -1 if none did."""

    def body(carry, k):
        st, finished, succeeded, fell, goal_step, end_step = carry
        st = jax.vmap(env.step)(st, policy_action(policy, st.obs["state"]))
        done = st.done > 0
        first = done & ~finished
        # after a done step info holds the next episode: its success is in the metrics
        now = jnp.where(done, st.metrics["episode_success"], st.info["success"]) > 0
        goal_step = jnp.where(~finished & now & (goal_step < 0), k + 1, goal_step)
        succeeded = succeeded | (first & (st.metrics["episode_success"] > 0))
        fell = fell | (first & (st.metrics["terminated"] > 0))
        end_step = jnp.where(first, k + 1, end_step)
        return (st, finished | done, succeeded, fell, goal_step, end_step), None

    zeros = jnp.zeros(state.done.shape, bool)
    never = jnp.full(state.done.shape, -1, jnp.int32)
    steps = jnp.arange(env.episode_steps, dtype=jnp.int32)
    return jax.lax.scan(body, (state, zeros, zeros, zeros, never, never), steps)[0][1:]


def fell_within(fell: np.ndarray, end_step: np.ndarray, steps: int, n_levels: int) -> list[float]:
    """Per level (robots row-major by level), the share of robots whose first episode ended in
    a fall by policy step `steps`: the falls of the first second with steps = 1 s / dt."""
    early = fell & (end_step > 0) & (end_step <= steps)
    return [float(v) for v in early.reshape(n_levels, -1).mean(1)]


def _check_finished(finished: np.ndarray) -> None:
    if not finished.all():
        raise RuntimeError("evaluation ended with robots still in their first episode")


def physics_settings(env: StairEnv | EnvConfig) -> dict[str, Any]:
    """The robot physics an evaluation ran in (the fields the evaluation preset sets), resolved
    from its preset: a record says what its numbers mean even after a preset's name is given to
    other settings. Of an env, or of the env config it is built from."""
    config = env.config if isinstance(env, StairEnv) else env
    robot = config.robot
    return {**{k: getattr(robot, k) for k in PHYSICS["evaluation"]},
            "decimation": config.decimation,
            # the robot's own, from the policy's config (or an override): not the preset's
            "joint_damping": robot.joint_damping, "implicit_damping": robot.implicit_damping,
            "head_collision": robot.head_collision, "calf_collision": robot.calf_collision,
            "thigh_collision": robot.thigh_collision, "limb_capsules": robot.limb_capsules,
            "action_delay_s": robot.action_delay_s,
            "pd_kd": robot.delayed_kd,  # the PD's damping gain at that delay (kd_per_delay)
            "contact_timeconst": robot.contact_timeconst}


def level_states(env: StairEnv, n_levels: int, spec: EvalSpec):
    """[n_levels * robots_per_level] robots on the env's level rows (row-major by level), reset
    from `spec.seed`: where `success_by_level` starts them (sim2sim's paired starts too)."""
    B = n_levels * spec.robots_per_level
    row = jnp.repeat(jnp.arange(n_levels, dtype=jnp.int32), spec.robots_per_level)
    keys = jax.random.split(jax.random.PRNGKey(spec.seed), B)
    return jax.jit(jax.vmap(env.reset_at))(keys, row, jnp.zeros(B, jnp.int32))


def success_by_level(policy: Policy, spec: EvalSpec) -> dict[str, Any]:
    """Run robots_per_level robots on every level for one episode each.

    Returns {"levels": [...1-based], "success": [...], "fell": [...], "robots": n, ...}.
    """
    env, levels = make_eval_env(policy, spec)
    n_levels = len(levels)
    state = level_states(env, n_levels, spec)
    t0 = time.time()
    finished, succeeded, fell, _, end_step = jax.device_get(
        jax.jit(lambda s: first_episodes(env, policy, s))(state))
    wall = time.time() - t0
    _check_finished(finished)
    succ = succeeded.reshape(n_levels, -1).mean(1)
    fall = fell.reshape(n_levels, -1).mean(1)
    return {
        "family": spec.family,
        "schedule": spec.schedule,
        "direction": spec.direction,
        "levels": [lv + 1 for lv in levels],
        "success": [float(s) for s in succ],
        "fell": [float(f) for f in fall],
        # falls in the first second: the gait setting off, not the stairs (docs/results.md 8ah)
        "fell_first_second": fell_within(fell, end_step, round(1.0 / env.dt), n_levels),
        "robots_per_level": spec.robots_per_level,
        "episode_length_s": spec.episode_length_s,
        "seed": spec.seed,
        "wall_s": wall,
        "device": jax.devices()[0].device_kind,
        "eval_physics": spec.physics,
        "physics_settings": physics_settings(env),
        **({"env_overrides": list(spec.env_overrides)} if spec.env_overrides else {}),
    }


# ----------------------------------------------------------------------------- cells


Cell = tuple[str, str, int]
"""(family, schedule, 0-based level): one staircase of the evaluation."""


@dataclasses.dataclass(frozen=True)
class CellSpec:
    """Policies on any list of cells, all under one compiled program."""

    cells: tuple[Cell, ...] = (("u_shaped", "test", 3),)
    robots_per_cell: int = 1000
    episode_length_s: float = 20.0
    seed: int = 0
    resolution: float = 0.025
    tile_size: float = 10.0
    physics: str = EVAL_PHYSICS  # see EvalSpec
    env_overrides: tuple[str, ...] = ()  # see EvalSpec


def schedule_cells(family: str, schedule: str, levels: Sequence[int] = ()) -> tuple[Cell, ...]:
    """The cells of `family`'s `schedule` (0-based `levels`; () = all)."""
    import terrains

    chosen = list(levels) or range(len(terrains.levels(family, schedule)))
    return tuple((family, schedule, int(lv)) for lv in chosen)


def cell_env(policy: Policy, spec: CellSpec) -> StairEnv:
    """The evaluation env of `policy` (its env config with the spec's overrides) over an atlas
    with one row per cell, two variants each."""
    import terrains

    return eval_env(policy, terrains.build_cell_atlas(spec.cells, 2, spec.resolution,
                                                      spec.tile_size), spec)


def initial_states(env: StairEnv, spec: CellSpec):
    """[cells * robots_per_cell] robots on their cells' spawns (row-major by cell)."""
    B = len(spec.cells) * spec.robots_per_cell
    row = jnp.repeat(jnp.arange(len(spec.cells), dtype=jnp.int32), spec.robots_per_cell)
    keys = jax.random.split(jax.random.PRNGKey(spec.seed), B)
    return jax.jit(jax.vmap(env.reset_at))(keys, row, jnp.zeros(B, jnp.int32))


def outcome_strings(success: np.ndarray, fell: np.ndarray, cells: int) -> list[str]:
    """Every robot's outcome, one string per cell of [cells * robots] robots: "s" succeeded,
    "f" fell, "-" neither (timed out). For paired comparisons of two physics from the same
    starts, where most episodes come out alike."""
    code = np.where(np.asarray(success, bool), "s", np.where(np.asarray(fell, bool), "f", "-"))
    return ["".join(row) for row in code.reshape(cells, -1)]


def cell_records(spec: CellSpec, success: np.ndarray, fell: np.ndarray, **extra) -> dict:
    """Per-cell success and falls of [cells * robots] outcomes, as a JSON-ready dict, with every
    robot's outcome (`outcome_strings`)."""
    shape = (len(spec.cells), spec.robots_per_cell)
    return {
        "cells": [{"family": f, "schedule": s, "level": lv + 1} for f, s, lv in spec.cells],
        "success": [float(v) for v in np.asarray(success).reshape(shape).mean(1)],
        "fell": [float(v) for v in np.asarray(fell).reshape(shape).mean(1)],
        "outcomes": outcome_strings(success, fell, len(spec.cells)),
        "robots_per_cell": spec.robots_per_cell,
        "episode_length_s": spec.episode_length_s,
        "seed": spec.seed,
        "eval_physics": spec.physics,
        "env_overrides": list(spec.env_overrides),
        **extra,
    }


def check_same_env(policies: dict[str, Policy], spec: EvalSpec | CellSpec) -> None:
    """ValueError unless every policy's evaluation env config (with the overrides) is the
    first's: one compiled program serves them all."""
    first = next(iter(policies))
    want = env_config_of(policies[first], physics_overrides(spec))
    for name, p in policies.items():
        if env_config_of(p, physics_overrides(spec)) != want:
            raise ValueError(f"policy {name!r} needs another env than {first!r}")


def run_policies(policies: dict[str, Policy], env: StairEnv, state):
    """Every policy's first episodes from `state` on `env`, one compiled program per network
    and observation layout. Yields (name, finished, succeeded, fell, goal_step, wall_s), arrays
    [B] on the host, the robots checked to have finished."""

    def run(st, params, norm, like):
        return first_episodes(env, like._replace(params=params, normalizer=norm), st)

    compiled: dict[Any, Any] = {}
    for name, p in policies.items():
        key = (p.network, p.layout, p.action_size)
        if key not in compiled:
            fn = jax.jit(functools.partial(run, like=p))
            compiled[key] = fn.lower(state, p.params, p.normalizer).compile()
        t0 = time.time()
        finished, succeeded, fell, goal_step, _ = jax.device_get(
            compiled[key](state, p.params, p.normalizer))
        _check_finished(finished)
        yield name, finished, succeeded, fell, goal_step, time.time() - t0


def success_by_cell(policies: dict[str, Policy], spec: CellSpec) -> dict[str, dict[str, Any]]:
    """Every policy on every cell of `spec`, MJX, one episode per robot, one compiled program
    for all policies (their env configs with the overrides must agree)."""
    check_same_env(policies, spec)
    env = cell_env(next(iter(policies.values())), spec)
    state = initial_states(env, spec)
    return {name: cell_records(spec, succeeded, fell, physics="mjx", wall_s=wall,
                               device=jax.devices()[0].device_kind,
                               physics_settings=physics_settings(env))
            for name, _, succeeded, fell, _, wall in run_policies(policies, env, state)}


def evaluate(
    checkpoints: Sequence[str | os.PathLike],
    families: Sequence[str],
    spec: EvalSpec,
    out_dir: str | os.PathLike | None = None,
) -> list[dict[str, Any]]:
    """Success per (checkpoint, family, level); writes results.json and results.md to out_dir,
    rewritten (atomically) after every (checkpoint, family), so that a run cut short keeps what
    it finished."""
    results = []
    out = Path(out_dir) if out_dir is not None else None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
    for path in checkpoints:
        policy = load_policy(path)
        for family in families:
            r = success_by_level(policy, dataclasses.replace(spec, family=family))
            r["checkpoint"] = str(path)
            r["policy_iteration"] = int(policy.metadata.get("iteration", -1))
            results.append(r)
            print(markdown_table([r]), flush=True)
            if out is not None:
                atomic.write_text(out / "results.json", json.dumps(results, indent=2))
                atomic.write_text(out / "results.md", markdown_table(results))
    return results


def markdown_table(results: Sequence[dict[str, Any]]) -> str:
    """One row per (checkpoint, family), one column per level, success in %."""
    levels = sorted({lv for r in results for lv in r["levels"]})
    head = "| checkpoint | family | " + " | ".join(f"L{lv}" for lv in levels) + " |"
    sep = "|---|---|" + "---|" * len(levels)
    rows = [head, sep]
    for r in results:
        by = dict(zip(r["levels"], r["success"], strict=True))
        cells = [f"{100 * by[lv]:.1f}" if lv in by else "" for lv in levels]
        path = Path(r.get("checkpoint", ""))  # a published run's dir/policy.npz: the dir
        name = (path.parent.name if path.name == "policy.npz" else path.stem) or str(path)
        if r.get("env_overrides"):
            name += " (" + ", ".join(r["env_overrides"]) + ")"
        if r.get("direction", "up") != "up":
            name += f", {r['direction']}"
        rows.append(f"| {name} | {r['family']} | " + " | ".join(cells) + " |")
    n = results[0]["robots_per_level"] if results else 0
    rows.append(f"\nSuccess in % of {n} robots per cell, one episode each.")
    return "\n".join(rows) + "\n"
