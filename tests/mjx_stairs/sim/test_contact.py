"""The 'nearest' sphere-terrain collider (mjx_stairs.sim.contact): geometry against a brute-force
reference, registration beside MJX's own collider, and physics that agrees with MJX's collider."""

import dataclasses

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from mujoco import mjx
from mujoco.mjx._src import collision_driver, mesh
from mujoco.mjx._src.collision_types import GeomInfo, HFieldInfo
from mujoco.mjx._src.types import GeomType

from mjx_stairs.sim import contact
from mjx_stairs.sim import robot as rb

from .test_robot import RES, _hold_pose

NX, NY, CELL = 9, 7, 0.05


def _grid_heights(rng):
    """[NX, NY] heights (MJX's z[ix, iy] layout): two stair risers along x plus a little noise."""
    x = np.arange(NX) * CELL
    steps = 0.15 * (x >= 0.12) + 0.15 * (x >= 0.27)
    return (steps[:, None] + 0.01 * rng.uniform(size=(NX, NY))).astype(np.float32)


def _triangles(z):
    """All triangles of the grid in MuJoCo's split, as [T, 3, 3] (same frame as the collider)."""
    sx, sy = 0.5 * (NX - 1) * CELL, 0.5 * (NY - 1) * CELL
    tris = []
    for i in range(NX - 1):
        for j in range(NY - 1):
            v = {
                (a, b): np.array([(i + a) * CELL - sx, (j + b) * CELL - sy, z[i + a, j + b]])
                for a in (0, 1)
                for b in (0, 1)
            }
            tris.append([v[0, 0], v[1, 1], v[0, 1]])
            tris.append([v[0, 0], v[1, 0], v[1, 1]])
    return np.array(tris)


def _brute_force_distance(p, tris, n=80):
    """Unsigned distance from p to the surface by dense sampling of every triangle."""
    u, v = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    keep = u + v <= 1
    u, v = u[keep], v[keep]
    a, b, c = tris[:, 0], tris[:, 1], tris[:, 2]
    pts = a[:, None] + u[None, :, None] * (b - a)[:, None] + v[None, :, None] * (c - a)[:, None]
    return np.min(np.linalg.norm(pts - p, axis=-1))


def _surface_height(xy, tris):
    """The surface height at xy: interpolated in the triangle whose footprint contains xy."""
    for a, b, c in tris:
        m = np.array([b[:2] - a[:2], c[:2] - a[:2]]).T
        u, v = np.linalg.solve(m, xy - a[:2])
        if u >= -1e-9 and v >= -1e-9 and u + v <= 1 + 1e-9:
            return a[2] + u * (b[2] - a[2]) + v * (c[2] - a[2])
    raise AssertionError(f"{xy} is outside the grid")


def test_nearest_point_matches_brute_force_reference():
    rng = np.random.default_rng(0)
    z = _grid_heights(rng)
    tris = _triangles(z)
    size = np.array([0.5 * (NX - 1) * CELL, 0.5 * (NY - 1) * CELL, 1.0, 0.1])
    h = HFieldInfo(jnp.zeros(3), jnp.eye(3), size, NY, NX, jnp.asarray(z))
    fn = jax.jit(lambda pos, r: contact.sphere_heightfield(
        h, GeomInfo(pos, jnp.eye(3), jnp.array([r, r, r])), (4, 4)))
    checked = 0
    for _ in range(40):
        r = rng.uniform(0.015, 0.05)
        xy = rng.uniform(-0.08, 0.08, size=2)
        # a centre from 2 cm under the surface to 6 cm above it
        top = _surface_height(xy, tris)
        p = np.array([*xy, top + rng.uniform(-0.02, 0.06)])
        dist, pos, frame = (np.asarray(a) for a in fn(jnp.asarray(p, jnp.float32), r))
        ref = _brute_force_distance(p, tris)
        below = p[2] < top
        expected = (-ref if below else ref) - r
        assert dist[0] == pytest.approx(expected, abs=1.5e-3), (p, r, dist, expected)
        assert dist[0] <= dist[1] + 1e-6
        n = frame[0, 0]
        assert np.linalg.norm(n) == pytest.approx(1.0, abs=1e-5)
        # the contact point is midway between the surface point and the sphere's deepest point
        surface_pt = pos[0] - 0.5 * dist[0] * n
        sphere_pt = p - r * n
        np.testing.assert_allclose(pos[0], 0.5 * (surface_pt + sphere_pt), atol=1e-5)
        assert np.linalg.norm(sphere_pt - surface_pt) == pytest.approx(abs(dist[0]), abs=1e-5)
        checked += 1
    assert checked == 40


