"""The height map as an elevation map delivers it, in the actor's stream only (env.noise, issue
24): a per-robot offset of every cell, and missing cells, anywhere, under the trunk (occluded
from the sensors) and beside step edges (where elevation maps lose returns). A missing cell reads
+clip: what a robot-side runner writes for a cell without data (tools/contract.py turns a NaN
terrain height into +clip), so the policy learns the value it will get. Off by default: the
draws use keys folded out of the step's noise key, so nothing else changes."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from mjx_stairs.env import observation
from mjx_stairs.env.config import EnvConfig, HeightMapConfig, NoiseConfig

BODY_HALF = (0.4, 0.2)
"""m: the cells under the trunk, |x| and |y| in the base's yaw frame at most these."""

EDGE_JUMP = 0.05
"""m: a cell beside a step edge differs by more than this from one of its 4 neighbours."""


def missing(noise: NoiseConfig) -> bool:
    """Whether any cell can be missing."""
    return max(noise.height_missing, noise.height_missing_body, noise.height_missing_edge) > 0


def draw(rng: jax.Array, config: EnvConfig) -> dict[str, jnp.ndarray]:
    """This episode's draws, each when configured: {"height_offset": [] (m), "missing_scale": []
    (the missing cells' chances times this, uniform in [0, 1])}."""
    noise = config.noise
    out = {}
    if noise.enabled and noise.height_offset > 0:
        o = noise.height_offset
        out["height_offset"] = jax.random.uniform(jax.random.fold_in(rng, 3), (), minval=-o,
                                                  maxval=o)
    if noise.enabled and noise.height_missing_per_episode and missing(noise):
        out["missing_scale"] = jax.random.uniform(jax.random.fold_in(rng, 5), ())
    return out


def body_cells(hm: HeightMapConfig) -> np.ndarray:
    """[size * size] bool: the cells under the trunk (rows along y, columns along x)."""
    half = 0.5 * (hm.size - 1) * hm.spacing
    axis = np.linspace(-half, half, hm.size)
    gx, gy = np.meshgrid(axis, axis, indexing="xy")
    return ((np.abs(gx) <= BODY_HALF[0] + 1e-6) & (np.abs(gy) <= BODY_HALF[1] + 1e-6)).ravel()


def edge_cells(clean: jnp.ndarray, size: int) -> jnp.ndarray:
    """[size * size] bool: the cells of the clean map [size * size] beside a step edge."""
    m = clean.reshape(size, size)
    dy = jnp.abs(jnp.diff(m, axis=0)) > EDGE_JUMP  # [size - 1, size]
    dx = jnp.abs(jnp.diff(m, axis=1)) > EDGE_JUMP  # [size, size - 1]
    edge = (jnp.pad(dy, ((1, 0), (0, 0))) | jnp.pad(dy, ((0, 1), (0, 0)))
            | jnp.pad(dx, ((0, 0), (1, 0))) | jnp.pad(dx, ((0, 0), (0, 1))))
    return edge.ravel()


def missing_chance(clean: jnp.ndarray, hm: HeightMapConfig, noise: NoiseConfig) -> jnp.ndarray:
    """[size * size] each cell's chance to be missing this step (the largest that applies)."""
    p = jnp.full(clean.shape, noise.height_missing)
    if noise.height_missing_body > 0:
        p = jnp.where(body_cells(hm), jnp.maximum(p, noise.height_missing_body), p)
    if noise.height_missing_edge > 0:
        p = jnp.where(edge_cells(clean, hm.size), jnp.maximum(p, noise.height_missing_edge), p)
    return p


def corrupt(obs: dict[str, jnp.ndarray], info: dict, rng: jax.Array | None,
            config: EnvConfig) -> dict[str, jnp.ndarray]:
    """``obs`` with the actor's height map offset by ``info["height_offset"]`` (when drawn) and
    its missing cells at +clip; unchanged with ``rng`` None or all of it off."""
    noise, hm = config.noise, config.height_map
    if rng is None or not noise.enabled or not (missing(noise) or "height_offset" in info):
        return obs
    n = observation.n_vec_of(config)
    heights = obs["state"][n:]
    if "height_offset" in info:
        heights = heights + info["height_offset"]
    if missing(noise):
        p = missing_chance(obs["privileged_state"][n:], hm, noise)
        if "missing_scale" in info:
            p = p * info["missing_scale"]
        hole = jax.random.uniform(jax.random.fold_in(rng, 11), p.shape) < p
        heights = jnp.where(hole, hm.clip, heights)
    return {**obs, "state": jnp.concatenate([obs["state"][:n], heights])}
