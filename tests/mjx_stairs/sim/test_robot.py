"""The Go2 model: compiles in MuJoCo and MJX, matches the reference, stands, and touches terrain."""

import dataclasses

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from mujoco import mjx

from mjx_stairs.sim import robot as rb
from mjx_stairs.sim import touch

# shared/reference/go2.md, typed in independently of the model.
REFERENCE_RANGE = {
    "hip": (-1.0472, 1.0472),
    "front_thigh": (-1.5708, 3.4907),
    "rear_thigh": (-0.5236, 4.5379),
    "calf": (-2.7227, -0.83776),
}
REFERENCE_TORQUE = {"hip": 23.7, "thigh": 23.7, "calf": 45.43}

RES = 0.05
SIM_STEPS = 400  # 2 s at 5 ms


HOLD_CHUNK = 20  # steps per compiled call (a program per collider and heightfield size)


@jax.jit
def _hold_chunk(mx, d, qpos_joints, qvel_joints):
    """HOLD_CHUNK MJX steps with PD holding the nominal pose; the model is an argument, so
    models of one collider whose heightfields have the same size (grid and elevation range: MJX
    keeps hfield_size static) share the compiled program, and a test holds for any length."""
    limit = jnp.asarray(rb.TORQUE_LIMIT)
    target = jnp.asarray(rb.NOMINAL_JOINT_POS)

    def sub(d, _):
        tau = rb.pd_torque(target, d.qpos[qpos_joints], d.qvel[qvel_joints], 35.0, 1.0, limit)
        d = mjx.step(mx, d.replace(ctrl=tau))
        return d, d.qpos

    return jax.lax.scan(sub, d, None, length=HOLD_CHUNK)


def _hold_pose(model: mujoco.MjModel, qpos0: np.ndarray, steps: int):
    """Run MJX with PD holding the nominal pose; returns qpos [steps, 19] and final MJX data."""
    assert steps % HOLD_CHUNK == 0, steps
    ids = rb.robot_ids(model)
    mx = mjx.put_model(model)
    d = mjx.make_data(mx).replace(qpos=jnp.asarray(qpos0))
    # every input committed to the device, as the outputs fed back are: one program, not two
    mx, d, joints = jax.device_put((mx, d, (ids.qpos_joints, ids.qvel_joints)), jax.devices()[0])
    traj = []
    for _ in range(steps // HOLD_CHUNK):
        d, q = _hold_chunk(mx, d, *joints)
        traj.append(np.asarray(q))
    return np.concatenate(traj), d


@pytest.fixture(scope="module")
def flat_model():
    return rb.build_mj_model(np.zeros((161, 161), np.float32), RES)


def test_compiles_in_mujoco_and_mjx(flat_model):
    m = flat_model
    assert m.nq == 19 and m.nv == 18 and m.nu == 12
    traj, d = _hold_pose(m, rb.standing_qpos((4, 4)), HOLD_CHUNK)  # the program others reuse
    assert np.all(np.isfinite(traj)) and np.all(np.isfinite(np.asarray(d.qvel)))
    assert m.opt.timestep == pytest.approx(0.005)


def test_total_mass(flat_model):
    assert flat_model.body_subtreemass[flat_model.body("base").id] == pytest.approx(15.2, abs=0.3)


def test_joint_ranges_and_torque_limits_match_reference(flat_model):
    m = flat_model
    for name in rb.JOINT_NAMES:
        leg, part = name.split("_")[0], name.split("_")[1]
        key = part if part != "thigh" else ("front_thigh" if leg[0] == "F" else "rear_thigh")
        np.testing.assert_allclose(m.joint(name).range, REFERENCE_RANGE[key], atol=1e-6)
        act = m.actuator(f"{leg}_{part}")
        assert act.trnid[0] == m.joint(name).id
        np.testing.assert_allclose(act.ctrlrange, [-REFERENCE_TORQUE[part], REFERENCE_TORQUE[part]])
    np.testing.assert_allclose(
        rb.TORQUE_LIMIT, [REFERENCE_TORQUE[p.split("_")[1]] for p in rb.JOINT_NAMES]
    )


def test_only_sphere_terrain_collisions(flat_model):
    m = flat_model
    terrain = m.geom("terrain").id
    colliding = [g for g in range(m.ngeom) if m.geom_contype[g] or m.geom_conaffinity[g]]
    for g in colliding:
        if g == terrain:
            continue
        assert m.geom_type[g] == mujoco.mjtGeom.mjGEOM_SPHERE
        # robot geoms never collide with each other: contype & conaffinity is 0 among them
        assert m.geom_conaffinity[g] == 0
    names = {m.geom(g).name for g in colliding}
    for group in ("foot", "knee", "shin", "trunk"):
        assert set(rb.SPHERE_GROUPS[group]) <= names


def test_stands_on_flat_heightfield(flat_model):
    traj, _ = _hold_pose(flat_model, rb.standing_qpos((4.0, 4.0), 0.40), SIM_STEPS)
    final = traj[-1]
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, final[3:7].astype(np.float64))
    tilt = np.arccos(np.clip(rot[8], -1, 1))  # angle between body z and world z
    assert tilt < 0.1
    assert 0.25 <= final[2] <= 0.35
    landed = traj[60]  # 0.3 s: the feet are down
    assert np.linalg.norm(final[:2] - landed[:2]) < 0.05