def test_second_contact_is_the_other_face_of_a_concave_corner():
    z = np.zeros((NX, NY), np.float32)
    z[4:, :] = 0.15  # a riser at x index 4 (a 5 cm ramp between grid points 3 and 4)
    size = np.array([0.5 * (NX - 1) * CELL, 0.5 * (NY - 1) * CELL, 1.0, 0.1])
    h = HFieldInfo(jnp.zeros(3), jnp.eye(3), size, NY, NX, jnp.asarray(z))
    r = 0.03
    x_ramp0 = 3 * CELL - size[0]
    # A sphere in the inner corner: resting on the lower tread, pushed into the ramp.
    p = jnp.array([x_ramp0 - 0.005, 0.0, r - 0.002])
    dist, pos, frame = contact.sphere_heightfield(
        h, GeomInfo(p, jnp.eye(3), jnp.array([r, r, r])), (3, 3))
    normals = np.asarray(frame[:, 0])
    assert np.all(np.asarray(dist) < 0)  # both faces penetrated
    up = np.argmax(normals[:, 2])
    np.testing.assert_allclose(normals[up], [0, 0, 1], atol=1e-5)  # the tread pushes up
    assert normals[1 - up, 0] < -0.9  # the ramp pushes back (-x)
    # On the open tread only one face is within reach: the second contact is inactive.
    p = jnp.array([0.0, 0.0, 0.15 + r - 0.001])
    dist, _, _ = contact.sphere_heightfield(
        h, GeomInfo(p, jnp.eye(3), jnp.array([r, r, r])), (3, 3))
    assert float(dist[0]) == pytest.approx(-0.001, abs=1e-5)
    assert float(dist[1]) > 0


def test_registered_beside_mjx_collider_and_model_is_the_same_robot():
    funcs = collision_driver._COLLISION_FUNC
    assert funcs[(GeomType.HFIELD, GeomType.ELLIPSOID)].ncon == contact.NCON == 2
    assert funcs[(GeomType.HFIELD, GeomType.SPHERE)].ncon == 4  # MJX's own, untouched
    contact.register()  # idempotent
    heights = np.zeros((41, 41), np.float32)
    ref = rb.build_mj_model(heights, RES)
    lean = rb.build_mj_model(heights, RES, rb.RobotConfig(terrain_contacts="nearest"))
    np.testing.assert_allclose(lean.body_mass, ref.body_mass)
    np.testing.assert_allclose(lean.body_inertia, ref.body_inertia)
    for group in rb.SPHERE_GROUPS.values():
        for name in group:
            g = lean.geom(name)
            assert g.type == mujoco.mjtGeom.mjGEOM_ELLIPSOID
            np.testing.assert_allclose(g.size, [ref.geom(name).size[0]] * 3)
    n_ref = mjx.make_data(mjx.put_model(ref))._impl.contact.dist.shape[0]
    n_lean = mjx.make_data(mjx.put_model(lean))._impl.contact.dist.shape[0]
    assert (n_ref, n_lean) == (16 * 4, 16 * 2)
    with pytest.raises(ValueError, match="terrain_contacts must be 'mjx', 'nearest' or 'columns'"):
        rb.build_mj_model(heights, RES, rb.RobotConfig(terrain_contacts="box"))


def test_standing_on_a_slope_agrees_with_mjx_collider():
    """The robot lands on a 10-degree slope (the surface crosses its grid's cell diagonals) and
    holds its pose while it slides ~18 cm downhill and stops: the two colliders give the same
    trajectory to a few millimetres over 2 s of physics."""
    x = np.arange(161) * RES
    heights = np.tile(np.tan(np.radians(10.0)) * x, (161, 1)).astype(np.float32)
    finals = {}
    for kind in ("mjx", "nearest"):
        model = rb.build_mj_model(heights, RES, rb.RobotConfig(terrain_contacts=kind))
        z0 = np.tan(np.radians(10.0)) * 4.0 + 0.34
        traj, d = _hold_pose(model, rb.standing_qpos((4.0, 4.0), z0), 400)
        finals[kind] = traj[[100, 200, 399]]
        assert np.all(np.isfinite(traj))
        assert np.any(np.asarray(d._impl.contact.dist) < 1e-3)
    a, b = finals["mjx"], finals["nearest"]
    ground = np.tan(np.radians(10.0)) * a[-1, 0]
    assert 0.22 < a[-1, 2] - ground < 0.36, a[-1, :3]  # standing
    assert 0.1 < 4.0 - a[-1, 0] < 0.3  # slid downhill
    np.testing.assert_allclose(a[:, :3], b[:, :3], atol=0.008)  # base position
    np.testing.assert_allclose(a[:, 3:7], b[:, 3:7], atol=0.01)  # orientation
    np.testing.assert_allclose(a[:, 7:], b[:, 7:], atol=0.03)  # joints


