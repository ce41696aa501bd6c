"""What an evaluation runs on: a plain dataclass (no JAX), so the CLI builds its flags from it
without importing the simulator."""

from __future__ import annotations

import dataclasses
from dataclasses import field
from typing import Literal

EVAL_PHYSICS = "evaluation"
"""The physics preset (sim.robot.PHYSICS) every evaluation runs in unless told otherwise,
whatever physics the policy trained in; "trained" keeps the policy's own."""


@dataclasses.dataclass(frozen=True)
class EvalSpec:
    """What to evaluate one policy on. The `flag` metadata names the command-line flag (cli.py
    generates the eval, transfer-matrix and exp1-report flags from these fields)."""

    family: str = field(default="u_shaped", metadata={"help": "stair family"})
    schedule: Literal["train", "test", "extended"] = field(
        default="test", metadata={"help": "the level table"})
    direction: Literal["up", "down"] = field(
        default="up", metadata={"help": "walk the family's staircases up or down (the same "
                                "tiles; down: spawn on the top landing, goal at the foot; "
                                "--mesh and --suite cases carry their own)"})
    levels: tuple[int, ...] = field(
        default=(), metadata={"help": "levels, e.g. 1,2,3 (default all)", "one_based": True})
    robots_per_level: int = field(
        default=1000, metadata={"help": "robots per level", "flag": "--robots"})
    episode_length_s: float = field(
        default=20.0, metadata={"help": "evaluation episode length (s)", "flag": "--episode-s"})
    seed: int = field(default=0, metadata={"help": "seed of the robots' resets"})
    resolution: float = field(default=0.025, metadata={"help": "terrain grid (m)"})
    tile_size: float = field(default=10.0, metadata={"help": "tile side (m)"})
    physics: str = field(
        default=EVAL_PHYSICS,
        metadata={"help": "physics preset to evaluate in: evaluation (default; contact solref "
                  "0.01 s), evaluation_soft (the same at go2.xml's 0.02 s, as published "
                  "2026-11-25 to 11-28), evaluation_top (as published to 2026-11-24), reference, "
                  "lean, lean_implicit, or trained (the policy's own)"})
    env_overrides: tuple[str, ...] = field(
        default=(),
        metadata={"flag": "--env", "metavar": "KEY=VALUE",
                  "help": "override the policy's env config, keys under [env], e.g. "
                  "robot.physics=reference (evaluate in other physics than trained with)"})