@pytest.mark.parametrize("terrain_contacts", ["mjx", "nearest"])
def test_foot_pressed_into_step_is_pushed_out(terrain_contacts):
    heights = np.zeros((161, 161), np.float32)
    heights[:, 60:] = 0.10  # a 10 cm step for x >= 3 m
    model = rb.build_mj_model(heights, RES, rb.RobotConfig(terrain_contacts=terrain_contacts))
    data = mujoco.MjData(model)
    data.qpos[:] = rb.standing_qpos((5.0, 4.0), 0.0)
    mujoco.mj_kinematics(model, data)
    feet = [model.geom(n).id for n in rb.SPHERE_GROUPS["foot"]]
    lowest = min(data.geom_xpos[g][2] for g in feet) - 0.022
    # Feet 1.5 cm inside the step's top surface.
    data.qpos[2] = 0.10 - 0.015 - lowest
    traj, d = _hold_pose(model, data.qpos.copy(), 40)
    mujoco.mj_kinematics(model, data)
    data.qpos[:] = traj[-1]
    mujoco.mj_kinematics(model, data)
    bottoms = [data.geom_xpos[g][2] - 0.022 for g in feet]
    assert min(bottoms) > 0.10 - 0.006, bottoms  # pushed back out of the step
    assert np.any(np.asarray(d._impl.contact.dist) < 1e-3)  # through heightfield contacts


def test_the_head_sphere_is_a_trunk_sphere_where_configured():
    """robot.head_collision: the head (assets/go2_full.xml's lower head sphere) touches the
    terrain in MJX (our columns collider) and in the ground truth's box world, as a trunk
    sphere; without it the trunk is the four corners of go2.xml."""
    from mjx_stairs.sim import box_world

    heights = np.zeros((41, 41), np.float32)
    plain = rb.build_mj_model(heights, 0.25, rb.RobotConfig(terrain_contacts="columns"))
    assert len(rb.robot_ids(plain).trunk_geoms) == 4
    assert mujoco.mj_name2id(plain, mujoco.mjtObj.mjOBJ_GEOM, rb.HEAD[0]) == -1
    cfg = rb.RobotConfig(terrain_contacts="columns", head_collision=True)
    model = rb.build_mj_model(heights, 0.25, cfg)
    ids = rb.robot_ids(model)
    head = model.geom(rb.HEAD[0])
    assert ids.trunk_geoms[-1] == head.id and len(ids.trunk_geoms) == 5
    assert head.size[0] == rb.HEAD[2] and head.bodyid[0] == ids.base_body
    np.testing.assert_allclose(model.body_mass, plain.body_mass)  # collision only
    # level, the head's bottom 1 cm into the floor, the trunk corners 2.7 cm above it
    qpos = rb.standing_qpos((5.0, 5.0), rb.HEAD[2] - rb.HEAD[1][2] - 0.01)
    d = jax.jit(mjx.forward)(mjx.put_model(model), mjx.make_data(model).replace(
        qpos=jnp.asarray(qpos)))
    touching = touch.sphere_contacts(d, touch.sphere_contact_rows(model, ids))["trunk"]
    assert np.asarray(touching).tolist() == [False] * 4 + [True]
    # the ground truth's robot: the same sphere against a box top
    world = box_world.build_model(np.array([[5.3, 5.0, -0.05, 0.2, 0.2, 0.05]]), cfg)
    data = mujoco.MjData(world)
    data.qpos[:] = qpos
    mujoco.mj_forward(world, data)
    pairs = {world.geom(int(g)).name for g in data.contact.geom1[:data.ncon]} | {
        world.geom(int(g)).name for g in data.contact.geom2[:data.ncon]}
    assert rb.HEAD[0] in pairs and not pairs & set(rb.SPHERE_GROUPS["trunk"])


