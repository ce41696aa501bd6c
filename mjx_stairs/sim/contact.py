"""A lean sphere-heightfield contact for MJX: the exact nearest point, at most two contacts.

MJX collides a sphere with a heightfield (`collision_convex.hfield_sphere`) by building the two
triangular prisms of every grid cell under the sphere, running a sphere-convex test against each
and keeping four "manifold" points: four contacts per sphere-terrain pair, so 4 x 4 = 16
pyramidal constraint rows per sphere whether it touches or not. A sphere on a piecewise-planar
surface needs one contact per face it touches: one on a tread or on a step's convex edge, two in
the concave corner where a tread meets a riser.

This collider treats the heightfield as the surface it is (two triangles per grid cell, split
along the cell diagonal exactly like MuJoCo's prisms), finds the point of that surface nearest to
the sphere's centre, and emits it as the first contact. The second contact is the nearest surface
point in front of the first contact's tangent plane: the other face of a concave corner (where a
tread meets a riser), and nothing (an inactive contact) on a flat tread or at a convex edge.
Distances are signed: a centre below the surface gives a penetration deeper than the radius, with
the normal pointing back out.

On an H100 at 4096 robots this alone took MJX's physics-only rate from 272 k to 590 k env steps/s
(experiments/results/bench/NOTES.md, Change 4); policies trained with it keep their success rates
in MJX's collider and the other way round.

MJX picks a collision function by the geom types of a pair, so this one is registered for
(heightfield, ellipsoid) pairs, a pair MJX has no function for, and `mjx_stairs.sim.robot` turns the
robot's collision spheres into ellipsoids with three equal radii when `RobotConfig.terrain_contacts
== "nearest"`. An ellipsoid with equal radii is the same sphere to MuJoCo (mass comes from the
bodies' inertials, not from geoms) and to the C engine, so the same model steps in MuJoCo C
(play, export) with MuJoCo's own convex-heightfield collider. Models with sphere geoms keep
MJX's collider: the two coexist in one process.

Uses MJX internals (`collision_driver._COLLISION_FUNC`, `collision_convex.collider`), pinned by
the mujoco-mjx version in pyproject.toml; tests/mjx_stairs/test_contact.py checks the
registration, the distances against a brute-force reference, and MJX trajectories against
MJX's own collider.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import mujoco
from mujoco.mjx._src import collision_convex, collision_driver, support
from mujoco.mjx._src import math as mjx_math
from mujoco.mjx._src.types import GeomType

NCON = 2
"""Contacts per sphere-terrain pair: the nearest point and the other face of a concave corner."""

FRONT = 0.02
"""How far in front of the first contact's plane (in sphere radii) a second contact must lie."""


def _closest_on_triangles(p: jnp.ndarray, a: jnp.ndarray, b: jnp.ndarray, c: jnp.ndarray):
    """Closest point of each triangle (a, b, c: [T, 3]) to the point p [3]: [T, 3]."""
    ab, ac = b - a, c - a
    n = jnp.cross(ab, ac)
    nn = jnp.sum(n * n, -1, keepdims=True)
    # Projection onto the plane and its barycentric coordinates.
    ap = p - a
    v = jnp.sum(jnp.cross(ap, ac) * n, -1, keepdims=True) / nn
    w = jnp.sum(jnp.cross(ab, ap) * n, -1, keepdims=True) / nn
    inside = (v >= 0) & (w >= 0) & (v + w <= 1)
    proj = a + v * ab + w * ac

    def seg(s0, s1):
        d = s1 - s0
        t = jnp.clip(jnp.sum((p - s0) * d, -1, keepdims=True) / jnp.sum(d * d, -1, keepdims=True),
                     0.0, 1.0)
        return s0 + t * d

    edges = jnp.stack([seg(a, b), seg(b, c), seg(c, a)])  # [3, T, 3]
    edge_d2 = jnp.sum((edges - p) ** 2, -1)  # [3, T]
    nearest_edge = jnp.take_along_axis(edges, jnp.argmin(edge_d2, 0)[None, :, None], 0)[0]
    return jnp.where(inside, proj, nearest_edge)


