"""The atlas heightfield as the robot's model holds it: heights anywhere, the local height map."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from mjx_stairs.env.config import HeightMapConfig
from mjx_stairs.env.geometry import sample_heights
from mjx_stairs.sim import robot as rb


class Terrain:
    """Heights of the atlas (corner at the world origin) and the height map around a base."""

    def __init__(self, robot: rb.Robot, shape: tuple[int, int], resolution: float,
                 height_map: HeightMapConfig):
        mj = robot.mj_model
        self.shape = shape  # (ny, nx) grid points
        self.resolution = resolution
        # height = lo + span * hfield_data (the data MuJoCo keeps is normalised)
        self.lo = float(mj.geom_pos[robot.ids.hfield_geom][2])
        self.span = float(mj.hfield_size[0][2])
        self.size = ((shape[1] - 1) * resolution, (shape[0] - 1) * resolution)  # (x, y) m
        self._device = robot.mjx_model.hfield_data
        self._host = mj.hfield_data
        self._hm = height_map
        half = 0.5 * (height_map.size - 1) * height_map.spacing
        axis = np.linspace(-half, half, height_map.size)
        gx, gy = np.meshgrid(axis, axis, indexing="xy")
        self._map_xy = jnp.asarray(np.stack([gx.ravel(), gy.ravel()], -1), jnp.float32)  # [S*S, 2]

    def height(self, x: jnp.ndarray, y: jnp.ndarray) -> jnp.ndarray:
        """[...] terrain height (m) at world (x, y), on the device."""
        return self.lo + self.span * sample_heights(self._device, self.shape, self.resolution,
                                                    x, y)

    def heights(self) -> np.ndarray:
        """[ny, nx] the heights (m) at the grid points, on the host."""
        return self.lo + self.span * np.asarray(self._host, np.float64).reshape(self.shape)

    def height_map(self, pos: jnp.ndarray, yaw: jnp.ndarray, lo: jnp.ndarray,
                   hi: jnp.ndarray) -> jnp.ndarray:
        """[size * size] map values (base z - terrain z - offset, clipped) around `pos` [3], on
        a grid turned by the base's yaw (rows along its y, columns along its x), read inside the
        xy box [lo, hi] [2] alone: points past its edge read the edge."""
        hm = self._hm
        c, s = jnp.cos(yaw), jnp.sin(yaw)
        px = pos[0] + c * self._map_xy[:, 0] - s * self._map_xy[:, 1]
        py = pos[1] + s * self._map_xy[:, 0] + c * self._map_xy[:, 1]
        px, py = jnp.clip(px, lo[0], hi[0]), jnp.clip(py, lo[1], hi[1])
        h = self.height(px, py)
        if hm.occlusion_samples > 0:
            h = jnp.maximum(h, self._occluder(pos, px, py))
        return jnp.clip(pos[2] - h - hm.offset, -hm.clip, hm.clip)

    def _occluder(self, pos: jnp.ndarray, px: jnp.ndarray, py: jnp.ndarray) -> jnp.ndarray:
        """[P] the highest terrain above the sensor on the segment from the base to each map
        point (HeightMapConfig.occlusion_samples), -inf where none is."""
        hm = self._hm
        s = jnp.arange(1, hm.occlusion_samples, dtype=jnp.float32) / hm.occlusion_samples
        z = self.height(pos[0] + s * (px[:, None] - pos[0]), pos[1] + s * (py[:, None] - pos[1]))
        return jnp.where(z > pos[2] + hm.sensor_height, z, -jnp.inf).max(-1)
