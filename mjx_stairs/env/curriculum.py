"""The terrain curriculum as device arrays: every robot keeps its own family, level and tile.

A robot's family is drawn once, at its first reset (uniformly, or by `family_weights`), and kept;
its tile is a random column of its family at its level, so an atlas built with both directions
(terrains.build_atlas(direction="both")) walks every level up and down under one level.

The rule (paper; thresholds from the authors' code): when a robot's episode ends it moves up one
level if it ended within `up_distance` of the goal (planar) and within `up_yaw` of the goal's
heading, otherwise down one level. A robot that clears the top level is sent to a random level,
and with `random_level_prob` any robot is, at that rate per episode (to a level from
`random_level_low` up).
Pure jnp functions on per-robot scalars, vmapped by the env with the robots.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from mjx_stairs.config import ConfigError


@dataclasses.dataclass(frozen=True)
class CurriculumConfig:
    """Curriculum settings."""

    enabled: bool = True  # update levels at episode ends (off in evaluation)
    up_distance: float = 0.8  # planar distance to goal (m) under which a robot moves up
    up_yaw: float = 0.4  # heading error (rad) under which a robot moves up
    initial_max_level: int = 1  # robots start uniformly in levels [0, initial_max_level]
    random_on_top: bool = True  # a robot that clears the top level goes to a random level
    # the chance that any robot's next level is a random one instead (0: the paper's rule alone).
    # Robots then train on levels above the one where half of them succeed, and walk down from
    # there one level per failed episode.
    random_level_prob: float = 0.0
    # the lowest level such a jump lands on (0: any level; e.g. 7: only the levels 7-9 of ten, the
    # building family's code-riser bands). A level above the atlas's top means its top level.
    random_level_low: int = 0
    # how often each family of the atlas is drawn, in its order (() = uniformly)
    family_weights: tuple[float, ...] = ()

    def __post_init__(self):
        if not 0.0 <= self.random_level_prob <= 1.0:
            raise ConfigError("config key 'env.curriculum.random_level_prob': must be in [0, 1], "
                              f"got {self.random_level_prob}")
        if self.random_level_low < 0:
            raise ConfigError("config key 'env.curriculum.random_level_low': must be >= 0, got "
                              f"{self.random_level_low}")
        w = self.family_weights
        if w and (min(w) < 0 or sum(w) <= 0):
            raise ConfigError("config key 'env.curriculum.family_weights': must be >= 0 with a "
                              f"positive sum, got {list(w)}")


# Config keys a resumed run cannot act on: what they set is drawn at a robot's first reset and kept
# in the env state a checkpoint holds (the runner's resume warning says so beside the change)
RESUME_INERT = {
    "env.curriculum.family_weights": "each robot keeps the family drawn at its first reset",
    "env.curriculum.initial_max_level": "it sets the level of a robot's first reset only",
}


class TileTable:
    """Per-family column tables of an atlas, as device arrays.

    `columns[f, k]` is the k-th atlas column holding family f (padded with its first column);
    `num_columns[f]` how many there are.
    """

    def __init__(self, family: np.ndarray, cols: int, num_families: int):
        family_of_col = np.asarray(family)[:cols]
        table = np.zeros((num_families, cols), np.int32)
        counts = np.zeros(num_families, np.int32)
        for c, f in enumerate(family_of_col):
            table[f, counts[f]] = c
            counts[f] += 1
        if np.any(counts == 0):
            missing = [int(f) for f in np.nonzero(counts == 0)[0]]
            raise ValueError(f"atlas has no column for family index {missing}")
        for f in range(num_families):
            table[f, counts[f] :] = table[f, 0]
        self.columns = jnp.asarray(table)
        self.num_columns = jnp.asarray(counts)
        self.cols = cols


def pick_family(rng: jax.Array, num_families: int, config: CurriculumConfig) -> jnp.ndarray:
    """[] int32 family index of a new robot, uniform or by `config.family_weights`."""
    if not config.family_weights:
        return jax.random.randint(rng, (), 0, num_families)
    if len(config.family_weights) != num_families:
        raise ConfigError(f"config key 'env.curriculum.family_weights': {num_families} weights "
                          f"needed (one per atlas family), got {len(config.family_weights)}")
    p = jnp.asarray(config.family_weights, jnp.float32)
    return jax.random.choice(rng, num_families, p=p / p.sum()).astype(jnp.int32)


def next_level(
    level: jnp.ndarray,
    moved_up: jnp.ndarray,
    num_levels: int,
    rng: jax.Array,
    config: CurriculumConfig,
) -> jnp.ndarray:
    """The level after an episode ends. Scalars (vmapped over robots).

    Args:
      level: [] int32 current level, 0-based.
      moved_up: [] bool, the robot ended close enough to the goal.
      num_levels: number of levels (static).
      rng: key for the random level of robots that clear the top (and of the random jumps).
    """
    up = jnp.minimum(level + 1, num_levels - 1)
    down = jnp.maximum(level - 1, 0)
    new = jnp.where(moved_up, up, down)
    if config.random_on_top:
        cleared_top = moved_up & (level == num_levels - 1)
        new = jnp.where(cleared_top, jax.random.randint(rng, (), 0, num_levels), new)
    if config.random_level_prob > 0.0:  # other keys: with 0 the stream is the rule's alone
        k_jump, k_level = jax.random.split(jax.random.fold_in(rng, 1))
        jump = jax.random.uniform(k_jump) < config.random_level_prob
        low = min(config.random_level_low, num_levels - 1)
        new = jnp.where(jump, jax.random.randint(k_level, (), low, num_levels), new)
    return new.astype(jnp.int32)


def reached(
    planar_distance: jnp.ndarray, yaw_error: jnp.ndarray, config: CurriculumConfig
) -> jnp.ndarray:
    """[] bool: the robot ended within the up thresholds of the goal."""
    return (planar_distance < config.up_distance) & (jnp.abs(yaw_error) < config.up_yaw)


def pick_tile(
    level: jnp.ndarray, family: jnp.ndarray, table: TileTable, rng: jax.Array
) -> jnp.ndarray:
    """[] int32 atlas tile of a robot of `family` at `level`: a random column of its family."""
    k = jax.random.randint(rng, (), 0, table.num_columns[family])
    col = table.columns[family, k]
    return (level * table.cols + col).astype(jnp.int32)