def test_contact_timeconst_stiffens_both_simulators_contacts():
    """RobotConfig.contact_timeconst sets every geom's solref, the robot's and the terrain's, in
    the MJX model and the ground truth's box world alike (0 leaves MuJoCo's 0.02 s); in MuJoCo
    itself the stiffer contact lets a standing robot's feet sink less into a box floor."""
    from mjx_stairs.config import ConfigError
    from mjx_stairs.sim import box_world

    heights = np.zeros((41, 41), np.float32)
    stiff = rb.RobotConfig(terrain_contacts="columns", contact_timeconst=0.01)
    for model in (rb.build_mj_model(heights, 0.25, stiff),
                  box_world.build_model(np.array([[5.0, 5.0, -0.05, 1.0, 1.0, 0.05]]), stiff)):
        np.testing.assert_array_equal(model.geom_solref, [[0.01, 1.0]] * model.ngeom)
    default = rb.build_mj_model(heights, 0.25, rb.RobotConfig(terrain_contacts="columns"))
    np.testing.assert_array_equal(default.geom_solref[:, 0], 0.02)
    sink = {}
    for tc in (0.0, 0.01):
        world = box_world.build_model(np.array([[5.0, 5.0, -0.05, 1.0, 1.0, 0.05]]),
                                      rb.RobotConfig(contact_timeconst=tc))
        data = mujoco.MjData(world)
        data.qpos[:] = rb.standing_qpos((5.0, 5.0), rb.NOMINAL_BASE_HEIGHT)
        data.ctrl[:] = rb.NOMINAL_JOINT_POS
        for _ in range(400):  # 2 s holding the nominal pose
            mujoco.mj_step(world, data)
        sink[tc] = -min(data.contact.dist[:data.ncon])
    assert 0 < sink[0.01] < 0.7 * sink[0.0]
    with pytest.raises(ConfigError, match="env.robot.contact_timeconst"):
        rb.RobotConfig(contact_timeconst=0.005)


def _column_under(model, qpos, geom: str, heights, res) -> list[float]:
    """Raise the grid column under sphere `geom` of the robot at `qpos` to 5 mm above the
    sphere's bottom (in `heights`, in place); the same column as a box (cx, cy, cz, hx, hy, hz)."""
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    centre = data.geom_xpos[model.geom(geom).id]
    ix, iy = np.round(centre[:2] / res).astype(int)
    heights[iy, ix] = centre[2] - model.geom(geom).size[0] + 0.005
    return [ix * res, iy * res, heights[iy, ix] / 2, res / 2, res / 2, heights[iy, ix] / 2]


def _mjx_touching(heights, res, cfg, qpos) -> dict[str, list[bool]]:
    """{group: [n] bool} which sphere groups of robot `cfg` at `qpos` touch `heights` in MJX."""
    m = rb.build_mj_model(heights, res, cfg)
    d = jax.jit(mjx.forward)(mjx.put_model(m), mjx.make_data(m).replace(qpos=jnp.asarray(qpos)))
    rows = touch.sphere_contact_rows(m, rb.robot_ids(m))
    return {k: np.asarray(v).tolist() for k, v in touch.sphere_contacts(d, rows).items()}


