"""An experiment = terrain + env + learner settings, loaded from experiments/*.toml.

A TOML file may inherit from another (``base = "stage2_u.toml"``: its tables are merged over the
base's) and name a physics preset (``[env.robot] physics = "lean"``, sim.robot.PHYSICS).

A TOML file may carry a `[cpu]` table of overrides (dotted keys, as on the command line) that is
applied when JAX runs on the CPU, so `make train-stage1` on a laptop runs a small preset that
finishes in minutes instead of the 4096-robot GPU run.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Literal

import jax

from mjx_stairs.config import ConfigError, apply_overrides, from_dict, merge_tables, read_toml_chain
from mjx_stairs.env.config import EnvConfig
from mjx_stairs.env.rewards import PRESETS
from mjx_stairs.env.stair_env import StairEnv
from mjx_stairs.rl.networks import NetworkConfig
from mjx_stairs.rl.ppo import PPOConfig
from mjx_stairs.rl.trainer import TrainConfig
from mjx_stairs.sim.robot import expand_physics_in


@dataclass(frozen=True)
class TerrainConfig:
    """Which tiles the atlas holds."""

    families: tuple[str, ...] = field(default=("pyramid",), metadata={"help": "stair families"})
    schedule: Literal["train", "test", "extended"] = field(
        default="train", metadata={"help": "the level table: train | test | extended"})
    levels: tuple[int, ...] = field(default=(), metadata={"help": "0-based levels; () = all"})
    variants_per_family: int = field(default=4, metadata={"help": "atlas columns per family"})
    variants: dict[str, int] = field(default_factory=dict, metadata={
        "help": "atlas columns of the families named, instead of variants_per_family"})
    directions: tuple[Literal["up", "down"], ...] = field(default=("up",), metadata={
        "help": "up | down | both: every column is followed by the same tile walked down, so "
                "a robot's level holds both directions"})
    seed: int = field(default=0, metadata={"help": "which building staircases the tiles are"})
    building_landing: tuple[float, ...] = field(default=(), metadata={
        "help": "[lo, hi] m: the landing depths of every building level (U, switchback, L) "
                "instead of each level's own range; () = the levels'"})
    resolution: float = field(default=0.025, metadata={"help": "grid spacing (m)"})
    tile_size: float = field(default=10.0, metadata={"help": "tile side (m)"})
    border: float = field(default=2.0, metadata={"help": "flat border around the atlas (m)"})

    def __post_init__(self):
        d = self.directions
        if not d or len(set(d)) != len(d):
            raise ConfigError(f"config key 'terrain.directions': expected 'up', 'down' or both, "
                              f"each once, got {list(d)}")
        if self.variants_per_family < 1:
            raise ConfigError("config key 'terrain.variants_per_family': must be >= 1, got "
                              f"{self.variants_per_family}")
        unknown = sorted(set(self.variants) - set(self.families))
        if unknown or min(self.variants.values(), default=1) < 1:
            raise ConfigError(f"config key 'terrain.variants': families of terrain.families "
                              f"with >= 1 column each, got {dict(self.variants)}")
        if self.building_landing:
            from terrains.levels import check_landing

            try:
                check_landing(self.building_landing, "config key 'terrain.building_landing'")
            except ValueError as e:
                raise ConfigError(str(e)) from None



@dataclass(frozen=True)
class ExperimentConfig:
    """Everything one training run needs."""

    terrain: TerrainConfig = field(default_factory=TerrainConfig)
    env: EnvConfig = field(default_factory=EnvConfig)
    ppo: PPOConfig = field(default_factory=PPOConfig)
    network: NetworkConfig = field(default_factory=NetworkConfig)
    train: TrainConfig = field(default_factory=TrainConfig)
    reward_preset: Literal["", "stage1", "stage2"] = field(
        default="", metadata={"help": "stage1 | stage2: start env.rewards from this preset"}
    )
    init_from: str = field(
        default="", metadata={"help": "policy file whose params and normaliser start this run"}
    )
    init_from_std: float = field(
        default=0.0, metadata={"help": "> 0: the exploration std (every action) that a run started "
                               "from init_from begins with, in place of the policy's own (0: keep)"}
    )
    publish_dir: str = field(
        default="", metadata={"help": "copy policy, metrics, config and run facts here at the end"}
    )

    def __post_init__(self):
        if self.init_from_std < 0 or (self.init_from_std and not self.init_from):
            raise ConfigError(f"config key 'init_from_std': a std > 0 for a run with init_from "
                              f"(0 keeps the policy's), got {self.init_from_std}"
                              f"{'' if self.init_from else ' without init_from'}")
        weights, families = self.env.curriculum.family_weights, self.terrain.families
        if weights and len(weights) != len(families):
            raise ConfigError(f"config key 'env.curriculum.family_weights': one weight per "
                              f"terrain.families entry ({len(families)}), got {len(weights)}")


def load(path: str | Path | None, overrides: Iterable[str] = (), cpu: bool | None = None):
    """Load an experiment; returns (config, applied_cpu_preset: bool).

    `reward_preset` replaces env.rewards by a preset before the file's own [env.rewards] entries
    and the overrides apply on top of it. With `cpu` None, the [cpu] table applies when JAX's
    default backend is the CPU.
    """
    data: dict[str, Any] = {}
    if path is not None:
        path = Path(path)
        data = _read_with_physics(path)
    cpu_table = data.pop("cpu", {})
    if cpu is None:
        cpu = jax.default_backend() == "cpu"
    overrides = list(overrides)
    if cpu and cpu_table:
        overrides = [f"{k}={_toml_literal(v)}" for k, v in _flatten(cpu_table)] + overrides
    for item in ("", *overrides):  # in order: a physics preset sets the fields it names
        data = _with_physics(apply_overrides(data, [item] if item else []))
    preset = data.get("reward_preset", "")
    if preset:
        if preset not in PRESETS:
            raise ConfigError(
                f"reward_preset: unknown preset {preset!r} (known: {sorted(PRESETS)})"
            )
        base = dataclasses.asdict(PRESETS[preset])
        env = data.setdefault("env", {})
        env["rewards"] = {**base, **env.get("rewards", {})}
    try:
        config = from_dict(ExperimentConfig, data)
    except ConfigError as e:
        raise ConfigError(f"{path}: {e}" if path else str(e)) from None
    return config, bool(cpu and cpu_table)


def _read_with_physics(path: Path) -> dict[str, Any]:
    """An experiment file merged over its bases, with the physics preset that the last file
    naming one names (``[env.robot] physics``) expanded there: the preset wins over the fields
    set beside it and in the bases before it, the fields of the files inheriting it win over
    the preset (until 2026-11-29 a base's preset won over them too)."""
    chain = read_toml_chain(path)

    def names_physics(table: dict[str, Any]) -> bool:
        robot = table.get("env", {}).get("robot", {}) if isinstance(table.get("env"), dict) else {}
        return isinstance(robot, dict) and "physics" in robot

    last = max((i + 1 for i, t in enumerate(chain) if names_physics(t)), default=0)
    return merge_tables([_with_physics(merge_tables(chain[:last])), *chain[last:]])


def _with_physics(data: dict[str, Any]) -> dict[str, Any]:
    """``env.robot.physics = "reference" | "lean"`` replaced by the settings it names."""
    if isinstance(data.get("env"), dict):
        data = {**data, "env": expand_physics_in(data["env"], "robot")}
    return data


def build_atlas(terrain: TerrainConfig):
    """The atlas a TerrainConfig describes (one terrains.build_atlas, or one per family joined
    side by side when `terrain.variants` gives families different numbers of columns)."""
    import terrains

    counts = {f: terrain.variants.get(f, terrain.variants_per_family) for f in terrain.families}
    kwargs = dict(schedule=terrain.schedule, levels=list(terrain.levels) or None,
                  resolution=terrain.resolution, tile_size=terrain.tile_size,
                  border=terrain.border)
    if terrain.directions != ("up",):
        both = len(terrain.directions) == 2
        kwargs.update(direction="both" if both else terrain.directions[0])
    if terrain.seed:
        kwargs.update(seed=terrain.seed)
    if terrain.building_landing:
        kwargs.update(building_landing=terrain.building_landing)
    if len(set(counts.values())) == 1:
        return terrains.build_atlas(terrain.families, variants_per_family=counts[
            terrain.families[0]], **kwargs)
    return terrains.join_columns([terrains.build_atlas([f], variants_per_family=n, **kwargs)
                                  for f, n in counts.items()])


def make_env(config: ExperimentConfig) -> StairEnv:
    """Atlas + env of an experiment."""
    return StairEnv(build_atlas(config.terrain), config.env)


def publish(run_dir: str | Path, dest: str | Path, record: dict[str, Any], stop: str) -> None:
    """Copy a run's policy, metrics and config to `dest` and write run.json (hardware, wall
    time, env steps, steps/s). Each file is written through a temporary name and a rename."""
    import json
    import platform

    from mjx_stairs import atomic
    from mjx_stairs.rl import logger

    run_dir, dest = Path(run_dir), Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    for name in ("policy.npz", "metrics.jsonl", "config.json"):
        atomic.copy_file(run_dir / name, dest / name)
    rows = logger.read_jsonl(run_dir / "metrics.jsonl")
    rates = [r["perf/steps_per_s"] for r in rows[1:]] or [r["perf/steps_per_s"] for r in rows]
    facts = {
        "run_dir": str(run_dir),
        "device": jax.devices()[0].device_kind,
        "devices": len(jax.devices()),
        "processes": jax.process_count(),
        "backend": jax.default_backend(),
        "host": platform.node(),
        "jax": jax.__version__,
        "iterations": record.get("iteration"),
        "env_steps": record.get("env_steps"),
        "wall_time_s": record.get("wall_time"),
        "compile_s": record.get("perf/compile_s"),
        "steps_per_s_median": sorted(rates)[len(rates) // 2] if rates else None,
        "stop_reason": stop,
        "final": {k: record.get(k) for k in ("episode/return", "level", "at_top", "success")},
    }
    atomic.write_text(dest / "run.json", json.dumps(facts, indent=2))


def _flatten(table: dict, prefix: str = ""):
    for k, v in table.items():
        key = f"{prefix}.{k}" if prefix else k
        if isinstance(v, dict):
            yield from _flatten(v, key)
        else:
            yield key, v


def _toml_literal(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return '"' + v.replace('"', '\\"') + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_literal(x) for x in v) + "]"
    return repr(v)
