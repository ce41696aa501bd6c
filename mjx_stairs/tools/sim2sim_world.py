"""The sim-to-sim world: a Go2 MJCF (ours with full collision geometry, or any file with Unitree's
joint names and torque motors) among the stair geometry, in MuJoCo itself.

Everything is matched by name: the policy's joints (the sidecar's `joints.names`) are found in
the MJCF by name, each with the one torque motor that drives it, so a file whose actuators come
in another order (the Go2 SDK's FR, FL, RR, RL) drives the same joints. The staircase is a height
grid made of boxes (terrains.boxes: vertical risers, sharp edges); a heightfield is only for the
contract test, where the training env's bilinear heights are exact. Stair geoms sit in geom group
TERRAIN_GROUP, which the height-map rays alone look at.
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from mjx_stairs.sim import solref
from mjx_stairs.tools.contract import Contract
from terrains import sample_heights
from terrains.boxes import grid_boxes

OUR_ROBOT = Path(__file__).resolve().parents[1] / "sim" / "assets" / "go2_full.xml"


def file_sha256(path) -> str:
    """The SHA-256 of a file's bytes: which robot MJCF a record ran (go2_full.xml's calves
    changed on 2026-11-29 under the same name)."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()
TERRAIN_GROUP = 5
PARTS = ("trunk", "hip", "thigh", "calf", "foot")
"""Robot geoms by part: the base body's (trunk and head), hip, thigh, calf (its non-sphere
geoms) and foot (spheres in a calf or foot body)."""
FRICTION = 0.8
EDGE_RADIUS = 0.05  # m: a contact this close (in xy) to a height jump is at a step edge
EDGE_JUMP = 0.02  # m: the smallest height jump that is a step edge


class RobotError(ValueError):
    """The robot MJCF cannot be used (missing file, joint or motor)."""


@dataclass
class World:
    """A compiled world and the ids the runner reads (joint arrays in the contract's order)."""

    model: mujoco.MjModel
    data: mujoco.MjData
    base_body: int
    base_qpos: int  # qpos address of the free joint (x, y, z, qw, qx, qy, qz)
    base_dof: int
    qpos_adr: np.ndarray  # [12]
    dof_adr: np.ndarray  # [12]
    actuator: np.ndarray  # [12] the motor of each joint
    gear: np.ndarray  # [12]
    part: np.ndarray  # [ngeom] index into PARTS, -1 for terrain / non-colliding geoms
    terrain: np.ndarray  # [ngeom] bool: stair geoms
    edge: np.ndarray  # [ny, nx] bool: grid points within EDGE_RADIUS of a step edge
    grid_origin: np.ndarray  # [2] xy of grid point (0, 0)
    resolution: float
    ray_top: float  # m, rays start here (above everything)
    substeps: int  # physics steps per control step
    elevation: np.ndarray | None = None  # [ny, nx] m: the elevation map at the grid points,
    # ray cast as first asked for (NaN: not yet), for the sidecar's occlusion rule


def _load_spec(path: str | os.PathLike | None) -> mujoco.MjSpec:
    path = OUR_ROBOT if path is None else Path(path)
    if not path.is_file():
        raise RobotError(f"{path}: no such robot MJCF")
    try:
        return mujoco.MjSpec.from_file(str(path))
    except Exception as e:  # mujoco raises ValueError with a multi-line message
        raise RobotError(f"{path}: cannot load the MJCF ({str(e).splitlines()[0]})") from None


def _add_boxes(spec: mujoco.MjSpec, boxes: np.ndarray) -> None:
    """Stair boxes [M, 6] (centre, half sizes), shaded lighter the higher their top."""
    boxes = np.asarray(boxes, np.float64)
    top = boxes[:, 2] + boxes[:, 5]
    shade = (top - top.min()) / max(np.ptp(top), 1e-6)
    for i, (cx, cy, cz, hx, hy, hz) in enumerate(boxes):
        grey = 0.35 + 0.45 * shade[i]
        spec.worldbody.add_geom(
            name=f"stair{i}", type=mujoco.mjtGeom.mjGEOM_BOX, pos=[cx, cy, cz],
            size=[hx, hy, hz], contype=1, conaffinity=1, group=TERRAIN_GROUP,
            friction=[FRICTION, 0.02, 0.01], rgba=[grey, grey * 1.02, grey * 1.1, 1.0])


def _add_heightfield(spec: mujoco.MjSpec, heights: np.ndarray, resolution: float) -> None:
    """The grid as a heightfield with its corner point at the world origin (contract test)."""
    from mjx_stairs.sim.robot import add_heightfield

    add_heightfield(spec, np.asarray(heights, np.float32), resolution, FRICTION)
    geom = spec.geom("terrain")
    geom.group, geom.contype, geom.conaffinity = TERRAIN_GROUP, 1, 1


