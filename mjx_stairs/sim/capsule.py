"""A capsule-heightfield contact for MJX: a limb against the terrain with two contacts, not twenty.

The sphere chains of `sim.geoms` give the calves and thighs the full robot's shape in MJX through
the sphere colliders of `sim.contact`, at two contacts (eight pyramidal constraint rows) a
sphere: eleven spheres a calf and nine a thigh took the solver from 32 contacts a robot to 192, and
a calf chain alone cost training a third of its env steps a second (108 k to 71 k on an H200,
docs/results.md 8v). A limb touches a step edge at one place, or two.

This collider takes the limb as the capsule it is (`RobotConfig.limb_capsules`: go2_full.xml's
calf and thigh capsules, `geoms.CALF_SHAPE` and `THIGH_SHAPE`) and gives it two contacts: it
places POINTS spheres of the capsule's radius along its axis, end to end (close enough that a
sharp edge reaches at most `geoms.CALF_EDGE_GAP` into the capsule between two of them, as the
chains are spaced), finds each one's nearest terrain point as the sphere colliders do (the columns
of `contact.sphere_columns`, a sunk centre leaving by the same rule, or the nearest-point surface
of `contact.sphere_heightfield`, by the heightfield's asset name as `contact._collide` picks), and
keeps the deepest of the spheres in each half of the capsule: one contact where an edge crosses
the limb, two where the limb lies along a tread. The spheres' contact geometry is the chains';
only the contacts the solver sees are fewer.

MJX keys collision functions by geom types; this one is registered for (heightfield, capsule)
pairs in place of MJX's own `hfield_capsule` (prisms and four contacts). Our robot's only
colliding capsules are the limbs that `limb_capsules` adds (go2.xml's capsules are visual), so
no other pair changes. MuJoCo itself (the ground truth's box world, sim2sim) collides the same
capsules natively.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco.mjx._src import collision_convex, collision_driver, support
from mujoco.mjx._src.types import GeomType

from mjx_stairs.sim import contact

POINTS = 9
"""Spheres along a capsule's axis (its two end centres included): for every capsule of
geoms.CALF_SHAPE and THIGH_SHAPE close enough for the CALF_EDGE_GAP rule (a test checks)."""

MAX_RADIUS = 0.025
"""The largest capsule radius the collider's per-sphere window of columns covers (m); larger
capsules are refused when the model is built (`check`)."""

NCON = 2
"""Contacts a capsule-terrain pair: the deepest sphere of each half of the capsule."""

KEY = (GeomType.HFIELD, GeomType.CAPSULE)


def capsule_heightfield(h, c, subgrid_size, surface: str = "columns", sunk_exit: str = "nearest"):
    """(dist [NCON], pos [NCON, 3], frame [NCON, 3, 3]) of capsule `c` (size: radius,
    half-length; its axis the frame's z) against heightfield `h`, in the world frame: POINTS
    spheres along the axis, each's nearest terrain point (`surface` "columns": contact's
    sphere_columns with `sunk_exit`; "surface": its sphere_heightfield), the deepest of each half.
    `subgrid_size` (MJX's, for the whole capsule) is not used: each sphere looks at the columns
    within MAX_RADIUS of its centre."""
    del subgrid_size
    dx = 2.0 * float(h.size[0]) / (h.ncol - 1)
    dy = 2.0 * float(h.size[1]) / (h.nrow - 1)
    window = (int(np.ceil(2 * MAX_RADIUS / dx)) + 1, int(np.ceil(2 * MAX_RADIUS / dy)) + 1)
    t = jnp.linspace(-1.0, 1.0, POINTS)
    centres = c.pos + (t * c.size[1])[:, None] * c.mat[:, 2]

    def sphere(p):
        s = c.replace(pos=p)
        if surface == "columns":
            d, pos, frame = contact.sphere_columns(h, s, window, sunk_exit=sunk_exit, ncon=1)
        else:
            d, pos, frame = contact.sphere_heightfield(h, s, window)
        return d[0], pos[0], frame[0]

    dist, pos, frame = jax.vmap(sphere)(centres)
    half = (POINTS + 1) // 2
    k = jnp.stack([jnp.argmin(dist[:half]), half + jnp.argmin(dist[half:])])
    return dist[k], pos[k], frame[k]


_BY_NAME = {
    contact.COLUMNS_HFIELD: collision_convex.collider(ncon=NCON)(
        functools.partial(capsule_heightfield, sunk_exit="top")),
    contact.COLUMNS_EXIT_HFIELD: collision_convex.collider(ncon=NCON)(
        functools.partial(capsule_heightfield, sunk_exit="nearest")),
}
_SURFACE = collision_convex.collider(ncon=NCON)(
    functools.partial(capsule_heightfield, surface="surface"))


def _collide(m, d, key, geom):
    """MJX's collision function for KEY: columns or the nearest-point surface, by asset name."""
    name = support.id2name(m, mujoco.mjtObj.mjOBJ_HFIELD, int(key.data_ids[0]))
    return _BY_NAME.get(name, _SURFACE)(m, d, key, geom)


_collide.ncon = NCON


def check(model: mujoco.MjModel) -> None:
    """Refuse a model with a terrain-colliding capsule wider than MAX_RADIUS (the collider's
    window of columns would miss some)."""
    for g in range(model.ngeom):
        is_capsule = model.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE
        wide = is_capsule and model.geom_size[g, 0] > MAX_RADIUS
        if wide and model.geom_contype[g] | model.geom_conaffinity[g]:
            raise ValueError(f"capsule geom {model.geom(g).name!r}: radius {model.geom_size[g, 0]}"
                             f" > {MAX_RADIUS}, more than sim.capsule's collider covers")


def register() -> None:
    """Make MJX collide (heightfield, capsule) pairs with `capsule_heightfield` (idempotent)."""
    collision_driver._COLLISION_FUNC[KEY] = _collide


register()
