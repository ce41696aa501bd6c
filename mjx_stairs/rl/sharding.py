"""Data parallelism over the devices: a 1-D mesh named "batch" that splits the robots.

The env state, the running episode stats and the rollout are sharded on their robot axis,
everything else is replicated; XLA (GSPMD) inserts the gradient averaging and every other
reduction over the robots (normaliser, metrics). One device works unchanged (every helper is
then a no-op or a plain placement). With several processes (rl.distributed) the mesh spans the
devices of all of them, process p's devices holding a contiguous block of robots;
``to_host`` gathers such global arrays and ``put_global`` builds them from host arrays.
"""

from __future__ import annotations

from typing import Any

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding
from jax.sharding import PartitionSpec as P

BATCH_AXIS = "batch"


def make_mesh(devices: list | None = None) -> Mesh:
    """1-D mesh over all devices of all processes (or ``devices``), axis name "batch"."""
    devs = jax.devices() if devices is None else devices
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


def to_host(tree: Any) -> Any:
    """numpy copies of every leaf's global value. Leaves split over other processes' devices are
    gathered (a collective: every process calls this with the same tree)."""

    def one(x):
        if not isinstance(x, jax.Array) or x.is_fully_addressable or x.is_fully_replicated:
            return np.asarray(jax.device_get(x))
        from jax.experimental import multihost_utils

        return np.asarray(multihost_utils.process_allgather(x, tiled=True))

    return jax.tree_util.tree_map(one, tree)


def put_global(host: Any, shardings: Any) -> Any:
    """Global arrays with ``shardings`` from host arrays that every process holds whole: each
    process transfers only the slices of its own devices."""
    if jax.process_count() == 1:
        return jax.device_put(host, shardings)

    def one(a, s):
        a = np.asarray(a)
        return jax.make_array_from_callback(a.shape, s, lambda idx: a[idx])

    return jax.tree_util.tree_map(one, host, shardings)
