"""The critic's value over a tile's x-y grid (the paper's Figure 4)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from mjx_stairs.env import observation
from mjx_stairs.env.geometry import yaw_quat
from mjx_stairs.rl.policy import Policy, policy_value
from mjx_stairs.sim.robot import NOMINAL_BASE_HEIGHT, NOMINAL_JOINT_POS
from mjx_stairs.study.evaluate import EvalSpec, eval_env, make_eval_env


def critic_map(
    policy: Policy,
    family: str = "u_shaped",
    level: int = 2,
    variant: int = 0,
    spacing: float = 0.1,
    schedule: str = "test",
    resolution: float = 0.025,
    tile_size: float = 10.0,
) -> dict[str, np.ndarray]:
    """The critic's value over a family's tile (the paper's Figure 4): `family` at 0-based
    `level` of `schedule`, `variant` (0 or 1); see values_on_tile."""
    spec = EvalSpec(family=family, schedule=schedule, levels=(level,), robots_per_level=1,
                    resolution=resolution, tile_size=tile_size)
    env, _ = make_eval_env(policy, spec)
    return values_on_tile(policy, env, variant, spacing)


def critic_map_of_tile(policy: Policy, tile, spec: EvalSpec,
                       spacing: float = 0.1) -> dict[str, np.ndarray]:
    """The critic's value over any terrains.Tile (e.g. an imported mesh), in the evaluation
    env that `spec` decides; see values_on_tile."""
    import terrains

    env = eval_env(policy, terrains.build_tile_atlas([[tile]]), spec)
    return values_on_tile(policy, env, 0, spacing)


def values_on_tile(policy: Policy, env, tile: int, spacing: float = 0.1) -> dict[str, np.ndarray]:
    """The critic's value over the x-y grid of atlas tile `tile` of `env`.

    At each grid point the robot stands upright at its nominal height above the terrain, faces
    along the nearest centre-line segment, velocities and last action zero; it sees the local
    height map and the goal. Points on walls are NaN.
    Returns {"x": [nx], "y": [ny], "value": [ny, nx], "heights": tile heights
    [ny_t, nx_t], "extent": (x0, x1, y0, y1), "goal": [4], "centreline": [K, 3]}.

    Long: the grid, its observations, the values and the tile around them, in order.
    """
    resolution = env.resolution
    tile_size = float(env.tiles.hi[tile][0] - env.tiles.lo[tile][0]) + resolution
    ox, oy = (float(v) for v in env.tile_origin[tile])
    xs = np.arange(ox + 0.2, ox + tile_size - 0.2 + 1e-9, spacing)
    ys = np.arange(oy + 0.2, oy + tile_size - 0.2 + 1e-9, spacing)
    gx, gy = np.meshgrid(xs, ys, indexing="xy")
    line = env.tiles.centreline(tile)

    def yaw_at(x, y):
        d = np.linalg.norm(line[None, :-1] - np.stack([x, y], -1)[:, None], axis=-1)
        seg = np.diff(line, axis=0)
        seg_len = np.linalg.norm(seg, axis=-1)
        d = np.where(seg_len[None] > 1e-6, d, np.inf)
        i = d.argmin(1)
        return np.arctan2(seg[i, 1], seg[i, 0])

    yaw = yaw_at(gx.ravel(), gy.ravel())

    def obs_at(x, y, psi):
        z = env.terrain_height(x, y) + NOMINAL_BASE_HEIGHT
        qpos = jnp.concatenate([jnp.stack([x, y, z]), yaw_quat(psi), NOMINAL_JOINT_POS])
        info = {"tile": jnp.int32(tile), "last_action": jnp.zeros(12),
                **observation.history_start(env.config.obs_history, jnp.zeros(12))}  # nominal pose
        return env.observe(qpos, jnp.zeros(18), info)["privileged_state"]

    obs = jax.jit(jax.vmap(obs_at))(
        jnp.asarray(gx.ravel(), jnp.float32),
        jnp.asarray(gy.ravel(), jnp.float32),
        jnp.asarray(yaw, jnp.float32),
    )
    values = np.asarray(jax.jit(lambda o: policy_value(policy, o))(obs)).reshape(gx.shape)
    # Walls are not walkable: leave them blank (above the goal landing by more than a riser).
    ground = np.asarray(jax.jit(env.terrain_height)(jnp.asarray(gx), jnp.asarray(gy)))
    goal = np.asarray(env.tiles.goal[tile])
    goal_z = float(max(goal[2], env.tiles.spawn[tile][2]))
    values = np.where(ground > goal_z + 0.3, np.nan, values)
    n = int(round(tile_size / resolution))
    i0, j0 = int(round(oy / resolution)), int(round(ox / resolution))
    heights = env.terrain.heights()[i0 : i0 + n + 1, j0 : j0 + n + 1]
    return {
        "x": xs,
        "y": ys,
        "value": values,
        "heights": heights,
        "extent": (ox, ox + tile_size, oy, oy + tile_size),
        "goal": goal,
        "centreline": line,
    }
