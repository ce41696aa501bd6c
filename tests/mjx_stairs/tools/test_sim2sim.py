"""sim2sim: the observation built from the sidecar alone equals the training env's, the ONNX action
equals the JAX policy's, motors are matched by name, the full-geometry Go2 is the training Go2's
body, episodes run through the CLI, and bad inputs give one-line errors."""

from __future__ import annotations

import copy
import dataclasses
import hashlib
import json
import re
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

pytest.importorskip("onnxruntime")

import terrains  # noqa: E402
from mjx_stairs import cli  # noqa: E402
from mjx_stairs.env import observation  # noqa: E402
from mjx_stairs.env.config import env_config_from, evaluation_config  # noqa: E402
from mjx_stairs.env.stair_env import StairEnv  # noqa: E402
from mjx_stairs.rl import networks  # noqa: E402
from mjx_stairs.rl import policy as policy_lib  # noqa: E402
from mjx_stairs.sim import robot as rb  # noqa: E402
from mjx_stairs.tools import contract as ct  # noqa: E402
from mjx_stairs.tools import export  # noqa: E402
from mjx_stairs.tools import sim2sim as s2s  # noqa: E402
from mjx_stairs.tools import sim2sim_world as sw  # noqa: E402
from tests.mjx_stairs.tools.test_export import MAP, N_VEC, _policy_state  # noqa: E402

ROOT = Path(__file__).resolve().parents[3]
STAGE2 = ROOT / "experiments" / "results" / "stage2_u" / "policy.npz"


def _export(tmp, mode: str, history: int = 0, occlusion: int = 0,
            delay: bool = False) -> tuple[Path, policy_lib.Policy]:
    """A policy of the real architecture (goal `mode`, `history` steps of observation history,
    `occlusion` samples of the height map's wall rule, `delay`: the action delay observed)
    exported to ONNX + sidecar."""
    state, cfg = _policy_state(history=history, delay=delay)
    path = tmp / "policy.npz"
    policy_lib.save_policy(path, state.params, state.normalizer, 7, cfg,
                           networks.ObsLayout(observation.n_vec(history, delay), MAP))
    policy = policy_lib.load_policy(path)
    meta = copy.deepcopy(policy.metadata)
    meta["config"]["env"].update(goal_mode=mode, waypoint_lookahead_m=1.0, obs_history=history,
                                 obs_action_delay=delay)
    meta["config"]["env"]["height_map"]["occlusion_samples"] = occlusion
    policy = policy._replace(metadata=meta)
    export.export_policy(policy, tmp / "policy.onnx")
    return tmp / "policy.onnx", policy


@pytest.fixture(scope="module")
def onnx_file(tmp_path_factory):
    return _export(tmp_path_factory.mktemp("onnx"), "waypoint")[0]


@pytest.fixture(scope="module", params=["final", "waypoint", "occluded"])
def contract_case(request, tmp_path_factory):
    """Random robot states on a U-shaped staircase (a heightfield): the observation of the
    training env and of sim2sim for each, and the policy ("occluded": the waypoint goal with
    the height map's wall rule, height_map.occlusion_samples 32)."""
    mode = "final" if request.param == "final" else "waypoint"
    onnx_path, policy = _export(tmp_path_factory.mktemp(request.param), mode,
                                occlusion=32 if request.param == "occluded" else 0)
    cfg = evaluation_config(env_config_from(policy.metadata["config"]["env"]))
    atlas = terrains.build_cell_atlas([("u_shaped", "test", 3)], 1, resolution=0.05,
                                      tile_size=10.0, border=1.0)
    env = StairEnv(atlas, cfg)
    c = ct.load_contract(onnx_path)
    world = sw.build_world(c, atlas.heights, atlas.resolution, terrain="heightfield")
    course = s2s.Course("u3", atlas.heights, atlas.resolution, atlas.spawn[0], atlas.goal[0],
                        atlas.centreline[0])
    sim = s2s.Sim(c, None, world, course)
    sim.reset(*atlas.spawn[0][[0, 1, 5]])
    observe = jax.jit(lambda q, v, i: env.observe(q, v, i)["state"])
    rng = np.random.default_rng(1)
    ours, theirs, points, rays, seen = [], [], [], [], []
    for _ in range(16):  # inside the tile, 3 m from its edges: the map never leaves it
        xy = atlas.origin[0] + rng.uniform(3.0, 7.0, 2)
        floor = float(env.terrain_height(jnp.float32(xy[0]), jnp.float32(xy[1])))
        q = rng.normal(size=4)
        q[1:3] *= 0.3  # tilted by up to ~35 deg, any heading
        qpos = np.concatenate([xy, [floor + rng.uniform(0.2, 0.45)], q / np.linalg.norm(q),
                               rb.NOMINAL_JOINT_POS + rng.uniform(-0.4, 0.4, 12)])
        qvel = rng.normal(size=18) * np.r_[[0.8] * 6, [4.0] * 12]
        last = rng.uniform(-4.0, 4.0, 12)
        world.data.qpos[:], world.data.qvel[:] = qpos, qvel
        sim.last_action = last
        m = sim.measure()
        ours.append(ct.observation(c, m))
        points.append(ct.map_points(c, m.base_pos, ct.base_yaw(m.base_rot)))
        rays.append(sw.terrain_z(world, points[-1]))  # the plain ray casts
        seen.append(m.terrain_z)  # what the observation used (the wall rule, where on)
        info = {"tile": jnp.int32(0), "last_action": jnp.asarray(last, jnp.float32)}
        theirs.append(np.asarray(observe(jnp.asarray(qpos, jnp.float32),
                                         jnp.asarray(qvel, jnp.float32), info)))
    return dict(mode=mode, onnx=onnx_path, policy=policy, contract=c, atlas=atlas,
                ours=np.array(ours), theirs=np.array(theirs), points=np.array(points),
                rays=np.array(rays), seen=np.array(seen))