def sphere_heightfield(h, s, subgrid_size: tuple[int, int]):
    """(dist [NCON], pos [NCON, 3], frame [NCON, 3, 3]) of one sphere against a heightfield, in
    the world frame; `h` is MJX's HFieldInfo, `s` the sphere's GeomInfo (size[0] = radius).

    Long: one collision kernel whose geometry reads top to bottom.
    """
    r = s.size[0]
    p = h.mat.T @ (s.pos - h.pos)  # centre in the heightfield frame
    ncol, nrow = h.ncol, h.nrow
    dx = 2.0 * h.size[0] / (ncol - 1)
    dy = 2.0 * h.size[1] / (nrow - 1)

    def z(i, j):  # heights at grid points; MJX's layout is data[ix, iy]. Gather, then scale:
        return h.data[i, j] * h.size[2]  # never the whole field

    # The grid cells under the sphere: the same sub-grid MJX sizes from the bounding radius.
    c0 = jnp.floor((p[0] - r + h.size[0]) / dx).astype(jnp.int32)
    r0 = jnp.floor((p[1] - r + h.size[1]) / dy).astype(jnp.int32)
    ci = jnp.clip(c0 + jnp.arange(subgrid_size[0]), 0, ncol - 2)
    ri = jnp.clip(r0 + jnp.arange(subgrid_size[1]), 0, nrow - 2)
    ci, ri = jnp.meshgrid(ci, ri, indexing="ij")
    ci, ri = ci.ravel(), ri.ravel()
    x0 = ci * dx - h.size[0]
    y0 = ri * dy - h.size[1]
    x1, y1 = x0 + dx, y0 + dy
    v00 = jnp.stack([x0, y0, z(ci, ri)], -1)
    v10 = jnp.stack([x1, y0, z(ci + 1, ri)], -1)
    v01 = jnp.stack([x0, y1, z(ci, ri + 1)], -1)
    v11 = jnp.stack([x1, y1, z(ci + 1, ri + 1)], -1)
    # MuJoCo's split of a cell: (00, 11, 01) above the diagonal, (00, 10, 11) below it.
    a = jnp.concatenate([v00, v00])
    b = jnp.concatenate([v11, v10])
    c = jnp.concatenate([v01, v11])
    q = _closest_on_triangles(p, a, b, c)  # [T, 3]
    d = jnp.linalg.norm(q - p, axis=-1)  # [T]

    # Is the centre under the surface? The surface height at the centre's (x, y).
    fx = jnp.clip((p[0] + h.size[0]) / dx, 0.0, ncol - 1.0)
    fy = jnp.clip((p[1] + h.size[1]) / dy, 0.0, nrow - 1.0)
    ic = jnp.clip(jnp.floor(fx).astype(jnp.int32), 0, ncol - 2)
    ir = jnp.clip(jnp.floor(fy).astype(jnp.int32), 0, nrow - 2)
    u, w = fx - ic, fy - ir
    z00, z10, z01, z11 = z(ic, ir), z(ic + 1, ir), z(ic, ir + 1), z(ic + 1, ir + 1)
    surface = jnp.where(w >= u, z00 + w * (z01 - z00) + u * (z11 - z01),
                        z00 + u * (z10 - z00) + w * (z11 - z10))
    sign = jnp.where(p[2] < surface, -1.0, 1.0)

    def contact(k):
        dk = d[k]
        face_n = jnp.cross(b[k] - a[k], c[k] - a[k])  # up (+z) for both halves
        face_n = face_n / jnp.linalg.norm(face_n)
        n = jnp.where(dk > 1e-6, sign * (p - q[k]) / jnp.maximum(dk, 1e-6), face_n)
        dist = sign * dk - r
        pos = q[k] + 0.5 * dist * n
        return dist, pos, n

    k1 = jnp.argmin(d)
    dist1, pos1, n1 = contact(k1)
    # The second face of a concave corner: a surface point in front of the first contact's
    # plane. Points on or behind that plane (the rest of a flat tread, a convex edge, the
    # far side of a crest) are not contacts of their own; nor is anything when the centre is
    # under the surface (one contact pushes it out).
    ahead = (q - q[k1]) @ n1 > FRONT * r
    k2 = jnp.argmin(jnp.where(ahead, d, jnp.inf))
    dist2, pos2, n2 = contact(k2)
    dist2 = jnp.where(jnp.any(ahead) & (sign > 0), dist2, 1.0)
    dist = jnp.stack([dist1, dist2])
    pos = jnp.stack([pos1, pos2]) @ h.mat.T + h.pos
    n = jnp.stack([n1, n2]) @ h.mat.T
    return dist, pos, jax.vmap(mjx_math.make_frame)(n)


