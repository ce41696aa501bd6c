"""Transfer between stair shapes: every model on every family, and the paper's transferability.

Transferability of a model trained on A to family B = S_A(B) / S_B(B), the success of A's model
on B over the success of B's own model on B, each averaged over test levels 3 and 4 (paper).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from mjx_stairs import atomic
from mjx_stairs.config import ConfigError, read_toml
from mjx_stairs.rl.policy import load_policy
from mjx_stairs.study import evaluate

PAPER_TABLE1 = {  # U-shaped model on each family, test levels 3 and 4 (%)
    "u_shaped": (91.3, 87.7),
    "straight": (98.0, 96.3),
    "l_shaped": (75.7, 72.1),
    "spiral": (44.7, 25.8),
}
PAPER_TABLE2 = {  # each family's model on U-shaped stairs, levels 3 and 4 (%)
    "straight": (2.0, 1.0),
    "l_shaped": (0.7, 2.0),
    "spiral": (1.7, 0.0),
}


def load_models(path: str | os.PathLike) -> dict[str, str]:
    """experiments/transfer_matrix.toml: a [models] table {family: policy path}."""
    path = Path(path)
    data = read_toml(path)
    models = data.get("models")
    if not isinstance(models, dict) or not models:
        raise ConfigError(f'{path}: needs a [models] table of family = "policy.npz"')
    import terrains

    for family, p in models.items():
        if family not in terrains.FAMILIES:
            raise ConfigError(f"{path}: models.{family}: unknown stair family")
        if not isinstance(p, str):
            raise ConfigError(f"{path}: models.{family}: expected a path string")
    return dict(models)


def _sha256(path: str | os.PathLike) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _finished_cell(path: Path, want: dict[str, Any]) -> dict[str, Any] | None:
    """The cell record at `path` if it was evaluated as `want` asks, else None (a file that is
    not a cell record counts as not finished: records are written whole, so only a foreign file
    can be one)."""
    try:
        rec = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(rec, dict) or any(rec.get(k) != v for k, v in want.items()):
        return None
    return rec


def matrix(
    models: dict[str, str], spec: evaluate.EvalSpec, out_dir: str | os.PathLike | None = None,
    rows: Sequence[str] = (), columns: Sequence[str] = (),
) -> dict[str, Any]:
    """Success of each model (rows) on each family (columns) at spec.levels; transferability.
    With `out_dir`, every (model, family) cell is written to out_dir/cells/ when it finishes and
    a cell finished there before (same policy file, levels, robots, physics, overrides) is
    reused: a matrix cut short resumes where it stopped. `rows` / `columns` (model and family
    names) restrict the run to those cells, e.g. one cell per GPU of a host: the part's cells
    are returned ({"cells": {model: {family: record}}}) and written, the matrix is not; a run
    over the same folder without them assembles it from the kept cells."""
    families = list(models)
    unknown = sorted((set(rows) | set(columns)) - set(families))
    if unknown:
        raise ConfigError(f"transfer matrix: {', '.join(unknown)} not among its models "
                          f"({', '.join(families)})")
    partial = bool(rows or columns)
    success: dict[str, dict[str, dict[str, Any]]] = {}
    cells = Path(out_dir) / "cells" if out_dir is not None else None
    for src, path in models.items():
        if rows and src not in rows:
            continue
        load = functools.cache(functools.partial(load_policy, path))  # once, if evaluated
        digest = _sha256(path)
        success[src] = {dst: _cell(src, dst, path, digest, load, spec, cells)
                        for dst in families if not columns or dst in columns}
    if partial:
        return {"cells": success}
    mean = {s: {d: float(np.mean(success[s][d]["success"])) for d in families} for s in families}
    transfer = transferability(mean)
    out = {
        "levels": [lv + 1 for lv in spec.levels],
        "models": models,
        "success": success,
        "mean_success": mean,
        "transferability": transfer,
        "paper": {"table1_u_model": PAPER_TABLE1, "table2_onto_u": PAPER_TABLE2},
        **({"env_overrides": list(spec.env_overrides)} if spec.env_overrides else {}),
    }
    if out_dir is not None:
        d = Path(out_dir)
        d.mkdir(parents=True, exist_ok=True)
        atomic.write_text(d / "transfer.json", json.dumps(out, indent=2))
        atomic.write_text(d / "transfer.md", markdown(out))
    return out


def _cell(src: str, dst: str, path: str, digest: str, load: Callable[[], Any],
          spec: evaluate.EvalSpec, cells: Path | None) -> dict[str, Any]:
    """One cell of the matrix: model `src` (policy file `path`, SHA-256 `digest`, `load()` its
    policy) on family `dst`, kept from cells/ when it was evaluated there as asked, else
    evaluated and written there. As asked includes the physics the preset resolves to today: a
    cell judged before a preset's name was given to other settings is evaluated again."""
    want = {"family": dst, "levels": [lv + 1 for lv in spec.levels],
            "robots_per_level": spec.robots_per_level,
            "episode_length_s": spec.episode_length_s, "seed": spec.seed,
            "eval_physics": spec.physics, "env_overrides": list(spec.env_overrides),
            "checkpoint": str(path), "checkpoint_sha256": digest}
    cell = cells / f"{src}__on__{dst}.json" if cells is not None else None
    if cell is not None:  # the settings as JSON holds them, as the record does
        want["physics_settings"] = json.loads(json.dumps(
            evaluate.physics_settings(evaluate.eval_config(load(), spec))))
    rec = _finished_cell(cell, want) if cell is not None else None
    if rec is not None:
        print(f"[transfer] {src} on {dst}: kept {cell}", flush=True)
        return rec
    rec = evaluate.success_by_level(load(), dataclasses.replace(spec, family=dst))
    rec.update(env_overrides=list(spec.env_overrides), checkpoint=str(path),
               checkpoint_sha256=digest)
    if cell is not None:
        cell.parent.mkdir(parents=True, exist_ok=True)
        atomic.write_text(cell, json.dumps(rec, indent=2))
    return rec