def test_vector_observation_equals_the_training_env(contract_case):
    ours, theirs = contract_case["ours"], contract_case["theirs"]
    np.testing.assert_allclose(ours[:, :N_VEC], theirs[:, :N_VEC], rtol=0, atol=1e-4)
    c = contract_case["contract"]
    goal = ours[:, c.slices["goal"]]
    assert np.ptp(goal[:, 0]) > 0.5  # the goal term varies: a real comparison
    if contract_case["mode"] == "waypoint":  # waypoints 1 m ahead, not the far final goal
        assert np.median(np.linalg.norm(goal[:, :2], axis=1)) < 2.5


def test_height_map_equals_the_training_env_where_both_are_exact(contract_case):
    """MuJoCo triangulates a heightfield cell, the env interpolates it bilinearly: the two are
    the same plane wherever the cell's bilinear twist h00 - h01 - h10 + h11 is zero (treads, and
    risers that cross the cell straight); there the ray cast must equal the env to 1e-4.
    Elsewhere (where a riser meets a wall) the ray's height lies within the cell's corners."""
    atlas, c = contract_case["atlas"], contract_case["contract"]
    h, res = atlas.heights.astype(np.float64), atlas.resolution
    sl = c.slices["height_map"]
    ours, theirs = contract_case["ours"][:, sl], contract_case["theirs"][:, sl]
    pts = contract_case["points"].reshape(-1, 2)
    ix, iy = np.floor(pts[:, 0] / res).astype(int), np.floor(pts[:, 1] / res).astype(int)
    h00, h01, h10, h11 = h[iy, ix], h[iy, ix + 1], h[iy + 1, ix], h[iy + 1, ix + 1]
    planar = np.abs(h00 - h01 - h10 + h11) < 1e-6
    ours, theirs = ours.ravel(), theirs.ravel()
    assert planar.mean() > 0.97
    np.testing.assert_allclose(ours[planar], theirs[planar], rtol=0, atol=1e-4)
    ray = contract_case["rays"].ravel()
    lo = np.minimum(np.minimum(h00, h01), np.minimum(h10, h11))
    hi = np.maximum(np.maximum(h00, h01), np.maximum(h10, h11))
    assert np.all((ray >= lo - 1e-4) & (ray <= hi + 1e-4))
    assert np.ptp(theirs) > 0.5  # the map sees the stairs


def test_the_wall_rule_raises_what_lies_behind_a_wall_alone(contract_case):
    """With the sidecar's occlusion rule a map point reads the highest terrain above the sensor
    between the base and it: behind the U tile's divider and outer walls (1.6 m) the map reads
    the wall, elsewhere the plain ray cast; without the rule, the ray cast everywhere."""
    rays, seen = contract_case["rays"].ravel(), contract_case["seen"].ravel()
    rule = contract_case["contract"].raw["height_map"]["occlusion"]
    assert (rule or {}).get("samples", 0) == contract_case["contract"].hm_occlusion
    if not contract_case["contract"].hm_occlusion:
        np.testing.assert_array_equal(seen, rays)
        return
    raised = seen > rays + 1e-6
    assert 0.02 < raised.mean() < 0.6
    assert np.all(seen[raised] > 1.0)  # a wall's height, not a step's
    np.testing.assert_allclose(seen[~raised], rays[~raised], rtol=0, atol=1e-9)


def test_onnx_action_equals_the_jax_policy(contract_case):
    c, policy = contract_case["contract"], contract_case["policy"]
    run = ct.OnnxPolicy(contract_case["onnx"], c)
    got = np.stack([run(o) for o in contract_case["ours"]])
    want = np.asarray(jax.jit(lambda o: policy_lib.policy_action(policy, o))(
        jnp.asarray(contract_case["ours"])))
    assert np.std(want) > 0.1
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-5)


# ----------------------------------------------------------------------------- the robot models


def _sdk_ordered_copy(tmp: Path) -> Path:
    """go2_full.xml with its motors listed in the Go2 SDK's order (FR, FL, RR, RL)."""
    text = sw.OUR_ROBOT.read_text()
    motors = re.findall(r"    <motor name=.*/>\n", text)
    assert len(motors) == 12 and 'name="FL_hip"' in motors[0]
    by_leg = {leg: [m for m in motors if f'name="{leg}_' in m] for leg in ("FL", "FR", "RL", "RR")}
    sdk = "".join(m for leg in ("FR", "FL", "RR", "RL") for m in by_leg[leg])
    path = tmp / "go2_sdk_order.xml"
    path.write_text(text.replace("".join(motors), sdk))
    return path


@pytest.fixture(scope="module")
def history_onnx(tmp_path_factory):
    """A policy that observes 2 steps of history (env.obs_history), exported."""
    return _export(tmp_path_factory.mktemp("history"), "final", history=2)


