"""Issue 19, the U-turn: does the columns collider's sunk rule make MJX optimistic? Today a
sphere whose centre is inside a column is pushed out through that column's top (right for a foot
sunk into a tread; for a foot driven into a riser, or a wall, it lifts the foot onto the step,
where MuJoCo C's box pushes it back out through the riser). 'nearest' pushes it out through the
column's nearest exposed face (the top, or a side whose neighbouring column stands lower than the
centre). MJX (CPU) success of one policy on one cell under either rule, same starts.

Usage (CPU): JAX_PLATFORMS=cpu PYTHONPATH=. python experiments/gt_sunk_exit.py top|nearest \
    ROBOTS CELL POLICY        (e.g. nearest 256 8 stage2_u_lean; ~6 min on 2 cores)
"""

from __future__ import annotations

import json
import sys
import time

import jax
import jax.numpy as jnp
from mujoco.mjx._src import collision_convex
from mujoco.mjx._src import math as mjx_math

from mjx_stairs.sim import contact

sys.path.insert(0, "experiments/gpu")


def sphere_columns_exit(h, s, subgrid_size):
    r = s.size[0]
    p = h.mat.T @ (s.pos - h.pos)
    ncol, nrow = h.ncol, h.nrow
    dx = 2.0 * h.size[0] / (ncol - 1)
    dy = 2.0 * h.size[1] / (nrow - 1)
    c0 = jnp.floor((p[0] - r + h.size[0]) / dx + 0.5).astype(jnp.int32)
    r0 = jnp.floor((p[1] - r + h.size[1]) / dy + 0.5).astype(jnp.int32)
    ci = jnp.clip(c0 + jnp.arange(subgrid_size[0]), 0, ncol - 1)
    ri = jnp.clip(r0 + jnp.arange(subgrid_size[1]), 0, nrow - 1)
    ci, ri = jnp.meshgrid(ci, ri, indexing="ij")
    ci, ri = ci.ravel(), ri.ravel()
    top = h.data[ci, ri] * h.size[2]
    lo = jnp.stack([(ci - 0.5) * dx - h.size[0], (ri - 0.5) * dy - h.size[1],
                    jnp.full_like(top, -h.size[3])], -1)
    hi = jnp.stack([(ci + 0.5) * dx - h.size[0], (ri + 0.5) * dy - h.size[1], top], -1)
    q = jnp.clip(p, lo, hi)
    d = jnp.linalg.norm(q - p, axis=-1)
    inside = d <= 0.0
    sunk = jnp.any(inside)
    k_in = jnp.argmax(jnp.where(inside, top, -jnp.inf))

    def contact_(k):
        dk = d[k]
        n = (p - q[k]) / jnp.maximum(dk, 1e-9)
        return dk - r, q[k] + 0.5 * (dk - r) * n, n

    k1 = jnp.argmin(d)
    dist1, pos1, n1 = contact_(k1)
    # sunk: the nearest exposed face of the column holding the centre (top, or a side whose
    # neighbouring column stands lower than the centre)
    cx, cy = ci[k_in], ri[k_in]

    def nb(ix, iy):
        in_grid = (ix >= 0) & (ix < ncol) & (iy >= 0) & (iy < nrow)
        z = h.data[jnp.clip(ix, 0, ncol - 1), jnp.clip(iy, 0, nrow - 1)] * h.size[2]
        return jnp.where(in_grid, z, -jnp.inf)

    lk, hk = lo[k_in], hi[k_in]
    cand_d = jnp.stack([hk[2] - p[2], p[0] - lk[0], hk[0] - p[0], p[1] - lk[1], hk[1] - p[1]])
    exposed = jnp.stack([True, nb(cx - 1, cy) < p[2], nb(cx + 1, cy) < p[2],
                         nb(cx, cy - 1) < p[2], nb(cx, cy + 1) < p[2]])
    normals = jnp.array([[0., 0., 1.], [-1., 0., 0.], [1., 0., 0.], [0., -1., 0.], [0., 1., 0.]])
    j = jnp.argmin(jnp.where(exposed, cand_d, jnp.inf))
    depth, n_in = cand_d[j], normals[j]
    q_in = p + depth * n_in
    dist1 = jnp.where(sunk, -depth - r, dist1)
    n1 = jnp.where(sunk, n_in, n1)
    pos1 = jnp.where(sunk, q_in + 0.5 * (-depth - r) * n_in, pos1)
    q1 = jnp.where(sunk, q_in, q[k1])
    ahead = (q - q1) @ n1 > contact.FRONT * r
    k2 = jnp.argmin(jnp.where(ahead, d, jnp.inf))
    dist2, pos2, n2 = contact_(k2)
    dist2 = jnp.where(jnp.any(ahead) & ~sunk, dist2, 1.0)
    dist = jnp.stack([dist1, dist2])
    pos = jnp.stack([pos1, pos2]) @ h.mat.T + h.pos
    n = jnp.stack([n1, n2]) @ h.mat.T
    return dist, pos, jax.vmap(mjx_math.make_frame)(n)


def main(rule: str, robots: int, cell: int, pol: str) -> None:
    if rule == "nearest":
        contact._COLUMNS = collision_convex.collider(ncon=contact.NCON)(sphere_columns_exit)
    elif rule != "top":
        sys.exit(f"rule must be top or nearest, got {rule!r}")
    from fidelity import CELLS, OPTIONS, POLICIES

    from mjx_stairs.rl.policy import load_policy
    from mjx_stairs.study.evaluate import CellSpec, success_by_cell

    spec = CellSpec(cells=(CELLS[cell],), robots_per_cell=robots,
                    env_overrides=OPTIONS["evaluation"], physics="trained")
    t0 = time.time()
    r = success_by_cell({pol: load_policy(POLICIES[pol])}, spec)[pol]
    print(json.dumps(dict(rule=rule, cell=list(CELLS[cell]), policy=pol, robots=robots,
                          success=r["success"], fell=r["fell"],
                          wall_s=round(time.time() - t0))))


if __name__ == "__main__":
    if len(sys.argv) != 5:
        sys.exit(__doc__)
    main(sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4])
