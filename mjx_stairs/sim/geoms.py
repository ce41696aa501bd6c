"""Collision geoms that a `RobotConfig` adds to assets/go2.xml: the head, calf and thigh chains.

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
session 32): the shape of the calf's front decides it. The thigh chain does the same for
go2_full.xml's thigh capsule, which go2.xml leaves bare but for the knee sphere at its lower end:
in MuJoCo itself the full robot without its thighs descended a residential U flight 4.9 points
less often (docs/results.md 8ak), so the real thighs bear on step edges that training did not see.
`add_capsules` adds the same limbs as go2_full.xml's capsules instead (`RobotConfig.limb_capsules`,
collided in MJX by `sim.capsule` with two contacts each where a chain has two a sphere).
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

THIGH_SHAPE = (((0.0, 0.0, -0.02), (0.0, 0.0, -0.195), 0.02),)
"""(from, to, radius) in the thigh body's frame of assets/go2_full.xml's thigh capsule (its
`thigh_col` class), the thigh's length from below the hip to above the knee sphere."""

KNEE = ((0.0, 0.0, 0.0), 0.025)
"""go2.xml's knee sphere (centre in the calf body's frame, radius): chain spheres inside it are
left out."""

THIGH_TO_CALF = (0.0, 0.0, -0.213)
"""The calf body's origin (the knee) in the thigh body's frame (assets/go2.xml)."""


def chain_spheres(shape, inside: tuple = KNEE) -> tuple[np.ndarray, np.ndarray]:
    """([k, 3] centres, [k] radii) in a body's frame: spheres of each of `shape`'s capsules
    ((from, to, radius) in that frame) of its radius along its axis, end to end, spaced by the
    CALF_EDGE_GAP rule; those inside the sphere `inside` ((centre, radius) in the same frame) and
    a later capsule's first one (within a radius of the earlier capsule's last) left out."""
    centres, radii = [], []
    for a, b, r in shape:
        a, b = np.asarray(a), np.asarray(b)
        spacing = 2.0 * np.sqrt(r**2 - (r - CALF_EDGE_GAP) ** 2)
        for t in np.linspace(0.0, 1.0, int(np.ceil(np.linalg.norm(b - a) / spacing)) + 1):
            p = a + t * (b - a)
            if np.linalg.norm(p - inside[0]) + r <= inside[1]:
                continue
            if centres and np.linalg.norm(p - centres[-1]) < r:
                continue
            centres.append(p)
            radii.append(r)
    return np.array(centres), np.array(radii)


def calf_chain_spheres() -> tuple[np.ndarray, np.ndarray]:
    """CALF_SHAPE's chain in the calf body's frame (chain_spheres). 11 per calf."""
    return chain_spheres(CALF_SHAPE)


def thigh_chain_spheres() -> tuple[np.ndarray, np.ndarray]:
    """THIGH_SHAPE's chain in the thigh body's frame (chain_spheres). 9 per thigh."""
    return chain_spheres(THIGH_SHAPE, (np.add(KNEE[0], THIGH_TO_CALF), KNEE[1]))


CHAINS = {"calf": calf_chain_spheres, "thigh": thigh_chain_spheres}
"""The chains by the link (body `{leg}_{link}`) they lie along."""

SHAPES = {"calf": CALF_SHAPE, "thigh": THIGH_SHAPE}
"""The capsules (RobotConfig.limb_capsules) by the link they lie along."""

CALF_CHAIN_LEN = len(calf_chain_spheres()[1])
"""Chain spheres per calf."""


def chain_names(leg: str, link: str = "calf") -> tuple[str, ...]:
    """Geom names of one leg's chain along `link` (leg: FL, FR, RL or RR; link: calf or thigh)."""
    return tuple(f"{leg}_{link}_chain{i}" for i in range(len(CHAINS[link]()[1])))


def calf_chain_names(leg: str) -> tuple[str, ...]:
    """Geom names of one leg's calf chain (leg: FL, FR, RL or RR)."""
    return chain_names(leg, "calf")


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
    add_chains(spec, legs, "calf", like)


def add_chains(spec: mujoco.MjSpec, legs: tuple[str, ...], link: str, like: str) -> None:
    """Each leg's chain along `link` (CHAINS) on its `{leg}_{link}` body, massless, colliding as
    that leg's geom `like` does (e.g. "{leg}_knee", go2.xml's knee sphere, for the thighs)."""
    centres, radii = CHAINS[link]()
    for leg in legs:
        like_geom = spec.geom(like.format(leg=leg))
        body = spec.body(f"{leg}_{link}")
        for name, pos, r in zip(chain_names(leg, link), centres, radii, strict=True):
            geom = body.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_SPHERE,
                                 size=[float(r), 0.0, 0.0], pos=pos.tolist())
            geom.density = 0.0
            collide_like(geom, like_geom)


def add_capsules(spec: mujoco.MjSpec, legs: tuple[str, ...], link: str, like: str) -> None:
    """Each leg's capsules along `link` (SHAPES: go2_full.xml's) on its `{leg}_{link}` body,
    massless, named `{leg}_{link}_cap<i>`, colliding as that leg's geom `like` does (collided
    with the terrain by sim.capsule in MJX)."""
    for leg in legs:
        like_geom = spec.geom(like.format(leg=leg))
        for i, (a, b, r) in enumerate(SHAPES[link]):
            geom = spec.body(f"{leg}_{link}").add_geom(
                name=f"{leg}_{link}_cap{i}", type=mujoco.mjtGeom.mjGEOM_CAPSULE,
                size=[float(r), 0.0, 0.0], fromto=[*a, *b])
            geom.density = 0.0
            collide_like(geom, like_geom)


def chain_ids(model: mujoco.MjModel, legs: tuple[str, ...], link: str = "calf") -> np.ndarray:
    """[len(legs), k] geom ids of each leg's chain along `link` in `model`, or of its capsules
    (add_capsules) where it has those (k = 0 without either)."""
    def ids(names):
        return [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, n) for n in names]

    out = [ids(chain_names(leg, link)) for leg in legs]
    out = [i for i in out if min(i) >= 0]
    if not out:
        caps = len(SHAPES[link])
        out = [i for i in (ids(f"{leg}_{link}_cap{j}" for j in range(caps)) for leg in legs)
               if min(i) >= 0]
    return np.array(out, np.int32).reshape(len(legs), -1)