def test_history_terms_are_placed_as_the_training_env_places_them(history_onnx):
    """The robot side's history terms (encoder readings and actions kept by ct.History) land
    where the env's observation has them, with the same values."""
    onnx_path, policy = history_onnx
    c = ct.load_contract(onnx_path)
    cfg = evaluation_config(env_config_from(policy.metadata["config"]["env"]))
    assert c.history == 2 and cfg.obs_history == 2
    assert c.obs_size == observation.size(cfg.height_map, 2) == policy.layout.obs_size
    atlas = terrains.build_cell_atlas([("straight", "test", 0)], 1, resolution=0.1,
                                      tile_size=10.0, border=1.0)
    env = StairEnv(atlas, cfg)
    rng = np.random.default_rng(2)
    encoders = rb.NOMINAL_JOINT_POS + rng.uniform(-0.4, 0.4, (2, 12))
    actions = rng.uniform(-7.0, 7.0, (2, 12))  # beyond the clip of 5: both sides clip
    n = c.hm_size * c.hm_size
    m = ct.Measurement(rb.NOMINAL_JOINT_POS, np.zeros(12), np.zeros(3), np.eye(3),
                       np.zeros(3), np.zeros(3), np.zeros(12), np.zeros(4), np.zeros(n),
                       joint_pos_history=encoders, action_history=actions)
    ours = ct.observation(c, m)
    qpos = np.concatenate([atlas.spawn[0][:2], [0.4, 1.0, 0, 0, 0], rb.NOMINAL_JOINT_POS])
    info = {"tile": jnp.int32(0), "last_action": jnp.zeros(12),
            "joint_pos_history": jnp.asarray(encoders - rb.NOMINAL_JOINT_POS, jnp.float32),
            "action_history": jnp.asarray(np.clip(actions, -5, 5), jnp.float32)}
    theirs = np.asarray(env.observe(jnp.asarray(qpos, jnp.float32), jnp.zeros(18), info)["state"])
    for name in ct.HISTORY_TERMS:
        np.testing.assert_allclose(ours[c.slices[name]], theirs[c.slices[name]], atol=1e-6)
        assert np.ptp(ours[c.slices[name]]) > 0.5
    with pytest.raises(ct.ContractError, match="needs joint_pos_history"):
        ct.observation(c, m._replace(joint_pos_history=None))


def test_sim2sim_keeps_the_history_the_policy_acted_on(history_onnx, tmp_path):
    """Newest first: after each action, the observation it acted on (its joint positions and
    its last action) joins the history; at the start both hold the reset pose and zeros."""
    sim = _sim(history_onnx[0], policy=lambda obs: np.full(12, 0.4))
    sl = sim.c.slices
    o1 = sim.observe()
    np.testing.assert_allclose(o1[sl["joint_pos_history"]], np.tile(o1[sl["joint_pos"]], 2),
                               atol=1e-6)
    assert np.all(o1[sl["action_history"]] == 0.0)
    sim.act(o1)
    o2 = sim.observe()
    sim.act(o2)
    o3 = sim.observe()
    assert np.abs(o3[sl["joint_pos"]] - o2[sl["joint_pos"]]).max() > 1e-3  # the joints moved
    np.testing.assert_allclose(o3[sl["joint_pos_history"]],
                               np.concatenate([o2[sl["joint_pos"]], o1[sl["joint_pos"]]]),
                               atol=1e-6)
    np.testing.assert_allclose(o3[sl["action_history"]],
                               np.concatenate([o2[sl["last_action"]], o1[sl["last_action"]]]))
    assert np.all(o3[sl["action_history"]][:12] == 0.4)
    side = json.loads(ct.sidecar_path(history_onnx[0]).read_text())  # a history that does not
    side["observation"]["history_steps"] = 3  # fit its terms: a one-line error
    bad = tmp_path / "policy.onnx"
    bad.write_bytes(history_onnx[0].read_bytes())
    ct.sidecar_path(bad).write_text(json.dumps(side))
    with pytest.raises(ct.ContractError, match="history_steps 3"):
        ct.load_contract(bad)


@pytest.fixture(scope="module")
def delay_onnx(tmp_path_factory):
    """A policy that observes 1 step of history and its action delay (env.obs_action_delay)."""
    return _export(tmp_path_factory.mktemp("delay"), "final", history=1, delay=True)


