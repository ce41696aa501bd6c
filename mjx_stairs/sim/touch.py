"""Which of the robot's collision spheres touch the terrain, read off MJX's contact array.

MJX lays contacts out by collision-function group, each geom pair repeated ncon times; the
layout is static for a model, so `sphere_contact_rows` reads it once at build time and
`sphere_contacts` indexes it every step.
"""

from __future__ import annotations

import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx
from mujoco.mjx._src import collision_driver

from mjx_stairs.sim.robot import RobotIds


def sphere_contact_rows(mj_model: mujoco.MjModel, ids: RobotIds) -> dict[str, np.ndarray | None]:
    """{group: [4, rows per leg] rows of MJX's contact array} for each sphere group (None for
    a group that does not collide); a leg's "shin" rows are its mid-shin sphere's and its calf
    chain's (with calf_collision), its "knee" rows its knee sphere's and its thigh chain's (with
    thigh_collision), the trunk group's [4 or 5, ncon] one sphere each (tests check the layout
    against a forward pass)."""
    rows: dict[int, list[int]] = {}
    i = 0
    for key, pairs in collision_driver._geom_groups(mj_model).items():
        ncon = collision_driver._COLLISION_FUNC[key.types].ncon
        for g1, g2, _ in pairs:
            for g in (g1, g2):
                rows.setdefault(int(g), [])
            rows[int(g2)].extend(range(i, i + ncon))
            rows[int(g1)].extend(range(i, i + ncon))
            i += ncon
    out = {}
    calf = [ids.shin_geoms[i:i + 1].tolist() + ids.calf_geoms[i].tolist() for i in range(4)]
    thigh = [ids.knee_geoms[i:i + 1].tolist() + ids.thigh_geoms[i].tolist() for i in range(4)]
    for group, geoms in (
        ("foot", ids.foot_geoms[:, None]),
        ("knee", thigh),  # the knee sphere and the thigh chain: one thigh's contacts
        ("shin", calf),  # the mid-shin sphere and the calf chain: one calf's contacts
        ("trunk", ids.trunk_geoms[:, None]),
    ):
        per = [sum((rows.get(int(g), []) for g in leg), []) for leg in geoms]
        if all(len(p) == 0 for p in per):  # a group without collision, e.g. shins switched off
            out[group] = None
        elif len({len(p) for p in per}) != 1:
            raise ValueError(f"collision spheres of group {group!r} collide unevenly: {per}")
        else:
            out[group] = np.array(per, np.int32)
    return out


def sphere_contacts(data: mjx.Data, rows: dict[str, np.ndarray | None]) -> dict[str, jnp.ndarray]:
    """{group: [n] bool} which collision spheres touch the terrain (rows: sphere_contact_rows;
    n = 4, the trunk 5 with the head)."""
    dist = data._impl.contact.dist
    return {
        g: jnp.zeros(4, bool) if r is None else jnp.any(dist[r] < 1e-3, axis=-1)
        for g, r in rows.items()
    }