def test_env_with_nearest_contacts_reads_foot_contacts():
    import terrains
    from mjx_stairs.env.config import EnvConfig
    from mjx_stairs.env.stair_env import StairEnv

    atlas = terrains.build_atlas(["pyramid"], "train", levels=[0], variants_per_family=1,
                                 resolution=0.05, tile_size=6.0, border=1.0)
    cfg = EnvConfig(episode_length_s=2.0)
    cfg = dataclasses.replace(cfg, robot=dataclasses.replace(cfg.robot,
                                                             terrain_contacts="nearest"))
    env = StairEnv(atlas, cfg)
    rows = env.contact_rows["foot"]
    assert rows.shape == (4, 2)
    state = jax.jit(env.reset)(jax.random.PRNGKey(0))
    step = jax.jit(env.step)
    for _ in range(25):  # 0.5 s of standing still
        state = step(state, jnp.zeros(12))
    geom = np.asarray(state.pipeline_state._impl.contact.geom)
    for k, g in enumerate(env.robot.ids.foot_geoms):
        assert np.all(geom[rows[k]] == [env.robot.ids.hfield_geom, g])
    assert bool(state.info["last_foot_contact"].all())
    assert float(state.pipeline_state.qpos[2]) > 0.2


def test_spheres_off_the_grid_and_far_above_give_finite_inactive_contacts():
    z = np.zeros((NX, NY), np.float32)
    size = np.array([0.5 * (NX - 1) * CELL, 0.5 * (NY - 1) * CELL, 1.0, 0.1])
    h = HFieldInfo(jnp.zeros(3), jnp.eye(3), size, NY, NX, jnp.asarray(z))
    r = 0.02
    for p in ([5.0, -3.0, 0.01], [0.0, 0.0, 3.0], [-0.2, 0.15, 0.5]):
        dist, pos, frame = contact.sphere_heightfield(
            h, GeomInfo(jnp.array(p), jnp.eye(3), jnp.array([r, r, r])), (3, 3))
        assert all(np.all(np.isfinite(np.asarray(a))) for a in (dist, pos, frame))
        assert np.all(np.asarray(dist) > 0), (p, dist)


def test_mujoco_c_steps_the_nearest_model_like_the_sphere_model():
    """play and export step the model in MuJoCo C, which collides ellipsoids through its general
    convex path: on the slope the ellipsoid model follows the sphere model to a few millimetres."""
    x = np.arange(161) * RES
    heights = np.tile(np.tan(np.radians(10.0)) * x, (161, 1)).astype(np.float32)
    q0 = rb.standing_qpos((4.0, 4.0), np.tan(np.radians(10.0)) * 4.0 + 0.34)
    trajs = {}
    for kind in ("mjx", "nearest"):
        model = rb.build_mj_model(heights, RES, rb.RobotConfig(terrain_contacts=kind))
        ids = rb.robot_ids(model)
        data = mujoco.MjData(model)
        data.qpos[:] = q0
        traj = []
        for _ in range(400):
            data.ctrl[:] = rb.pd_torque(rb.NOMINAL_JOINT_POS, data.qpos[ids.qpos_joints],
                                        data.qvel[ids.qvel_joints], 35.0, 1.0, rb.TORQUE_LIMIT)
            mujoco.mj_step(model, data)
            traj.append(data.qpos.copy())
        trajs[kind] = np.array(traj)[[100, 200, 399]]
    a, b = trajs["mjx"], trajs["nearest"]
    assert 0.1 < 4.0 - a[-1, 0] < 0.3  # slid downhill, as in MJX
    np.testing.assert_allclose(a[:, :3], b[:, :3], atol=0.005)
    np.testing.assert_allclose(a[:, 3:7], b[:, 3:7], atol=0.01)


