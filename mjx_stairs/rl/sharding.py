"""Data parallelism over the local devices: a 1-D mesh named "batch" that splits the robots.

The env state, the running episode stats and the rollout are sharded on their robot axis,
everything else is replicated; XLA (GSPMD) inserts the gradient averaging. One device works
unchanged (every helper is then a no-op or a plain placement).
"""

from __future__ import annotations

from typing import Any

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding
from jax.sharding import PartitionSpec as P

BATCH_AXIS = "batch"


def make_mesh(devices: list | None = None) -> Mesh:
    """1-D mesh over all local devices (or ``devices``), axis name "batch"."""
    devs = jax.local_devices() if devices is None else devices
    return Mesh(np.array(devs), (BATCH_AXIS,))


def replicated(mesh: Mesh) -> NamedSharding:
    return NamedSharding(mesh, P())


def batched(mesh: Mesh) -> NamedSharding:
    """Split the leading (robot) axis over the mesh."""
    return NamedSharding(mesh, P(BATCH_AXIS))


def constrain(tree: Any, mesh: Mesh, axis: int) -> Any:
    """Pin the robot/sample axis ``axis`` of every leaf to the mesh (no-op where it won't split)."""
    n = mesh.devices.size
    if n == 1:
        return tree

    def one(x):
        if x.ndim <= axis or x.shape[axis] % n:
            return x
        spec = P(*([None] * axis), BATCH_AXIS)
        return jax.lax.with_sharding_constraint(x, NamedSharding(mesh, spec))

    return jax.tree_util.tree_map(one, tree)