@pytest.mark.parametrize("latency_ms", [0.0, 10.0, 20.0])
def test_the_delay_term_is_the_latency_the_runner_applies(delay_onnx, latency_ms):
    """sim2sim measures the latency it applies (whole physics steps) and the sidecar's term reads
    it as the training env reads its robot's drawn delay: 50 / s, after the history; the ONNX
    action sees it."""
    onnx_path, policy = delay_onnx
    c = ct.load_contract(onnx_path)
    cfg = evaluation_config(env_config_from(policy.metadata["config"]["env"]))
    assert c.delay_scale == observation.DELAY_SCALE and cfg.obs_action_delay
    assert c.slices["action_delay"] == slice(observation.n_vec(1, True) - 1,
                                             observation.n_vec(1, True))
    assert json.loads(ct.sidecar_path(onnx_path).read_text())["observation"]["action_delay"]
    sim = _sim(onnx_path, latency_ms=latency_ms)
    ours = sim.observe()
    atlas = terrains.build_cell_atlas([("straight", "test", 0)], 1, resolution=0.1,
                                      tile_size=10.0, border=1.0)
    env = StairEnv(atlas, cfg)
    qpos = np.concatenate([atlas.spawn[0][:2], [0.4, 1.0, 0, 0, 0], rb.NOMINAL_JOINT_POS])
    info = {"tile": jnp.int32(0), "last_action": jnp.zeros(12),
            **observation.history_start(1, jnp.zeros(12)),
            "delay_steps": jnp.int32(round(latency_ms / 5.0))}
    theirs = np.asarray(env.observe(jnp.asarray(qpos, jnp.float32), jnp.zeros(18), info)["state"])
    sl = c.slices["action_delay"]
    np.testing.assert_allclose(ours[sl], theirs[sl], atol=1e-6)
    np.testing.assert_allclose(ours[sl], [latency_ms / 20.0], atol=1e-6)
    onnx = ct.OnnxPolicy(onnx_path, c)
    other = ours.copy()
    other[sl] += 1.0
    assert np.abs(onnx(other) - onnx(ours)).max() > 1e-4  # the network reads it


@pytest.mark.parametrize("term", ["action_delay", "joint_damping"])
def test_a_term_the_critic_alone_read_is_written_as_zero(delay_onnx, tmp_path, term):
    """env.obs_action_delay_actor false, or env.obs_joint_damping (the same one float at the
    vector part's end): the sidecar gives the term scale 0, so sim2sim writes 0 there at any
    latency, as the training env's actor observation holds; a sidecar that gives the damping a
    scale is refused."""
    _, policy = delay_onnx
    meta = copy.deepcopy(policy.metadata)
    meta["config"]["env"].update({"obs_action_delay_actor": False} if term == "action_delay"
                                 else {"obs_action_delay": False, "obs_joint_damping": True})
    onnx_path = tmp_path / "policy.onnx"
    export.export_policy(policy._replace(metadata=meta), onnx_path)
    c = ct.load_contract(onnx_path)
    side = json.loads(ct.sidecar_path(onnx_path).read_text())
    entry = next(e for e in side["observation"]["layout"] if e["name"] == term)
    assert entry["scale"] == 0.0 and "actor read" in entry["description"]
    assert c.delay_scale == (0.0 if term == "action_delay" else None)
    cfg = evaluation_config(env_config_from(meta["config"]["env"]))
    ours = _sim(onnx_path, latency_ms=20.0).observe()
    atlas = terrains.build_cell_atlas([("straight", "test", 0)], 1, resolution=0.1,
                                      tile_size=10.0, border=1.0)
    qpos = np.concatenate([atlas.spawn[0][:2], [0.4, 1.0, 0, 0, 0], rb.NOMINAL_JOINT_POS])
    info = {"tile": jnp.int32(0), "last_action": jnp.zeros(12),
            **observation.history_start(1, jnp.zeros(12)), "delay_steps": jnp.int32(4),
            "joint_damping": jnp.float32(1.5)}
    obs = StairEnv(atlas, cfg).observe(jnp.asarray(qpos, jnp.float32), jnp.zeros(18), info)
    sl = c.slices[term]
    assert ours[sl] == [0.0] and float(np.asarray(obs["state"])[sl][0]) == 0.0
    assert float(np.asarray(obs["privileged_state"])[sl][0]) == pytest.approx(
        1.0 if term == "action_delay" else 1.5)
    if term == "joint_damping":
        entry["scale"] = 1.0
        ct.sidecar_path(onnx_path).write_text(json.dumps(side))
        with pytest.raises(ct.ContractError, match="critic's alone"):
            ct.load_contract(onnx_path)


def test_motors_in_sdk_order_give_the_same_torque_on_every_named_joint(onnx_file, tmp_path):
    c = ct.load_contract(onnx_file)
    tile = terrains.make_tile("straight", 2, schedule="test", resolution=0.05)
    course = s2s.tile_course(tile, "straight")
    sims = []
    for robot in (None, _sdk_ordered_copy(tmp_path)):
        world = sw.build_world(c, course.heights, course.resolution, robot)
        sims.append(s2s.Sim(c, lambda obs: np.full(12, 0.7), world, course))
    ours, sdk = sims
    assert ours.w.model.actuator(0).name == "FL_hip"
    assert sdk.w.model.actuator(0).name == "FR_hip"
    assert sorted(ours.w.actuator) == list(range(12)) and list(sdk.w.actuator) != list(range(12))
    rng = np.random.default_rng(0)
    target = rb.NOMINAL_JOINT_POS + rng.uniform(-1.2, 1.2, 12)
    q, v = rng.uniform(-0.3, 0.3, 12), rng.uniform(-3.0, 3.0, 12)
    for sim in sims:
        sim.reset(*course.spawn[[0, 1, 5]])
        sim.w.data.qpos[sim.w.qpos_adr] += q
        sim.w.data.qvel[sim.w.dof_adr] = v
        sim.active = target
        sim.apply_pd()
        mujoco.mj_forward(sim.w.model, sim.w.data)
    want = ct.pd_torque(c, target, ours.w.data.qpos[ours.w.qpos_adr], v)
    assert np.abs(want).max() > 5.0 and np.any(np.abs(want) >= c.torque_limit - 1e-9)
    for sim in sims:  # the torque on each joint, found by its name
        for i, name in enumerate(c.joint_names):
            dof = sim.w.model.jnt_dofadr[sim.w.model.joint(name).id]
            assert sim.w.data.qfrc_actuator[dof] == pytest.approx(want[i], abs=1e-9)
    for sim in sims:  # and a control step of each moves the robot the same way
        sim.act(np.zeros(c.obs_size))
    np.testing.assert_array_equal(ours.w.data.qpos, sdk.w.data.qpos)