def sphere_columns(h, s, subgrid_size: tuple[int, int], sunk_exit: str = "top",
                   ncon: int = NCON):
    """(dist [ncon], pos [ncon, 3], frame [ncon, 3, 3]) of one sphere against the heightfield's
    grid read as columns, as `terrains.boxes.grid_boxes` builds the ground truth: grid point
    (ix, iy) owns the square cell around it (half a spacing each way), a flat-topped column from
    the field's base up to its height, so risers are vertical and edges sharp.

    The distance to a union of boxes is the least distance to one of them, and the nearest point
    of an axis-aligned box is the centre clamped to it. The first contact is the nearest column,
    the second the nearest column in front of the first contact's plane (the riser of a concave
    corner), as in `sphere_heightfield`; each further one (``ncon`` > 2) the nearest column in
    front of every earlier contact's plane (the other riser where a step edge crosses the grid).
    A centre inside a column (the sphere sunk deeper than its radius) leaves through its top
    (``sunk_exit="top"``: right for a foot sunk into a tread, but a foot driven into a riser is
    lifted onto the step above), or through its nearest exposed face (``"nearest"``: the top, or
    a side whose neighbouring column stands lower than the centre), as MuJoCo's box pushes it
    (issue 19, docs/results.md section 5b).
    """
    r = s.size[0]
    corner, p, ci, ri, top, lo, hi = _columns_near(h, s.pos, r, subgrid_size)
    q = jnp.clip(p, lo, hi)  # [C, 3] nearest point of each column
    d = jnp.linalg.norm(q - p, axis=-1)
    inside = d <= 0.0
    sunk = jnp.any(inside)
    k_in = jnp.argmax(jnp.where(inside, top, -jnp.inf))

    def contact(k):
        dk = d[k]
        n = (p - q[k]) / jnp.maximum(dk, 1e-9)
        return dk - r, q[k] + 0.5 * (dk - r) * n, n

    k1 = jnp.argmin(d)
    dist1, pos1, n1 = contact(k1)
    depth, n_in = _exit_face(h, p, ci[k_in], ri[k_in], lo[k_in], hi[k_in], sunk_exit)
    q_in = p + depth * n_in
    dist1 = jnp.where(sunk, -depth - r, dist1)
    n1 = jnp.where(sunk, n_in, n1)
    pos1 = jnp.where(sunk, q_in + 0.5 * (-depth - r) * n_in, pos1)
    q1 = jnp.where(sunk, q_in, q[k1])
    found = [(dist1, pos1, n1)] + _further_contacts(q, d, q1, n1, contact, ~sunk, FRONT * r,
                                                    ncon - 1)
    dist = jnp.stack([c[0] for c in found])
    pos = jnp.stack([c[1] for c in found]) @ h.mat.T + corner
    n = jnp.stack([c[2] for c in found]) @ h.mat.T
    return dist, pos, jax.vmap(mjx_math.make_frame)(n)