def edge_mask(heights: np.ndarray, resolution: float) -> np.ndarray:
    """[ny, nx] bool: grid points with a height difference > EDGE_JUMP within EDGE_RADIUS."""
    r = max(1, int(round(EDGE_RADIUS / resolution)))
    h = np.pad(np.asarray(heights, np.float64), r, mode="edge")
    ny, nx = heights.shape
    hi = np.full((ny, nx), -np.inf)
    lo = np.full((ny, nx), np.inf)
    for dy in range(2 * r + 1):
        for dx in range(2 * r + 1):
            win = h[dy:dy + ny, dx:dx + nx]
            hi, lo = np.maximum(hi, win), np.minimum(lo, win)
    return hi - lo > EDGE_JUMP


def build_world(contract: Contract, heights: np.ndarray, resolution: float,
                robot: str | os.PathLike | None = None, terrain: str = "boxes",
                pad: float = 3.0, contact_timeconst: float = 0.0) -> World:
    """The robot among the staircase `heights` [ny, nx] (grid point (ix, iy) at world
    (ix * res, iy * res)), padded by `pad` m of edge heights on every side (what the training
    env's height map reads past a tile's edge). `terrain`: "boxes" or "heightfield" (the grid
    as a MuJoCo heightfield, unpadded: for the contract test). `contact_timeconst` > 0: every
    geom's solref (timeconst, 1), robot and stairs (a contact mixes its two geoms'), in place of
    the MJCF's (MuJoCo's default 0.02 s): the stiffer contact of issue 19's spiral study, as the
    training option env.robot.contact_timeconst sets it in MJX."""
    spec = _load_spec(robot)
    if robot is None:
        spec.option.timestep = contract.physics_dt
    for g in spec.geoms:  # the rays see the terrain group alone
        if g.group == TERRAIN_GROUP:
            g.group = TERRAIN_GROUP - 1
    heights = np.asarray(heights, np.float64)
    if terrain == "heightfield":
        _add_heightfield(spec, heights, resolution)
        grid, origin = heights, np.zeros(2)
    elif terrain == "boxes":
        n = int(np.ceil(pad / resolution))
        grid, origin = np.pad(heights, n, mode="edge"), np.full(2, -n * resolution)
        _add_boxes(spec, grid_boxes(grid, resolution, origin=tuple(origin)))
    else:
        raise ValueError(f"terrain must be 'boxes' or 'heightfield', got {terrain!r}")
    if contact_timeconst < 0:
        raise ValueError(f"contact_timeconst must be 0 (the MJCF's) or > 0 s, got "
                         f"{contact_timeconst}")
    solref.set_timeconst(spec, contact_timeconst)  # after the last geom is added
    try:
        model = spec.compile()
    except Exception as e:
        raise RobotError(f"{robot or OUR_ROBOT}: cannot compile ({str(e).splitlines()[0]})"
                         ) from None
    return _world(model, contract, grid, origin, resolution, robot or OUR_ROBOT)


