"""What play rolls out: a plain dataclass (no JAX, no MuJoCo), so the CLI builds its flags from
it before play chooses the OpenGL backend."""

from __future__ import annotations

import dataclasses
from dataclasses import field
from typing import Literal


@dataclasses.dataclass(frozen=True)
class PlaySpec:
    """What to roll out (cli.py generates the play command's flags from these fields)."""

    family: str = field(default="u_shaped", metadata={"help": "stair family"})
    level: int = field(default=0, metadata={"help": "level of the schedule", "one_based": True})
    schedule: Literal["train", "test", "extended"] = field(
        default="test", metadata={"help": "the level table"})
    robots: int = field(default=4, metadata={"help": "robots on the tile"})
    seconds: float = field(default=10.0, metadata={"help": "rollout length (s)"})
    seed: int = field(default=0, metadata={"help": "seed of the robots' resets"})
    episode_length_s: float = field(
        default=20.0, metadata={"help": "episode length (s; auto-reset after it)",
                                "flag": "--episode-s"})
    resolution: float = field(default=0.025, metadata={"help": "terrain grid (m)"})
    tile_size: float = field(default=10.0, metadata={"help": "tile side (m)"})
    border: float = field(default=2.0, metadata={"help": "flat border around the tile (m)"})
    env_overrides: tuple[str, ...] = field(
        default=(),
        metadata={"flag": "--env", "metavar": "KEY=VALUE",
                  "help": "override the policy's env config, keys under [env] (as eval's --env)"})