def _box_touch(box, cfg, qpos):
    """(model, names of the geoms in contact) of robot `cfg` at `qpos` beside the one `box` in
    the ground truth's box world (MuJoCo itself)."""
    from mjx_stairs.sim import box_world

    world = box_world.build_model(np.array([box]), cfg)
    data = mujoco.MjData(world)
    data.qpos[:] = qpos
    mujoco.mj_forward(world, data)
    return world, {world.geom(int(g)).name for g in data.contact.geom[:data.ncon].ravel()}


def test_calf_chain_covers_the_calf_and_touches_a_step_edge_as_a_calf():
    """robot.calf_collision: spheres along each calf as go2_full.xml shapes it (two capsules
    along the link's bow), overlapping; a column poking 5 mm into the front-left calf's upper
    stretch is a calf contact of that leg alone in MJX (our columns collider) and touches the
    chain in the ground truth's box world, where the robot without the chain touches nothing."""
    from mjx_stairs.sim import geoms
    from mjx_stairs.tools import sim2sim_world as sw

    cfg = rb.RobotConfig(terrain_contacts="columns", calf_collision=True)
    res = 0.025
    heights = np.zeros((41, 41), np.float32)
    model = rb.build_mj_model(heights, res, cfg)
    ids = rb.robot_ids(model)
    assert ids.calf_geoms.shape == (4, geoms.CALF_CHAIN_LEN)
    assert rb.robot_ids(rb.build_mj_model(heights, res)).calf_geoms.shape == (4, 0)
    # along both axes of go2_full.xml's FL calf every point lies at least (capsule radius - 4.2
    # mm) deep inside one sphere of training's calf: a sharp edge across the calf that reaches
    # 4.2 mm into the full robot's calf meets a sphere, it cannot slip between two
    full = mujoco.MjModel.from_xml_path(str(rb.ASSET.parent / "go2_full.xml"))
    caps = [full.geom(n) for n in ("FL_calf_col", "FL_calf_col_lower")]
    leg = [model.geom(f"FL_{p}") for p in ("knee", "shin", "foot")]
    leg += [model.geom(n) for n in geoms.calf_chain_names("FL")]
    for cap, (a, b, r) in zip(caps, geoms.CALF_SHAPE, strict=True):  # the one source of both
        assert cap.size[0] == r
        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, cap.quat)  # the geom in its calf body's frame
        ends = [cap.pos + s * cap.size[1] * rot.reshape(3, 3)[:, 2] for s in (-1.0, 1.0)]
        assert np.allclose(sorted(ends, key=lambda e: e[2]), sorted([b, a], key=lambda e: e[2]),
                           atol=1e-6)
        axis = np.asarray(a) + np.linspace(0.0, 1.0, 1000)[:, None] * (np.subtract(b, a))
        depth = np.zeros(len(axis))
        for g in leg:
            inside = g.size[0] ** 2 - np.sum((axis - g.pos) ** 2, axis=-1)
            depth = np.maximum(depth, np.sqrt(np.clip(inside, 0.0, None)))
        assert depth.min() >= r - geoms.CALF_EDGE_GAP - 1e-6, (depth.min(), r)
    # a column under a chain sphere between the knee and mid-shin spheres, its top 5 mm above
    # the sphere's bottom
    qpos = rb.standing_qpos((0.5, 0.5), 0.445)
    box = _column_under(model, qpos, "FL_calf_chain2", heights, res)
    touching = {calf: _mjx_touching(heights, res, dataclasses.replace(cfg, calf_collision=calf),
                                    qpos) for calf in (False, True)}
    assert touching[True]["shin"] == [True, False, False, False]
    assert not any(any(v) for v in touching[False].values()), touching[False]
    assert not any(touching[True][g][i] for g in ("foot", "knee", "trunk") for i in range(4))
    # the same column as a box in the ground truth's world
    for calf in (False, True):
        world, names = _box_touch(box, dataclasses.replace(cfg, calf_collision=calf), qpos)
        assert (names & set(geoms.calf_chain_names("FL")) != set()) == calf, names
        assert names <= {"stair0", *geoms.calf_chain_names("FL")}, names
        if calf:  # sim2sim's step-edge counts: the chain's touches are calf touches
            stairs = np.array([world.geom(g).name == "stair0" for g in range(world.ngeom)])
            parts = [sw.PARTS[i] for i in sw._parts(world, stairs)]
            assert {parts[world.geom(n).id] for n in geoms.calf_chain_names("RR")} == {"calf"}
            assert parts[world.geom("RR_foot").id] == "foot"


