"""sim.capsule: the limbs as capsules against the terrain, two contacts each."""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from mujoco import mjx

from mjx_stairs.sim import capsule, contact, geoms
from mjx_stairs.sim import robot as rb
from terrains.boxes import grid_boxes

RES = 0.025


def test_points_are_close_enough_on_every_limb_capsule():
    """POINTS spheres along each capsule of the calves and thighs lie close enough that a sharp
    edge reaches at most CALF_EDGE_GAP into the capsule between two of them (the chains' rule)."""
    for a, b, r in geoms.CALF_SHAPE + geoms.THIGH_SHAPE:
        spacing = np.linalg.norm(np.subtract(b, a)) / (capsule.POINTS - 1)
        assert spacing <= 2.0 * np.sqrt(r**2 - (r - geoms.CALF_EDGE_GAP) ** 2), (a, b, r)
        assert r <= capsule.MAX_RADIUS


def _world(heights, spec_geom):
    """A free capsule over `heights` read as columns: (MJX model, MuJoCo model with the same
    columns as boxes)."""
    spec = mujoco.MjSpec()
    spec.add_material(name="terrain")
    rb.add_heightfield(spec, heights, RES, 0.8, hfield_name=contact.COLUMNS_EXIT_HFIELD)
    body = spec.worldbody.add_body(name="limb")
    body.add_freejoint()
    spec_geom(body)
    boxes = mujoco.MjSpec()
    for i, (cx, cy, cz, hx, hy, hz) in enumerate(grid_boxes(heights, RES)):
        boxes.worldbody.add_geom(name=f"box{i}", type=mujoco.mjtGeom.mjGEOM_BOX,
                                 pos=[cx, cy, cz], size=[hx, hy, hz])
    body = boxes.worldbody.add_body(name="limb")
    body.add_freejoint()
    spec_geom(body)
    return spec.compile(), boxes.compile()


def test_a_capsule_across_a_step_edge_is_as_deep_as_mujoco_finds_it():
    """Thigh capsules (r 0.02, 0.175 m) laid at random over a 17 cm step's edge: the collider's
    deepest contact is as deep as MuJoCo's exact capsule-box distance within the chains' gap
    (never deeper), its normals unit, one contact in each half of the capsule."""
    heights = np.zeros((41, 41), np.float32)
    heights[:, 20:] = 0.17
    (a, b, r), = geoms.THIGH_SHAPE
    half = np.linalg.norm(np.subtract(b, a)) / 2

    def limb(body):
        body.add_geom(name="cap", type=mujoco.mjtGeom.mjGEOM_CAPSULE, size=[r, half, 0.0],
                      contype=1, conaffinity=1)

    model, boxes = _world(heights, limb)
    mx = mjx.put_model(model)
    rng = np.random.default_rng(0)
    n = 24
    qpos = np.zeros((n, 7))
    qpos[:, 0] = 0.5 + rng.uniform(-0.06, 0.06, n)  # the edge at x = 0.4875
    qpos[:, 1] = 0.5 + rng.uniform(-0.1, 0.1, n)
    qpos[:, 2] = 0.17 + r + rng.uniform(-0.006, 0.006, n)  # over the upper tread, or its edge
    yaw, tilt = rng.uniform(0.0, 2.0 * np.pi, n), rng.uniform(-0.08, 0.08, n)
    axis = np.stack([np.cos(yaw) * np.cos(tilt), np.sin(yaw) * np.cos(tilt), np.sin(tilt)], -1)
    for i in range(n):  # the capsule's z axis along `axis`
        mujoco.mju_quatZ2Vec(qpos[i, 3:], axis[i])

    @jax.jit
    def contacts(q):
        d = jax.vmap(lambda q: mjx.forward(mx, mjx.make_data(mx).replace(qpos=q)))(q)
        return d._impl.contact.dist, d._impl.contact.frame

    dist, frame = (np.asarray(x) for x in contacts(jnp.asarray(qpos, jnp.float32)))
    assert dist.shape == (n, capsule.NCON)
    assert np.allclose(np.linalg.norm(frame[:, :, 0], axis=-1), 1.0, atol=1e-5)
    data = mujoco.MjData(boxes)
    cap = boxes.geom("cap").id
    exact = np.zeros(n)
    for i in range(n):
        data.qpos[:] = qpos[i]
        mujoco.mj_kinematics(boxes, data)
        exact[i] = min(mujoco.mj_geomDistance(boxes, data, cap, g, 1.0, None)
                       for g in range(boxes.ngeom) if g != cap)
    deepest = dist.min(-1)
    near = exact < 0.005  # beyond a radius from every sphere the collider reads no distance
    assert np.all(deepest[near] >= exact[near] - 1e-4), np.c_[deepest, exact]
    assert np.all(deepest[near] <= exact[near] + geoms.CALF_EDGE_GAP + 1e-4), np.c_[deepest, exact]
    assert np.all(deepest[~near] > 0.0), np.c_[deepest, exact]
    assert np.sum(exact < 0) >= 6 and np.sum(~near) >= 2  # some touch, some do not


