"""The ground truth (CPU MuJoCo on box stairs) and the tile-locality of a step."""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

import terrains
from mjx_stairs.env.config import env_config_from, evaluation_config
from mjx_stairs.env.stair_env import StairEnv
from mjx_stairs.sim import box_world as bw
from mjx_stairs.sim import robot as rb
from terrains.boxes import grid_boxes


def test_go2_stands_on_box_stairs_with_its_weight_on_the_treads():
    tile = terrains.make_tile("u_shaped", 3, schedule="test", resolution=0.05)
    model = bw.build_model(grid_boxes(tile.heights, tile.resolution))
    sp = tile.spawn
    start = np.stack([rb.standing_qpos((sp[0], sp[1]), sp[2] + 0.36)] * 2)
    robots = bw.Batch([model, model], start, nthread=1)
    for _ in range(100):  # 2 s holding the nominal pose
        robots.step(np.tile(rb.NOMINAL_JOINT_POS, (2, 1)), 4)
    assert np.all(np.abs(robots.qpos[:, 2] - sp[2] - 0.29) < 0.03)
    assert np.all(np.abs(robots.qvel) < 0.05)
    data = mujoco.MjData(model)
    mujoco.mj_setState(model, data, robots.state[0], bw.STATE)
    data.ctrl[:] = rb.NOMINAL_JOINT_POS  # the PD target (a state does not carry it)
    mujoco.mj_forward(model, data)
    weight = float(model.body_subtreemass[1]) * 9.81
    assert bw.contact_summary(model, data)["vertical_force"] == pytest.approx(weight, rel=0.05)


def test_a_delay_holds_the_previous_target_for_its_physics_steps():
    """Batch.step with a delay (robot.action_delay_s in the ground truth): a delay of every
    substep is the previous target held, none is the new one, two of four is neither."""
    model = bw.build_model(np.zeros((0, 6)))
    start = np.stack([rb.standing_qpos((0.0, 0.0), 0.36)] * 2)
    before = np.tile(rb.NOMINAL_JOINT_POS + 0.3, (2, 1))
    after = np.tile(rb.NOMINAL_JOINT_POS - 0.3, (2, 1))
    runs = {}
    for name, target, delay in (("late", after, 4), ("held", before, 0), ("now", after, 0),
                                ("half", after, 2)):
        robots = bw.Batch([model, model], start, nthread=1)
        robots.step(target, 4, previous=before, delay=delay)
        runs[name] = robots.qpos.copy()
        robots.close()
    np.testing.assert_array_equal(runs["late"], runs["held"])
    assert np.abs(runs["late"] - runs["now"]).max() > 1e-3
    for other in ("late", "now"):
        assert np.abs(runs["half"] - runs[other]).max() > 1e-5


def test_pd_actuators_are_the_env_pd_law():
    model = bw.build_model(np.zeros((0, 6)), rb.RobotConfig(kp=30.0, kd=0.8))
    data = mujoco.MjData(model)
    rng = np.random.default_rng(0)
    data.qpos[:] = rb.standing_qpos()
    data.qpos[7:] += rng.uniform(-0.3, 0.3, 12)
    data.qvel[6:] = rng.uniform(-3, 3, 12)
    data.ctrl[:] = rb.NOMINAL_JOINT_POS + rng.uniform(-1, 1, 12)
    mujoco.mj_forward(model, data)
    expected = rb.pd_torque(data.ctrl, data.qpos[7:], data.qvel[6:], 30.0, 0.8, rb.TORQUE_LIMIT)
    np.testing.assert_allclose(data.actuator_force, expected, rtol=1e-5, atol=1e-5)


def _env(cells):
    atlas = terrains.build_cell_atlas(cells, 2, resolution=0.05, tile_size=10.0)
    return StairEnv(atlas, evaluation_config(env_config_from(None, ["robot.physics=evaluation"])))


def test_a_step_on_a_tile_does_not_depend_on_the_rest_of_the_atlas():
    """The evaluation physics (columns collider, shin spheres, 8 Newton iterations, 10
    line-search steps, the stiff 0.01 s contact): one step from the same states and actions on a
    tile alone and in a wider atlas whose other tiles are taller (so the heightfield's span,
    extent and centre all differ) gives the same next state and observation to 1e-5 (measured:
    the same state bit for bit, observations 2.4e-7 apart; also under the speed XLA flags). The
    columns collider works from the atlas corner, so a tile's points have the same float32
    coordinates in both; from the atlas centre (to
    2026-11-28) they were 1 ulp apart at 10 m, which the stiff contact turned into 1.1e-5 m/s.
    MJX's own collider (the reference physics) computes a contact in the heightfield's frame
    (centred on the atlas, heights scaled by its span), so there float32 rounding differs between
    the atlases and one Newton iteration passes it on: velocities agree to 1e-4 only (measured
    5.7e-5 m/s, relative 2e-4)."""
    cell = ("u_shaped", "test", 3)
    alone = _env([cell])
    wide = _env([cell, ("straight", "extended", 5), ("spiral", "extended", 5)])
    assert wide.atlas_shape[0] > alone.atlas_shape[0]
    keys = jax.random.split(jax.random.PRNGKey(3), 6)
    zero = jnp.zeros(6, jnp.int32)
    state = jax.jit(jax.vmap(alone.reset_at))(keys, zero, zero)
    step_alone, step_wide = jax.jit(jax.vmap(alone.step)), jax.jit(jax.vmap(wide.step))
    actions = 0.3 * jax.random.normal(jax.random.PRNGKey(4), (25, 6, 12))
    for k in range(25):  # land on the floor and walk a little: contacts of every kind
        state = step_alone(state, actions[k])
    a = 0.3 * jax.random.normal(jax.random.PRNGKey(5), (6, 12))
    x, y = step_alone(state, a), step_wide(state, a)
    np.testing.assert_allclose(x.pipeline_state.qpos, y.pipeline_state.qpos, atol=1e-5)
    np.testing.assert_allclose(x.pipeline_state.qvel, y.pipeline_state.qvel, atol=1e-5)
    np.testing.assert_allclose(x.obs["state"], y.obs["state"], atol=1e-5)
    # The same state observed in both atlases: the height map reads the robot's tile alone.
    info = {k: v for k, v in x.info.items() if k != "final_obs"}
    q, v = x.pipeline_state.qpos, x.pipeline_state.qvel
    np.testing.assert_allclose(jax.vmap(alone.observe)(q, v, info)["state"],
                               jax.vmap(wide.observe)(q, v, info)["state"], atol=1e-5)