def test_thigh_chain_covers_the_thigh_and_touches_a_step_edge_as_a_thigh():
    """robot.thigh_collision: spheres along each thigh as go2_full.xml's thigh capsule lies,
    overlapping; a column poking 5 mm into the front-left thigh (held out forward, the calf
    pointing up, nothing else above the floor there) is a knee (thigh) contact of that leg alone
    in MJX and touches the chain in the ground truth's box world, where the robot without the
    chain touches nothing; sim2sim counts the chain's touches as thigh touches."""
    from mjx_stairs.sim import geoms
    from mjx_stairs.tools import sim2sim_world as sw

    cfg = rb.RobotConfig(terrain_contacts="columns", thigh_collision=True)
    res = 0.025
    heights = np.zeros((41, 41), np.float32)
    model = rb.build_mj_model(heights, res, cfg)
    assert rb.robot_ids(model).thigh_geoms.shape == (4, 9)
    assert rb.robot_ids(rb.build_mj_model(heights, res)).thigh_geoms.shape == (4, 0)
    full = mujoco.MjModel.from_xml_path(str(rb.ASSET.parent / "go2_full.xml"))
    cap = full.geom("FL_thigh_col")
    ((a, b, r),) = geoms.THIGH_SHAPE  # the one source of both
    assert cap.size[0] == r and np.allclose(cap.pos, np.add(a, b) / 2, atol=1e-6)
    assert cap.size[1] == pytest.approx(np.linalg.norm(np.subtract(b, a)) / 2)
    # every point of the capsule's axis lies >= r - 4.2 mm deep inside a chain or knee sphere
    axis = np.asarray(a) + np.linspace(0.0, 1.0, 1000)[:, None] * np.subtract(b, a)
    centres, radii = geoms.thigh_chain_spheres()
    centres = np.vstack([centres, geoms.THIGH_TO_CALF])
    radii = np.append(radii, model.geom("FL_knee").size[0])
    depth = np.sqrt(np.clip(radii**2 - np.sum((axis[:, None] - centres) ** 2, -1), 0, None))
    assert depth.max(-1).min() >= r - geoms.CALF_EDGE_GAP - 1e-6
    qpos = rb.standing_qpos((0.5, 0.5), 0.445)
    qpos[7 + 1:7 + 3] = (-1.5708, -0.9)  # FL thigh forward, its calf up
    box = _column_under(model, qpos, "FL_thigh_chain4", heights, res)
    touching = {thigh: _mjx_touching(heights, res, dataclasses.replace(
        cfg, thigh_collision=thigh), qpos) for thigh in (False, True)}
    assert touching[True]["knee"] == [True, False, False, False], touching[True]
    assert not any(touching[True][g][i] for g in ("foot", "shin", "trunk") for i in range(4))
    assert not any(any(v) for v in touching[False].values()), touching[False]
    chain = set(geoms.chain_names("FL", "thigh"))
    for thigh in (False, True):
        world, names = _box_touch(box, dataclasses.replace(cfg, thigh_collision=thigh), qpos)
        assert bool(names & chain) == thigh and names <= {"stair0"} | chain, names
    stairs = np.array([world.geom(g).name == "stair0" for g in range(world.ngeom)])
    parts = [sw.PARTS[i] for i in sw._parts(world, stairs)]
    assert {parts[world.geom(n).id] for n in geoms.chain_names("RR", "thigh")} == {"thigh"}