def test_the_full_model_is_the_training_robot_with_full_collision_geometry():
    full = mujoco.MjModel.from_xml_path(str(sw.OUR_ROBOT))
    train = mujoco.MjModel.from_xml_path(str(rb.ASSET))
    assert full.nbody == train.nbody and full.njnt == train.njnt
    for b in range(train.nbody):
        assert full.body(b).name == train.body(b).name
    for field in ("body_pos", "body_quat", "body_mass", "body_inertia", "body_ipos",
                  "body_iquat", "jnt_axis", "jnt_range", "jnt_qposadr", "actuator_ctrlrange"):
        np.testing.assert_array_equal(getattr(full, field), getattr(train, field), field)
    np.testing.assert_allclose(full.dof_damping[6:], 2.0)  # go2.md
    np.testing.assert_allclose(full.dof_armature[6:], 0.01)
    np.testing.assert_allclose(full.dof_frictionloss[6:], 0.2)
    assert full.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    default = mujoco.MjModel.from_xml_string("<mujoco/>").opt
    assert (full.opt.iterations, full.opt.ls_iterations) == (default.iterations,
                                                             default.ls_iterations)
    assert full.opt.tolerance == default.tolerance
    kinds = {}
    for g in range(full.ngeom):
        if full.geom_contype[g] and full.geom_group[g] == 0:
            part = sw.PARTS[sw._parts(full, np.zeros(full.ngeom, bool))[g]]
            kinds.setdefault(part, set()).add(mujoco.mjtGeom(full.geom_type[g]).name)
    assert kinds == {"trunk": {"mjGEOM_BOX", "mjGEOM_CYLINDER", "mjGEOM_SPHERE"},
                     "hip": {"mjGEOM_CYLINDER"}, "thigh": {"mjGEOM_CAPSULE"},
                     "calf": {"mjGEOM_CAPSULE"}, "foot": {"mjGEOM_SPHERE"}}


def test_the_full_robot_stands_on_box_stairs(onnx_file):
    """Holding the nominal pose through the sidecar's PD for 2 s: upright at standing height,
    feet alone on the floor."""
    c = ct.load_contract(onnx_file)
    course = s2s.family_course("u_shaped", 3, resolution=0.05)
    sim = s2s.Sim(c, lambda obs: np.zeros(12), sw.build_world(c, course.heights, 0.05), course)
    sim.reset(*course.spawn[[0, 1, 5]])
    for _ in range(100):
        sim.act(np.zeros(c.obs_size))
    pos, rot = sim.base()
    assert pos[2] - course.spawn[2] == pytest.approx(0.29, abs=0.04)
    assert rot[2, 2] > 0.99 and np.abs(sim.w.data.qvel).max() < 0.05
    d = sim.w.data
    touching = {sw.PARTS[sim.w.part[g]] for g in np.r_[d.contact.geom1[:d.ncon],
                                                       d.contact.geom2[:d.ncon]]
                if sim.w.part[g] >= 0}
    assert touching == {"foot"} and not sim.fallen()


def test_a_stiffer_contact_sinks_the_feet_less(onnx_file):
    """contact_timeconst sets every geom's solref, robot and stairs; standing in the nominal
    pose, the feet's penetration into the boxes falls with the time constant (about as its
    square: MuJoCo's contact spring is ~1/timeconst^2)."""
    c = ct.load_contract(onnx_file)
    course = s2s.family_course("u_shaped", 3, resolution=0.05)
    depth = {}
    for tc in (0.0, 0.01):
        w = sw.build_world(c, course.heights, 0.05, contact_timeconst=tc)
        assert np.allclose(w.model.geom_solref, [tc or 0.02, 1.0])
        sim = s2s.Sim(c, lambda obs: np.zeros(12), w, course)
        sim.reset(*course.spawn[[0, 1, 5]])
        for _ in range(100):
            sim.act(np.zeros(c.obs_size))
        assert not sim.fallen()
        depth[tc] = -np.mean(w.data.contact.dist[:w.data.ncon])
    assert depth[0.0] > 0 and depth[0.01] < 0.5 * depth[0.0], depth


# ----------------------------------------------------------------------------- runner options


def _sim(onnx_file, policy=None, **options) -> s2s.Sim:
    c = ct.load_contract(onnx_file)
    course = s2s.family_course("straight", 2, resolution=0.05)
    world = sw.build_world(c, course.heights, course.resolution)
    sim = s2s.Sim(c, policy or (lambda obs: np.full(12, 0.4)), world, course,
                  s2s.Options(**options))
    sim.reset(*course.spawn[[0, 1, 5]])
    return sim


@pytest.mark.parametrize("latency_ms, applied_in_first", [(0.0, True), (10.0, True),
                                                          (20.0, False)])
