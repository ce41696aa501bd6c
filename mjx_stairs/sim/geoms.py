"""Collision spheres that a `RobotConfig` adds to assets/go2.xml: the head and the calf chains.

go2.xml collides through spheres only (feet, knees, mid-shins, trunk corners), which leaves
two stretches of each calf bare: between the knee sphere (r 0.025 at the knee) and the mid-shin
one (r 0.018 at 0.11 m), and between that and the foot (r 0.022 at 0.213 m). In MuJoCo itself
the full robot's calves (assets/go2_full.xml) touch step edges there: up to 100 times an episode
for a generalist at the Go2's joint damping of 2, where training saw nothing (docs/deploy.md,
session 31). The calf chain puts spheres along the calf as the full robot has it (CALF_SHAPE:
two capsules along the link's forward bow, 1-2 cm ahead of the knee-foot axis at mid-calf), so
that MJX sees what touches a real step edge through the sphere colliders it already has (the
heightfield and column colliders of `sim.contact`). Why the bow and not the axis (until
2026-11-29 both the chain and go2_full.xml's one capsule ran on the axis): on L-shaped level 6 at
damping 2 MuJoCo itself climbed 33 % with a straight calf capsule, 71 with go2.xml's mid-shin
sphere added (5-9 mm proud of it), 58 with the bowed calf, against MJX's 59.8 (docs/deploy.md,
session 32): the shape of the calf's front decides it.
"""

from __future__ import annotations

import mujoco
import numpy as np

HEAD = ("trunk_head", (0.293, 0.0, -0.06), 0.047)
"""(name, position in the base frame, radius) of the head sphere that `RobotConfig.head_collision`
adds to the trunk group: the lower head sphere of assets/go2_full.xml, 12 cm ahead of the trunk
corners; in sim2sim the head touches step edges up to 12 times per episode up 14 cm risers."""

CALF_SHAPE = (((-0.0045, 0.0, -0.0013), (0.0205, 0.0, -0.1187), 0.013),
              ((0.0216, 0.0, -0.1155), (0.0184, 0.0, -0.1805), 0.011))
"""(from, to, radius) in the calf body's frame of the two capsules that make the calf in
assets/go2_full.xml: the link's forward bow, 1-2 cm ahead of the knee-foot axis at mid-calf, as
MuJoCo Menagerie's unitree_go2 (BSD-3-Clause) models the calf with two cylinders (reference data:
their centres, half-lengths and tilts; its upper radius is 12 mm, ours 13, the straight capsule's
that go2_full.xml had until 2026-11-29). go2.md gives no calf shape."""

CALF_EDGE_GAP = 0.0042
"""How far (m) inside a calf capsule's surface a sharp step edge across the calf may reach before
it meets a chain sphere: consecutive spheres are close enough that every point of a capsule's
axis lies at least radius - CALF_EDGE_GAP deep inside one (a chain must overlap, not only touch,
or an edge passes between two spheres)."""

KNEE_RADIUS = 0.025
"""go2.xml's knee sphere (at the calf body's origin): chain spheres inside it are left out."""


def calf_chain_spheres() -> tuple[np.ndarray, np.ndarray]:
    """([k, 3] centres, [k] radii) in the calf body's frame: spheres of each CALF_SHAPE capsule's
    radius along its axis, end to end, spaced by the CALF_EDGE_GAP rule; those inside the knee
    sphere and a second capsule's first one (within a radius of the first capsule's last) left
    out. 11 per calf."""
    centres, radii = [], []
    for a, b, r in CALF_SHAPE:
        a, b = np.asarray(a), np.asarray(b)
        spacing = 2.0 * np.sqrt(r**2 - (r - CALF_EDGE_GAP) ** 2)
        for t in np.linspace(0.0, 1.0, int(np.ceil(np.linalg.norm(b - a) / spacing)) + 1):
            p = a + t * (b - a)
            if np.linalg.norm(p) + r <= KNEE_RADIUS:
                continue
            if centres and np.linalg.norm(p - centres[-1]) < r:
                continue
            centres.append(p)
            radii.append(r)
    return np.array(centres), np.array(radii)


CALF_CHAIN_LEN = len(calf_chain_spheres()[1])
"""Chain spheres per calf."""


def calf_chain_names(leg: str) -> tuple[str, ...]:
    """Geom names of one leg's calf chain (leg: FL, FR, RL or RR)."""
    return tuple(f"{leg}_calf_chain{i}" for i in range(CALF_CHAIN_LEN))


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
    """Each leg's calf chain (calf_chain_spheres) on its calf body, massless, colliding as that
    leg's geom `like` does (go2.xml's mid-shin sphere; e.g. "{leg}_calf_col" in go2_full.xml)."""
    centres, radii = calf_chain_spheres()
    for leg in legs:
        like_geom = spec.geom(like.format(leg=leg))
        body = spec.body(f"{leg}_calf")
        for name, pos, r in zip(calf_chain_names(leg), centres, radii, strict=True):
            geom = body.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_SPHERE,
                                 size=[float(r), 0.0, 0.0], pos=pos.tolist())
            geom.density = 0.0
            collide_like(geom, like_geom)


def calf_chain_ids(model: mujoco.MjModel, legs: tuple[str, ...]) -> np.ndarray:
    """[len(legs), k] geom ids of each leg's calf chain in `model` (k = 0 without one)."""
    ids = [[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, n) for n in calf_chain_names(leg)]
           for leg in legs]
    return np.array([i for i in ids if min(i) >= 0], np.int32).reshape(len(legs), -1)