def test_a_robot_with_limb_capsules_has_two_contacts_a_capsule_and_stands():
    """robot.limb_capsules: calves and thighs as go2_full.xml's capsules, 2 contacts each (24
    more a robot, the chains 160); the robot held in its pose on a flat floor neither sinks nor
    blows up, and no limb touches the floor."""
    cfg = rb.RobotConfig(**{**rb.PHYSICS["evaluation"], "calf_collision": True,
                            "thigh_collision": True, "limb_capsules": True})
    heights = np.zeros((41, 41), np.float32)
    model = rb.build_mj_model(heights, RES, cfg)
    ids = rb.robot_ids(model)
    assert ids.calf_geoms.shape == (4, 2) and ids.thigh_geoms.shape == (4, 1)
    full = mujoco.MjModel.from_xml_path(str(rb.ASSET.parent / "go2_full.xml"))
    for name in ("FL_thigh", "FL_calf"):  # the same capsules as the full robot's
        mine = [g for g in range(model.ngeom) if model.geom(g).name.startswith(name + "_cap")]
        theirs = [g for g in range(full.ngeom) if full.geom(g).name.startswith(name + "_col")]
        assert len(mine) == len(theirs)
        for g, h in zip(mine, theirs, strict=True):
            assert np.allclose(model.geom_size[g], full.geom_size[h], atol=1e-6)
            assert np.allclose(model.geom_pos[g], full.geom_pos[h], atol=1e-6)
    plain = rb.build_mj_model(heights, RES, rb.RobotConfig(**rb.PHYSICS["evaluation"]))
    mx = mjx.put_model(model)
    d = mjx.make_data(mx).replace(qpos=jnp.asarray(rb.standing_qpos((0.5, 0.5), 0.40)))
    assert d._impl.contact.dist.shape[0] == mjx.make_data(plain)._impl.contact.dist.shape[0] + 24
    limit, target = jnp.asarray(rb.TORQUE_LIMIT), jnp.asarray(rb.NOMINAL_JOINT_POS)

    def step(d, _):
        tau = rb.pd_torque(target, d.qpos[ids.qpos_joints], d.qvel[ids.qvel_joints], 35.0, 1.0,
                           limit)
        d = mjx.step(mx, d.replace(ctrl=tau))
        return d, d.qpos[2]

    d, z = jax.jit(lambda d: jax.lax.scan(step, d, None, length=200))(d)
    assert np.all(np.isfinite(np.asarray(z))) and 0.25 < float(z[-1]) < 0.40
    limbs = np.concatenate([ids.calf_geoms.ravel(), ids.thigh_geoms.ravel()])
    geom = np.asarray(d._impl.contact.geom)
    on_limb = np.isin(geom, limbs).any(-1)
    assert np.all(np.asarray(d._impl.contact.dist)[on_limb] > 0.01)


def test_a_capsule_wider_than_the_window_is_refused():
    spec = mujoco.MjSpec()
    spec.add_material(name="terrain")
    rb.add_heightfield(spec, np.zeros((5, 5), np.float32), RES, 0.8)
    spec.worldbody.add_body().add_geom(type=mujoco.mjtGeom.mjGEOM_CAPSULE, name="wide",
                                       size=[0.05, 0.1, 0.0])
    with pytest.raises(ValueError, match="'wide'"):
        capsule.check(spec.compile())