def test_latency_delays_the_pd_target(onnx_file, latency_ms, applied_in_first):
    """10 ms = 2 physics steps: the target takes over within the first control period; 20 ms
    = a whole period: the robot holds the previous target (the nominal pose) through it."""
    sim = _sim(onnx_file, latency_ms=latency_ms)
    assert sim.delay == int(latency_ms / 5)
    _, target = ct.action_to_target(sim.c, np.full(12, 0.4))
    sim.act(sim.observe())
    want = target if applied_in_first else sim.c.nominal
    np.testing.assert_allclose(sim.active, want)
    sim.act(sim.observe())
    np.testing.assert_allclose(sim.active, target)


@pytest.mark.parametrize("latency_ms", [0.0, 10.0, 20.0])
def test_the_pd_damping_follows_the_sidecars_schedule_at_the_robots_latency(onnx_file,
                                                                            latency_ms):
    """pd.kd_per_delay_s: the motors' damping is kd plus that times the latency the robot
    runs with (20 ms at 75: 1.0 + 1.5); without it (older sidecars) kd alone."""
    sim = _sim(onnx_file, latency_ms=latency_ms)
    sim.c = dataclasses.replace(sim.c, kd_per_delay=75.0)
    sim.w.data.qvel[sim.w.dof_adr] = 0.2
    q = sim.w.data.qpos[sim.w.qpos_adr].copy()
    sim.active = q  # no position error: the torque is the damping's alone
    kd = sim.c.kd + 75.0 * latency_ms * 1e-3
    np.testing.assert_allclose(sim.apply_pd(), -0.2 * kd * np.ones(12), rtol=1e-9)
    np.testing.assert_allclose(ct.pd_torque(dataclasses.replace(sim.c, kd_per_delay=0.0), q, q,
                                            np.full(12, 0.2), latency_ms * 1e-3),
                               -0.2 * sim.c.kd * np.ones(12), rtol=1e-9)


def test_noise_has_the_training_widths(onnx_file):
    sim = _sim(onnx_file, noise=True, seed=3)
    clean = ct.observation(sim.c, sim.measure())
    diff = np.stack([sim.observe() - clean for _ in range(50)])
    widths = sim.c.noise
    assert np.all(np.abs(diff) <= widths + 1e-6)
    noisy = widths > 0
    assert np.all(diff.std(0)[noisy] > 0.3 * widths[noisy])  # uniform: std = width / sqrt(3)
    for name in ("last_action", "goal"):
        assert np.all(diff[:, sim.c.slices[name]] == 0.0)
    assert widths[sim.c.slices["joint_vel"]][0] == 1.5  # the sidecar's training value


def test_a_push_kicks_the_base_velocity(onnx_file):
    calm, pushed = (_sim(onnx_file, push=p, push_every_s=0.1, push_speed=0.5, seed=1)
                    for p in (False, True))
    dof = calm.w.base_dof
    for k in range(6):  # a kick when control step 5 starts (every 0.1 s = 5 steps)
        before = pushed.w.data.qvel[dof:dof + 2].copy()
        for sim in (calm, pushed):
            sim.act(sim.observe())
        if k < 5:
            np.testing.assert_array_equal(calm.w.data.qvel, pushed.w.data.qvel)
    kick = pushed.w.data.qvel[dof:dof + 2] - calm.w.data.qvel[dof:dof + 2]
    assert np.linalg.norm(kick) == pytest.approx(0.5, rel=0.2)
    assert np.linalg.norm(before) < 0.3


def test_trunk_on_a_step_edge_counts_and_on_a_tread_does_not(onnx_file):
    """The robot upside down with its trunk box on a step's nosing: a trunk touch at an edge;
    the same on the middle of a tread: a touch, but not at an edge."""
    c = ct.load_contract(onnx_file)
    h = np.zeros((40, 80))
    h[:, 40:] = 0.15  # a step at x = 0.975 m (between grid points 39 and 40)
    course = s2s.Course("step", h, 0.025, np.array([0.5, 0.5, 0, 0.1, 0.1, 0, 0]),
                        np.array([1.8, 0.5, 0.15, 0.0]), np.array([[0.5, 0.5, 0], [1.8, 0.5, 0]]))
    counts = {}
    for name, x in (("edge", 0.975), ("tread", 1.6)):
        sim = s2s.Sim(c, lambda obs: np.zeros(12), sw.build_world(c, h, 0.025), course)
        sim.reset(x, 0.5, 0.0, z=0.15 + 0.057 - 0.002)
        qpos = sim.w.data.qpos
        qpos[3:7] = [0.0, 1.0, 0.0, 0.0]  # turned over about x: legs up, trunk top down
        sim.act(np.zeros(c.obs_size))
        counts[name] = dict(zip(sw.PARTS, sim.onsets, strict=True))
        d = sim.w.data
        assert d.ncon > 0
    assert counts["edge"]["trunk"] == 1 and counts["tread"]["trunk"] == 0
    assert all(v == 0 for k, v in counts["edge"].items() if k != "trunk")