def test_columns_collider_is_the_distance_to_the_ground_truth_boxes():
    """`columns`: the nearest distance to the union of terrains.boxes' boxes (the CPU ground
    truth's geometry), checked against a numpy clamp over every box, and a second contact only
    at a concave corner (a tread and its riser)."""
    from terrains.boxes import grid_boxes

    res = 0.025
    x = np.arange(64) * res
    heights = np.tile(0.16 * (x >= 0.8) + 0.16 * (x >= 1.1), (24, 1)).astype(np.float32)
    m = rb.build_mj_model(heights, res, rb.RobotConfig(terrain_contacts="columns"))
    mx = mjx.put_model(m)
    hid = m.geom("terrain").id
    info = mesh.hfield(mx, int(m.geom_dataid[hid])).replace(
        pos=jnp.asarray(m.geom_pos[hid]), mat=jnp.eye(3))
    r = 0.03
    collide = jax.jit(jax.vmap(lambda p: contact.sphere_columns(
        info, GeomInfo(p, jnp.eye(3), jnp.full(3, r)), (4, 4))))
    boxes = grid_boxes(heights, res)
    rng = np.random.default_rng(0)
    p = np.stack([rng.uniform(0.6, 1.3, 4000), rng.uniform(0.2, 0.4, 4000),
                  rng.uniform(-0.02, 0.36, 4000)], -1)
    lo, hi = boxes[:, :3] - boxes[:, 3:], boxes[:, :3] + boxes[:, 3:]
    ref = np.linalg.norm(np.clip(p[:, None], lo, hi) - p[:, None], axis=-1).min(-1)
    dist, pos, frame = collide(jnp.asarray(p, jnp.float32))
    near = (ref > 0) & (ref < r)
    assert near.sum() > 200
    np.testing.assert_allclose(np.asarray(dist[near, 0]), ref[near] - r, atol=1e-5)
    # A sphere resting in the corner of the first tread and the second riser (at x = 1.0875):
    corner = jnp.array([[1.0875 - r + 1e-3, 0.3, 0.16 + r - 1e-3]])
    d2 = np.asarray(collide(corner)[0][0])
    np.testing.assert_allclose(d2, [-1e-3, -1e-3], atol=1e-5)
    # ... and on the middle of a tread, or over the convex edge: one contact only.
    for q in ([0.95, 0.3, 0.16 + r - 1e-3], [1.0875 + 0.01, 0.3, 0.32 + r - 1e-3]):
        d = np.asarray(collide(jnp.array([q]))[0][0])
        assert d[0] < 0 and d[1] > 0.5
    # MJX finds the columns collider through the heightfield's asset name.
    assert mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_HFIELD, 0) == contact.COLUMNS_HFIELD


def test_columns_sunk_centre_leaves_by_the_top_or_the_nearest_exposed_face():
    """A centre inside a column: "top" pushes it up through the column's top; "nearest" out
    through the nearest exposed face (issue 19: a foot driven into a riser goes back out of the
    riser, as MuJoCo's boxes push it). Sunk into a tread, both push it up; a side against a
    higher neighbour is never an exit."""
    res = 0.025
    x = np.arange(64) * res
    heights = np.tile(0.16 * (x >= 0.8) + 0.16 * (x >= 1.1), (24, 1)).astype(np.float32)
    m = rb.build_mj_model(heights, res, rb.RobotConfig(terrain_contacts="columns",
                                                       sunk_exit="nearest"))
    assert mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_HFIELD, 0) == contact.COLUMNS_EXIT_HFIELD
    mx = mjx.put_model(m)
    hid = m.geom("terrain").id
    info = mesh.hfield(mx, int(m.geom_dataid[hid])).replace(
        pos=jnp.asarray(m.geom_pos[hid]), mat=jnp.eye(3))
    r = 0.022

    def collide(p, exit_):
        d, _, frame = contact.sphere_columns(info, GeomInfo(jnp.asarray(p), jnp.eye(3),
                                                            jnp.full(3, r)), (4, 4), exit_)
        return float(d[0]), np.asarray(frame[0, 0]), float(d[1])

    riser = [1.0875 + 0.005, 0.3, 0.20]  # 5 mm into the second step's riser, 12 cm under its top
    d, n, d2 = collide(riser, "top")
    np.testing.assert_allclose([d, *n], [-(0.32 - 0.20) - r, 0, 0, 1], atol=1e-5)
    d, n, d2 = collide(riser, "nearest")
    np.testing.assert_allclose([d, *n], [-0.005 - r, -1, 0, 0], atol=1e-5)
    assert d2 > 0.5  # one contact for a sunk centre
    # 12 mm into the first step's riser and 1 cm under its top: the top is the nearer exit.
    d, n, _ = collide([0.7875 + 0.012, 0.3, 0.15], "nearest")
    np.testing.assert_allclose([d, *n], [-0.01 - r, 0, 0, 1], atol=1e-5)
    # Deep in the first step, 6 cm from its riser and 2 cm under its top: up in both.
    for exit_ in ("top", "nearest"):
        d, n, _ = collide([0.95, 0.3, 0.14], exit_)
        np.testing.assert_allclose([d, *n], [-0.02 - r, 0, 0, 1], atol=1e-5)
    # 5 mm into the second step's riser, 2 mm from its cell's y side: that side faces a column
    # as high (inside the solid), so the riser is the exit.
    d, n, _ = collide([1.0875 + 0.005, 0.2875 + 0.002, 0.30], "nearest")
    np.testing.assert_allclose([d, *n], [-0.005 - r, -1, 0, 0], atol=1e-5)
    # "face" (a study: set_exit_study) takes that side all the same, as a MuJoCo box would
    d, n, _ = collide([1.0875 + 0.005, 0.2875 + 0.002, 0.30], "face")
    np.testing.assert_allclose([d, *n], [-0.002 - r, 0, -1, 0], atol=1e-5)
    with pytest.raises(Exception, match="sunk_exit"):
        rb.RobotConfig(terrain_contacts="columns", sunk_exit="side")
    with pytest.raises(ValueError, match="rule must be"):  # before it changes anything
        contact.set_exit_study("top")