def transferability(mean: dict[str, dict[str, float]]) -> dict[str, dict[str, float]]:
    """S_model(stairs) / S_stairs-model(stairs) for every (model, stairs) pair of a square
    {model: {stairs: mean success}} table; NaN where the stairs' own model never succeeds."""
    return {
        s: {d: (mean[s][d] / mean[d][d] if mean[d][d] > 0 else float("nan")) for d in row}
        for s, row in mean.items()
    }


def markdown(result: dict[str, Any]) -> str:
    """The success matrix and the transferability matrix as Markdown tables."""
    fams = list(result["models"])
    lv = ", ".join(f"L{v}" for v in result["levels"])

    def table(values: dict[str, dict[str, float]]) -> list[str]:
        rows = ["| model \\ stairs | " + " | ".join(fams) + " |", "|---|" + "---|" * len(fams)]
        for s in fams:
            rows.append(f"| {s} | " + " | ".join(f"{100 * values[s][d]:.1f}" for d in fams) + " |")
        return rows

    lines = [f"Success (%), mean over test levels {lv}; rows: trained on, columns: tested on."]
    if result.get("env_overrides"):
        lines.append("Every model evaluated with " + ", ".join(result["env_overrides"]) + ".")
    lines.append("")
    lines += table(result["mean_success"])
    lines += ["", "Transferability S_model(stairs) / S_stairs-model(stairs):", ""]
    lines += table(result["transferability"])
    return "\n".join(lines) + "\n"


EXPERIMENTS = {
    "u_shaped": "stage2_u",
    "straight": "straight",
    "l_shaped": "l_shaped",
    "spiral": "spiral",
}
"""The experiment file that trains each family's model (experiments/<name>.toml)."""


def run_pipeline(spec: evaluate.EvalSpec, force: bool = False) -> dict[str, Any]:
    """Train every family's model that is not published yet (stage 1 first if needed), then the
    matrix. On the CPU the experiments run their [cpu] presets under results/cpu_preset/."""
    import jax

    from mjx_stairs.rl import runner
    from mjx_stairs.study import experiment

    cpu = jax.default_backend() == "cpu"
    models = {}
    for name in ("stage1",) + tuple(EXPERIMENTS.values()):
        config, _ = experiment.load(f"experiments/{name}.toml")
        dest = Path(config.publish_dir)
        if not (dest / "policy.npz").exists() or force:
            print(f"[transfer] {name}: training{' (CPU preset)' if cpu else ''}", flush=True)
            result = runner.run(config, experiment.make_env(config))
            experiment.publish(result.run_dir, dest, result.metrics, result.stop_reason)
        if name != "stage1":
            family = config.terrain.families[0]
            models[family] = str(dest / "policy.npz")
    if cpu:
        spec = dataclasses.replace(
            spec, robots_per_level=min(spec.robots_per_level, 8), resolution=0.05
        )
    out = Path(models["u_shaped"]).parent.parent / "transfer"
    result = matrix(models, spec, out)
    print(markdown(result), flush=True)
    return result