@pytest.mark.parametrize("yaw, fallen_on_the_slope", [(0.0, False), (np.pi, True)])
def test_the_tilt_rule_reads_the_sidecars_slope_segment(onnx_file, yaw, fallen_on_the_slope):
    """A base pitched 65 deg nose up over a 37.8 deg stair: fallen by the world's vertical; by
    the sidecar's tilt_slope_m rule only when it faces down the stair (as endings.upright)."""
    riser, tread = 0.197, 0.254
    x = np.arange(160) * 0.025
    h = np.tile(riser * np.clip(np.floor((x - 1.0) / tread) + 1, 0, 12) * (x >= 1.0), (40, 1))
    course = s2s.Course("stair", h, 0.025, np.array([0.5, 0.5, 0, 0.1, 0.1, 0, 0]),
                        np.array([3.8, 0.5, h[0, -1], 0.0]), np.array([[0.5, 0.5, 0],
                                                                        [3.8, 0.5, 0]]))
    base = ct.load_contract(onnx_file)
    fallen = {}
    for length in (0.0, 0.8):
        c = dataclasses.replace(base, evaluation={**base.evaluation, "tilt_slope_m": length})
        sim = s2s.Sim(c, lambda obs: np.zeros(12), sw.build_world(c, h, 0.025), course)
        ground = riser * (np.floor((2.3 - 1.0) / tread) + 1)
        sim.reset(2.3, 0.5, yaw, z=ground + 0.3)
        pitch = np.radians(65)  # the heading's yaw, then nose up about the axis across it
        q = np.empty(4)
        mujoco.mju_mulQuat(q, [np.cos(pitch / 2), np.sin(pitch / 2) * np.sin(yaw),
                               -np.sin(pitch / 2) * np.cos(yaw), 0.0],
                           [np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])
        sim.w.data.qpos[sim.w.base_qpos + 3:sim.w.base_qpos + 7] = q
        _, rot = sim.base()
        assert rot[:, 0] @ [np.cos(yaw), np.sin(yaw), 0] == pytest.approx(np.cos(pitch))
        assert rot[2, 0] == pytest.approx(np.sin(pitch))  # the nose is up
        fallen[length] = sim.fallen()
    assert fallen == {0.0: True, 0.8: fallen_on_the_slope}


# ----------------------------------------------------------------------------- the command


def test_cli_runs_short_episodes_with_every_option(onnx_file, tmp_path, capsys):
    out, mcap = tmp_path / "r.json", tmp_path / "r.mcap"
    code = cli.main(["sim2sim", "--onnx", str(onnx_file), "--family", "u_shaped", "--level", "2",
                     "--resolution", "0.05", "--episodes", "2", "--episode-s", "0.6",
                     "--latency-ms", "20", "--noise", "--push", "--push-every", "0.2",
                     "--contact-timeconst", "0.01", "--out", str(out), "--mcap", str(mcap)])
    assert code == 0
    assert "u_shaped_test_2_up: success" in capsys.readouterr().out
    r = json.loads(out.read_text())
    assert r["episodes"] == 2 and len(r["records"]) == 2
    assert r["options"]["latency_ms"] == 20.0 and r["options"]["noise"] and r["options"]["push"]
    assert r["options"]["contact_timeconst"] == 0.01
    assert r["robot_sha256"] == hashlib.sha256(sw.OUR_ROBOT.read_bytes()).hexdigest()
    for rec in r["records"]:
        assert rec["outcome"] in ("timeout", "fell", "success")
        assert 0 < rec["time_s"] <= 0.6 + 1e-9
        assert set(rec["edge_contacts"]) == {"trunk", "hip", "thigh", "calf"}
    assert r["records"][0]["start"] != r["records"][1]["start"]
    from mjx_stairs.tools import mcap_log

    topics = mcap_log.read_mcap(mcap)
    steps = round(r["records"][0]["time_s"] / 0.02)
    assert len(topics["/robot0/joint_states"]) == steps and len(topics["/terrain"]) == 1
    names = topics["/robot0/joint_states"][0][1]["name"]
    assert names == list(rb.JOINT_NAMES)


@pytest.mark.skipif(not STAGE2.exists(), reason="no stage-2 policy in experiments/results")
def test_the_stage2_policy_climbs_u_level_1_in_sim2sim(tmp_path):
    """The published stage-2 policy, exported, on the full-geometry Go2 and box stairs."""
    export.export(STAGE2, tmp_path / "stage2.onnx")
    course = s2s.family_course("u_shaped", 1)
    r = s2s.run(tmp_path / "stage2.onnx", course, s2s.Options(episodes=1, seed=0))
    (rec,) = r["records"]
    assert rec["outcome"] == "success" and rec["time_s"] < 15.0


def test_the_runner_imports_no_training_code(onnx_file):
    """The observation is built without the env (or JAX): run an episode in a fresh process."""
    code = f"""
import sys
import numpy as np
from mjx_stairs.tools import sim2sim as s2s
course = s2s.family_course("straight", 1, resolution=0.05)
r = s2s.run({str(onnx_file)!r}, course, s2s.Options(episode_s=0.2))
assert r["records"][0]["time_s"] > 0
bad = sorted(m for m in sys.modules if m.startswith(("mjx_stairs.env", "mjx_stairs.rl", "jax")))
assert not bad, bad
print("clean")
"""
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=ROOT, env={"PYTHONPATH": str(ROOT), "JAX_PLATFORMS": "cpu",
                                        "PATH": "/usr/bin:/bin"})
    assert res.returncode == 0 and "clean" in res.stdout, res.stderr[-2000:]