def _world(model: mujoco.MjModel, contract: Contract, grid: np.ndarray, origin: np.ndarray,
           resolution: float, source) -> World:
    free = [j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
    if len(free) != 1:
        raise RobotError(f"{source}: needs exactly one free joint (the base), has {len(free)}")
    ratio = contract.control_dt / model.opt.timestep
    if abs(ratio - round(ratio)) > 1e-6 or round(ratio) < 1:
        raise RobotError(f"{source}: timestep {model.opt.timestep:g} s does not divide the "
                         f"policy's control period {contract.control_dt:g} s")
    qpos, dof, act, gear = _joints_and_motors(model, contract.joint_names, source)
    terrain = model.geom_group == TERRAIN_GROUP
    return World(
        model=model, data=mujoco.MjData(model), base_body=int(model.jnt_bodyid[free[0]]),
        base_qpos=int(model.jnt_qposadr[free[0]]), base_dof=int(model.jnt_dofadr[free[0]]),
        qpos_adr=qpos, dof_adr=dof, actuator=act, gear=gear,
        part=_parts(model, terrain), terrain=terrain, edge=edge_mask(grid, resolution),
        grid_origin=np.asarray(origin, np.float64), resolution=float(resolution),
        ray_top=float(np.max(grid)) + 2.0, substeps=int(round(ratio)),
        elevation=np.full(grid.shape, np.nan))


def _joints_and_motors(model: mujoco.MjModel, names: tuple[str, ...], source):
    """qpos and dof addresses, motor ids and gears of the joints `names`, by name."""
    qpos, dof, act, gear = [], [], [], []
    for name in names:
        j = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        if j < 0:
            raise RobotError(f"{source}: no joint named {name!r} (the policy's joints are "
                             f"{', '.join(names)})")
        if model.jnt_type[j] != mujoco.mjtJoint.mjJNT_HINGE:
            raise RobotError(f"{source}: joint {name!r} is not a hinge")
        mine = [a for a in range(model.nu) if model.actuator_trntype[a] ==
                mujoco.mjtTrn.mjTRN_JOINT and model.actuator_trnid[a, 0] == j]
        if len(mine) != 1:
            raise RobotError(f"{source}: joint {name!r} needs exactly one actuator, has "
                             f"{len(mine)}")
        a = mine[0]
        motor = (model.actuator_gaintype[a] == mujoco.mjtGain.mjGAIN_FIXED
                 and model.actuator_biastype[a] == mujoco.mjtBias.mjBIAS_NONE
                 and model.actuator_dyntype[a] == mujoco.mjtDyn.mjDYN_NONE
                 and model.actuator_gainprm[a, 0] == 1.0)
        if not motor:
            raise RobotError(f"{source}: actuator {model.actuator(a).name!r} of {name!r} is not "
                             "a torque motor (gain 1, no bias, no dynamics)")
        qpos.append(model.jnt_qposadr[j])
        dof.append(model.jnt_dofadr[j])
        act.append(a)
        gear.append(model.actuator_gear[a, 0])
    return (np.asarray(qpos, np.int64), np.asarray(dof, np.int64), np.asarray(act, np.int64),
            np.asarray(gear, np.float64))


def _parts(model: mujoco.MjModel, terrain: np.ndarray) -> np.ndarray:
    """[ngeom] PARTS index of each robot geom that can touch the terrain, else -1."""
    out = np.full(model.ngeom, -1, np.int64)
    for g in range(model.ngeom):  # the stairs' contype and conaffinity are 1
        if terrain[g] or not (model.geom_contype[g] | model.geom_conaffinity[g]) & 1:
            continue
        b = model.geom_bodyid[g]
        if b == 0:
            continue
        name = model.body(b).name.lower()
        sphere = model.geom_type[g] == mujoco.mjtGeom.mjGEOM_SPHERE
        geom = model.geom(g).name.lower()
        if "calf" in geom and "foot" not in geom:  # e.g. go2.xml's calf chain (sim.geoms)
            out[g] = PARTS.index("calf")
        elif "foot" in name or "foot" in geom or (sphere and "calf" in name):
            out[g] = PARTS.index("foot")
        elif "calf" in name:
            out[g] = PARTS.index("calf")
        elif "thigh" in name:
            out[g] = PARTS.index("thigh")
        elif "hip" in name:
            out[g] = PARTS.index("hip")
        elif model.jnt_type[model.body_jntadr[b]] == mujoco.mjtJoint.mjJNT_FREE:
            out[g] = PARTS.index("trunk")
    return out


# ----------------------------------------------------------------------------- sensing


def terrain_z(w: World, xy: np.ndarray) -> np.ndarray:
    """[N] terrain height (m) under world points xy [N, 2]: vertical rays (mj_ray) from above
    everything, against the stair geoms alone; -inf where a ray hits nothing."""
    groups = np.zeros(6, np.uint8)
    groups[TERRAIN_GROUP] = 1
    down = np.array([0.0, 0.0, -1.0])
    hit = np.zeros(1, np.int32)
    out = np.empty(len(xy))
    pnt = np.array([0.0, 0.0, w.ray_top])
    for i, (x, y) in enumerate(np.asarray(xy, np.float64)):
        pnt[0], pnt[1] = x, y
        d = mujoco.mj_ray(w.model, w.data, pnt, down, groups, 1, -1, hit)
        out[i] = w.ray_top - d if d >= 0 else -np.inf
    return out


def elevation_z(w: World, xy: np.ndarray) -> np.ndarray:
    """[...] the elevation map's height at world points xy [..., 2]: bilinear between its grid
    points (terrains.sample_heights, as the training env reads its heightfield), clamped to the
    grid's edge; each grid point is a terrain_z ray cast, made once, when first needed."""
    q = np.asarray(xy, np.float64) - w.grid_origin
    ny, nx = w.elevation.shape
    ix = np.clip(np.floor(q[..., 0] / w.resolution).astype(np.int64), 0, nx - 2).ravel()
    iy = np.clip(np.floor(q[..., 1] / w.resolution).astype(np.int64), 0, ny - 2).ravel()
    rows, cols = np.concatenate([iy, iy, iy + 1, iy + 1]), np.concatenate([ix, ix + 1, ix, ix + 1])
    missing = np.isnan(w.elevation[rows, cols])
    if missing.any():
        need = np.unique(np.stack([rows[missing], cols[missing]], -1), axis=0)
        w.elevation[need[:, 0], need[:, 1]] = terrain_z(
            w, w.grid_origin + need[:, ::-1] * w.resolution)
    return sample_heights(w.elevation, w.resolution, q[..., 0], q[..., 1])


def touching_edges(w: World) -> np.ndarray:
    """[ngeom] bool: robot geoms touching a stair geom at a step edge now."""
    d = w.data
    out = np.zeros(w.model.ngeom, bool)
    if d.ncon == 0:
        return out
    con = d.contact
    g1, g2 = con.geom1[: d.ncon], con.geom2[: d.ncon]
    robot_geom = np.where(w.terrain[g1], g2, g1)
    stair = w.terrain[g1] ^ w.terrain[g2]
    ij = np.round((con.pos[: d.ncon, :2] - w.grid_origin) / w.resolution).astype(np.int64)
    ny, nx = w.edge.shape
    ix, iy = np.clip(ij[:, 0], 0, nx - 1), np.clip(ij[:, 1], 0, ny - 1)
    at_edge = stair & w.edge[iy, ix] & (con.dist[: d.ncon] < 1e-3)
    out[robot_geom[at_edge]] = True
    return out
