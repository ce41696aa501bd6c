"""Collision spheres that a `RobotConfig` adds to assets/go2.xml: the head and the calf chains.

go2.xml collides through spheres only (feet, knees, mid-shins, trunk corners), which leaves
two stretches of each calf bare: between the knee sphere (r 0.025 at the knee) and the mid-shin
one (r 0.018 at 0.11 m), and between that and the foot (r 0.022 at 0.213 m). In MuJoCo itself
the full robot's calf capsules (assets/go2_full.xml, r 0.013) touch step edges there: up to 100
times an episode for a generalist at the Go2's joint damping of 2, where training saw nothing
(docs/deploy.md, session 31). `CALF_DEPTHS` fills both stretches with spheres of the capsule's
radius, so that MJX sees what touches a real step edge through the sphere colliders it already
has (the heightfield and column colliders of `sim.contact`). A chain must overlap, not only
touch: a sharp step edge passes through any gap between two spheres. What it does not change is
go2.xml's mid-shin sphere, 5-9 mm proud of the capsule's front: on L-shaped level 6 at damping 2
MuJoCo itself climbed 33 % with the full robot's straight capsule, 28 with the capsule as 15
spheres, 71 with those and the mid-shin sphere, 71 with training's calf and this chain in its
place (docs/deploy.md, session 32): the two robots' calves differ by that bump, chain or not.
"""

from __future__ import annotations

import mujoco
import numpy as np

HEAD = ("trunk_head", (0.293, 0.0, -0.06), 0.047)
"""(name, position in the base frame, radius) of the head sphere that `RobotConfig.head_collision`
adds to the trunk group: the lower head sphere of assets/go2_full.xml, 12 cm ahead of the trunk
corners; in sim2sim the head touches step edges up to 12 times per episode up 14 cm risers."""

CALF_RADIUS = 0.013
"""Radius (m) of the calf-chain spheres: go2_full.xml's calf capsule."""

CALF_DEPTHS = (0.032, 0.050, 0.069, 0.087, 0.133, 0.150, 0.168, 0.185)
"""Depths (m) below the knee of the calf-chain spheres along the calf's axis, which runs from
the knee to the foot at (-0.002, 0, -0.213): four in each bare stretch, so that with the knee,
mid-shin and foot spheres every point of the axis lies at least 8.8 mm deep inside a sphere
(the capsule's 13 mm): a step edge across the calf anywhere meets a sphere within 4.2 mm of the
capsule's surface."""


def calf_chain_positions() -> np.ndarray:
    """[len(CALF_DEPTHS), 3] sphere centres in the calf body's frame, on the knee-foot axis."""
    depth = np.asarray(CALF_DEPTHS)
    return np.stack([-0.002 * depth / 0.213, np.zeros_like(depth), -depth], axis=-1)


def calf_chain_names(leg: str) -> tuple[str, ...]:
    """Geom names of one leg's calf chain (leg: FL, FR, RL or RR)."""
    return tuple(f"{leg}_calf_chain{i}" for i in range(len(CALF_DEPTHS)))


def collide_like(geom, like) -> None:
    """Give MjSpec geom `geom` the contact settings of geom `like` (what it collides with, how)."""
    for attr in ("contype", "conaffinity", "condim", "friction", "solref", "solimp", "solmix",
                 "margin", "gap", "priority", "group"):
        setattr(geom, attr, getattr(like, attr))


def add_head(spec: mujoco.MjSpec) -> None:
    """The head sphere (HEAD) on the base, colliding as the trunk-corner spheres do."""
    name, pos, radius = HEAD
    head = spec.body("base").add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_SPHERE,
                                      size=[radius, 0.0, 0.0], pos=list(pos))
    collide_like(head, spec.geom("trunk_fl"))


def add_calf_chains(spec: mujoco.MjSpec, legs: tuple[str, ...], like: str = "{leg}_shin") -> None:
    """Each leg's calf chain (CALF_DEPTHS, CALF_RADIUS) on its calf body, massless, colliding
    as that leg's geom `like` does (go2.xml's mid-shin sphere; e.g. "{leg}_calf_col" in
    go2_full.xml)."""
    for leg in legs:
        like_geom = spec.geom(like.format(leg=leg))
        body = spec.body(f"{leg}_calf")
        for name, pos in zip(calf_chain_names(leg), calf_chain_positions(), strict=True):
            geom = body.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_SPHERE,
                                 size=[CALF_RADIUS, 0.0, 0.0], pos=pos.tolist())
            geom.density = 0.0
            collide_like(geom, like_geom)


def calf_chain_ids(model: mujoco.MjModel, legs: tuple[str, ...]) -> np.ndarray:
    """[len(legs), k] geom ids of each leg's calf chain in `model` (k = 0 without one)."""
    ids = [[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, n) for n in calf_chain_names(leg)]
           for leg in legs]
    return np.array([i for i in ids if min(i) >= 0], np.int32).reshape(len(legs), -1)