def test_a_mesh_staircase_with_a_route(onnx_file, tmp_path):
    from terrains.mesh import export_tile

    tile = terrains.make_tile("straight", 0, schedule="test", resolution=0.05, tile_size=7.0)
    export_tile(tile, tmp_path / "stairs.stl")
    start, goal = tuple(tile.spawn[:2]), tuple(tile.goal[:2])
    course = s2s.mesh_course(tmp_path / "stairs.stl", start, goal, resolution=0.05)
    np.testing.assert_allclose(course.heights.max(), tile.heights.max(), atol=1e-3)
    mid = (np.asarray(start) + np.asarray(goal)) / 2
    routed = s2s.mesh_course(tmp_path / "stairs.stl", start, goal, [start, mid, goal], 0.05)
    assert routed.route.shape == (3, 3)
    assert routed.route[-1, 2] == pytest.approx(tile.goal[2], abs=0.01)
    r = s2s.run(onnx_file, routed, s2s.Options(episode_s=0.2))
    assert r["course"] == "stairs" and r["records"][0]["time_s"] > 0


# ----------------------------------------------------------------------------- bad inputs


def _one_line_error(capsys, argv) -> str:
    assert cli.main(["sim2sim", *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("mjx-stairs sim2sim: error:"), err
    return err[0]


def _copy_onnx(onnx_file, tmp_path) -> Path:
    dst = tmp_path / "p.onnx"
    dst.write_bytes(onnx_file.read_bytes())
    (tmp_path / "p.onnx.json").write_text(ct.sidecar_path(onnx_file).read_text())
    return dst


def _edit_sidecar(path: Path, fn) -> None:
    side = ct.sidecar_path(path)
    d = json.loads(side.read_text())
    fn(d)
    side.write_text(json.dumps(d))


def _without_joint(tmp_path) -> Path:
    text = sw.OUR_ROBOT.read_text().replace('name="RR_calf_joint"', 'name="RR_knee"')
    text = text.replace('joint="RR_calf_joint"', 'joint="RR_knee"')
    (tmp_path / "no_calf.xml").write_text(text)
    return tmp_path / "no_calf.xml"


def _position_servo(tmp_path) -> Path:
    text = sw.OUR_ROBOT.read_text().replace(
        '<motor name="FL_hip" joint="FL_hip_joint" ctrlrange="-23.7 23.7"/>',
        '<position name="FL_hip" joint="FL_hip_joint" kp="30" ctrlrange="-1 1"/>')
    (tmp_path / "servo.xml").write_text(text)
    return tmp_path / "servo.xml"


def _map_of_20(d: dict) -> None:
    """A sidecar that holds together on its own (a 20 x 20 map) but not with the graph."""
    d["onnx"]["sha256"] = None
    hm = d["height_map"]
    hm["size"], hm["x_m"], hm["y_m"] = [20, 20], hm["x_m"][:20], hm["y_m"][:20]
    d["observation"]["layout"][-1]["stop"] = d["observation"]["size"] = N_VEC + 400


BAD = {
    "missing onnx": (lambda f, t: ["--onnx", str(t / "nope.onnx")], "no such ONNX file"),
    "missing sidecar": (lambda f, t: ["--onnx", str(_copy_onnx(f, t))],
                        "no sidecar beside"),
    "sha mismatch": (lambda f, t: ["--onnx", str(_copy_onnx(f, t))], "sidecar mismatch"),
    "size mismatch": (lambda f, t: ["--onnx", str(_copy_onnx(f, t))], "sidecar mismatch"),
    "old format": (lambda f, t: ["--onnx", str(_copy_onnx(f, t))], "format"),
    "missing joint": (lambda f, t: ["--onnx", str(f), "--robot", str(_without_joint(t))],
                      "no joint named 'RR_calf_joint'"),
    "not a motor": (lambda f, t: ["--onnx", str(f), "--robot", str(_position_servo(t))],
                    "not a torque motor"),
    "missing robot": (lambda f, t: ["--onnx", str(f), "--robot", str(t / "go2.xml")],
                      "no such robot MJCF"),
    "negative timeconst": (lambda f, t: ["--onnx", str(f), "--contact-timeconst", "-0.01"],
                           "contact_timeconst must be"),
}
EDITS = {
    "missing sidecar": lambda p: ct.sidecar_path(p).unlink(),
    "sha mismatch": lambda p: _edit_sidecar(p, lambda d: d["onnx"].update(sha256="0" * 64)),
    "size mismatch": lambda p: _edit_sidecar(p, _map_of_20),
    "old format": lambda p: _edit_sidecar(p, lambda d: d.update(
        format="mjx_stairs policy sidecar v1")),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_inputs_give_one_line_errors(onnx_file, tmp_path, capsys, case):
    argv, words = BAD[case]
    args = argv(onnx_file, tmp_path)
    if case in EDITS:
        EDITS[case](tmp_path / "p.onnx")
    err = _one_line_error(capsys, [*args, "--family", "straight", "--level", "1",
                                   "--resolution", "0.05", "--episode-s", "0.1"])
    assert words in err


@pytest.mark.parametrize("argv, words", [
    ([], "give a staircase"),
    (["--family", "straight"], "--level"),
    (["--family", "straight", "--level", "9"], "out of range"),
    (["--mesh", "nowhere.stl", "--start", "0,0", "--goal", "1,1"], "no such mesh file"),
    (["--mesh", "nowhere.stl"], "--start"),
])
def test_bad_staircases_give_one_line_errors(onnx_file, capsys, argv, words):
    assert words in _one_line_error(capsys, ["--onnx", str(onnx_file), *argv])