def _columns_near(h, centre, r, subgrid_size: tuple[int, int]):
    """(corner, p, ci, ri, top, lo, hi) for `sphere_columns`: the world position of grid point
    (0, 0), the sphere centre in its frame, and the columns whose cells reach [p - r, p + r] (at
    most ceil(2r / dx) + 1 per axis, the sub-grid MJX sizes from the bounding radius): grid
    indices, tops and box corners [C, 3]. From grid point (0, 0), the atlas corner (the world
    origin for our atlases), not the field's centre: a point of a tile has the same float32
    coordinates in every atlas that holds the tile (from the centre, 1 ulp at 10 m is 1e-6 m,
    which the stiff contact turned into 1e-5 m/s between atlases: issue 19)."""
    corner = h.pos - h.mat @ jnp.array([h.size[0], h.size[1], 0.0])
    p = h.mat.T @ (centre - corner)
    ncol, nrow = h.ncol, h.nrow
    dx = 2.0 * h.size[0] / (ncol - 1)
    dy = 2.0 * h.size[1] / (nrow - 1)
    c0 = jnp.floor((p[0] - r) / dx + 0.5).astype(jnp.int32)
    r0 = jnp.floor((p[1] - r) / dy + 0.5).astype(jnp.int32)
    ci = jnp.clip(c0 + jnp.arange(subgrid_size[0]), 0, ncol - 1)
    ri = jnp.clip(r0 + jnp.arange(subgrid_size[1]), 0, nrow - 1)
    ci, ri = jnp.meshgrid(ci, ri, indexing="ij")
    ci, ri = ci.ravel(), ri.ravel()
    top = h.data[ci, ri] * h.size[2]
    lo = jnp.stack([(ci - 0.5) * dx, (ri - 0.5) * dy, jnp.full_like(top, -h.size[3])], -1)
    hi = jnp.stack([(ci + 0.5) * dx, (ri + 0.5) * dy, top], -1)
    return corner, p, ci, ri, top, lo, hi


def _further_contacts(q, d, q1, n1, contact, active, front: float, count: int) -> list:
    """``count`` contacts after the first (point q1 of column, normal n1): each the nearest
    column (of nearest points q [C, 3], distances d [C]) in front of every earlier contact's
    plane by more than ``front``, as (dist, pos, normal) from ``contact(k)``; inactive (dist 1)
    where no column is in front, or where ``active`` is false (a sunk centre)."""
    out, ahead, qj, nj = [], jnp.ones_like(d, bool), q1, n1
    for _ in range(count):
        ahead = ahead & ((q - qj) @ nj > front)
        kj = jnp.argmin(jnp.where(ahead, d, jnp.inf))
        distj, posj, nj = contact(kj)
        out.append((jnp.where(jnp.any(ahead) & active, distj, 1.0), posj, nj))
        qj = q[kj]
    return out


def _exit_face(h, p, ix, iy, lo, hi, sunk_exit: str):
    """(depth, outward normal) of the face through which a centre p inside column (ix, iy)
    [lo, hi] leaves: its top ("top"), or its nearest exposed face ("nearest": the top, or a side
    whose neighbouring column, or the grid's edge, lies lower than p; a side against a column at
    least as high is inside the solid)."""
    up = jnp.array([0.0, 0.0, 1.0])
    if sunk_exit == "top":
        return hi[2] - p[2], up
    if sunk_exit not in ("nearest", "face"):
        raise ValueError(f"sunk_exit must be 'top', 'nearest' or 'face', got {sunk_exit!r}")
    ncol, nrow = h.ncol, h.nrow

    def below(jx, jy):
        inside = (jx >= 0) & (jx < ncol) & (jy >= 0) & (jy < nrow)
        z = h.data[jnp.clip(jx, 0, ncol - 1), jnp.clip(jy, 0, nrow - 1)] * h.size[2]
        return ~inside | (z < p[2])

    depth = jnp.stack([hi[2] - p[2], p[0] - lo[0], hi[0] - p[0], p[1] - lo[1], hi[1] - p[1]])
    open_ = jnp.stack([jnp.array(True), below(ix - 1, iy), below(ix + 1, iy), below(ix, iy - 1),
                       below(ix, iy + 1)])
    normals = jnp.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0],
                         [0.0, 1.0, 0.0]])
    if sunk_exit == "face":  # a study (set_exit_study): any face, as a MuJoCo box pushes it
        open_ = jnp.ones_like(open_)
    j = jnp.argmin(jnp.where(open_, depth, jnp.inf))
    return depth[j], normals[j]