def test_columns_third_contact_is_the_other_riser_of_a_corner_across_the_grid():
    """Where a step edge runs across the grid (a spiral's radial edges), a sphere in a concave
    corner touches a tread and two risers at right angles; the ground truth's boxes give all
    three. With 3 contacts a sphere (`set_columns_ncon`, issue 19's study) the columns collider
    gives the third; its first two are the 2-contact collider's, bit for bit."""
    res, r = 0.025, 0.03
    heights = np.zeros((24, 64), np.float32)  # rows along y, columns along x
    heights[:, 44:] = 0.16  # a riser facing -x at x = 1.0875
    heights[12:, :] = 0.16  # and one facing -y at y = 0.2875
    m = rb.build_mj_model(heights, res, rb.RobotConfig(terrain_contacts="columns",
                                                       sunk_exit="nearest"))
    mx = mjx.put_model(m)
    hid = m.geom("terrain").id
    info = mesh.hfield(mx, int(m.geom_dataid[hid])).replace(
        pos=jnp.asarray(m.geom_pos[hid]), mat=jnp.eye(3))
    sphere = GeomInfo(jnp.array([1.0875 - r + 1e-3, 0.2875 - r + 1e-3, r - 1e-3]), jnp.eye(3),
                      jnp.full(3, r))
    d2, p2, f2 = contact.sphere_columns(info, sphere, (4, 4), "nearest")
    d3, p3, f3 = contact.sphere_columns(info, sphere, (4, 4), "nearest", ncon=3)
    assert d2.shape == (2,) and d3.shape == (3,)
    np.testing.assert_allclose(np.asarray(d3), [-1e-3] * 3, atol=1e-5)
    normals = sorted(map(tuple, np.round(np.asarray(f3[:, 0]), 5)))
    assert normals == [(-1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, 1.0)]
    for a, b in ((d2, d3[:2]), (p2, p3[:2]), (f2, f3[:2])):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    # On a flat tread the extra contacts stay inactive.
    flat = GeomInfo(jnp.array([0.5, 0.1, r - 1e-3]), jnp.eye(3), jnp.full(3, r))
    d = np.asarray(contact.sphere_columns(info, flat, (4, 4), "nearest", ncon=3)[0])
    assert d[0] < 0 and (d[1:] > 0.5).all()
    # The process-wide switch sizes every (heightfield, ellipsoid) pair's contacts; back to 2.
    try:
        contact.set_columns_ncon(3)
        assert collision_driver._COLLISION_FUNC[contact.KEY].ncon == 3
    finally:
        contact.set_columns_ncon(contact.NCON)
    assert collision_driver._COLLISION_FUNC[contact.KEY].ncon == contact.NCON
    with pytest.raises(ValueError, match="at least 2"):
        contact.set_columns_ncon(1)