COLUMNS_HFIELD = "terrain_columns"
"""The heightfield asset name that selects `sphere_columns` (any other name but the next: the
nearest-point surface collider). MJX keys collision functions by geom types only, and the
colliders all collide (heightfield, ellipsoid) pairs, so the one registered function dispatches
on the asset's name."""

COLUMNS_EXIT_HFIELD = "terrain_columns_exit"
"""The heightfield asset name that selects `sphere_columns` with ``sunk_exit="nearest"``."""

KEY = (GeomType.HFIELD, GeomType.ELLIPSOID)


def _padded(fn, ncon: int):
    """`fn` (NCON contacts) with inactive contacts appended up to ``ncon``."""
    def padded(h, s, subgrid_size):
        dist, pos, frame = fn(h, s, subgrid_size)
        k = ncon - dist.shape[0]
        return (jnp.concatenate([dist, jnp.ones(k, dist.dtype)]),
                jnp.concatenate([pos, jnp.repeat(pos[-1:], k, 0)]),
                jnp.concatenate([frame, jnp.repeat(frame[-1:], k, 0)]))
    return padded


def _colliders(ncon: int, exit_rule: str = "nearest") -> tuple:
    """(nearest-point collider, {asset name: columns collider}) with ``ncon`` contacts a pair;
    ``exit_rule``: what the exit asset's collider does with a sunk centre (set_exit_study)."""
    nearest = sphere_heightfield if ncon == NCON else _padded(sphere_heightfield, ncon)
    return (collision_convex.collider(ncon=ncon)(nearest), {
        COLUMNS_HFIELD: collision_convex.collider(ncon=ncon)(
            functools.partial(sphere_columns, ncon=ncon)),
        COLUMNS_EXIT_HFIELD: collision_convex.collider(ncon=ncon)(
            functools.partial(sphere_columns, sunk_exit=exit_rule, ncon=ncon)),
    })


_NEAREST, _BY_NAME = _colliders(NCON)


def _collide(m, d, key, geom):
    """MJX's collision function for KEY: columns or the nearest-point surface, by asset name."""
    name = support.id2name(m, mujoco.mjtObj.mjOBJ_HFIELD, int(key.data_ids[0]))
    return _BY_NAME.get(name, _NEAREST)(m, d, key, geom)


_collide.ncon = NCON
_COLLIDER = _collide


def set_columns_ncon(ncon: int) -> None:
    """Give the columns colliders ``ncon`` contacts a sphere (the nearest-point one is padded):
    a study of the contact count (issue 19, experiments/damping_gt.py's ``_c<n>``), for a whole
    process, before any model is put on the device or any step is traced; MJX sizes every
    (heightfield, ellipsoid) pair's contacts from this count. Not a training option."""
    global _NEAREST, _BY_NAME
    if ncon < NCON:
        raise ValueError(f"ncon must be at least {NCON} (the nearest-point collider's), got {ncon}")
    _NEAREST, _BY_NAME = _colliders(ncon)
    _collide.ncon = ncon


def set_exit_study(rule: str) -> None:
    """For a whole process, before any model is put on the device: the evaluation physics'
    columns (``sunk_exit="nearest"``) push a sunk centre out by ``rule`` instead: "face", the
    nearest of the column's five faces whether or not a column as high stands beside it (what a
    MuJoCo box does with a centre inside it; issue 19's spiral study, experiments/gt_spiral/).
    Not a training option: records still name the preset's rule."""
    global _NEAREST, _BY_NAME
    if rule not in ("nearest", "face"):
        raise ValueError(f"rule must be 'nearest' or 'face', got {rule!r}")
    _NEAREST, _BY_NAME = _colliders(_collide.ncon, rule)


def register() -> None:
    """Make MJX collide (heightfield, ellipsoid) pairs with `sphere_heightfield` or
    `sphere_columns` (idempotent)."""
    current = collision_driver._COLLISION_FUNC.get(KEY)
    if current is not None and current is not _COLLIDER:
        raise RuntimeError(f"MJX already has a collision function for {KEY}: {current!r}")
    collision_driver._COLLISION_FUNC[KEY] = _COLLIDER


register()
