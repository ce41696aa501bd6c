"""The stair env on MJX (CPU): stepping, height map, terminations, rewards, curriculum, success."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import terrains
from mjx_stairs.config import ConfigError
from mjx_stairs.env import curriculum as cur
from mjx_stairs.env import observation
from mjx_stairs.env import rewards as rw
from mjx_stairs.env.config import EnvConfig
from mjx_stairs.env.geometry import base_kinematics, quat_to_mat
from mjx_stairs.env.stair_env import StairEnv
from mjx_stairs.sim import robot as rb

B = 8
LEVELS = (0, 6)  # pyramid level 1 is flat, level 7 has 0.1 m risers


@pytest.fixture(scope="session")
def atlas():
    return terrains.build_atlas(
        ["pyramid"],
        "train",
        levels=list(LEVELS),
        variants_per_family=1,
        resolution=0.05,
        tile_size=10.0,
        border=1.0,
    )


@pytest.fixture(scope="session")
def env(atlas):
    return StairEnv(atlas, EnvConfig(episode_length_s=6.0))


@pytest.fixture(scope="session")
def fns(env):
    return {
        "reset_at": jax.jit(jax.vmap(env.reset_at)),
        "step": jax.jit(jax.vmap(env.step)),
    }


def _reset(env, fns, rows, seed=0):
    keys = jax.random.split(jax.random.PRNGKey(seed), B)
    return fns["reset_at"](keys, jnp.asarray(rows, jnp.int32), jnp.zeros(B, jnp.int32))


def test_contact_layout_matches_a_physics_step(env, fns):
    """The env's contact rows are where MJX's collision puts each sphere's heightfield contacts
    (one step of the env's own compiled program, shared with the other tests)."""
    state = fns["step"](_reset(env, fns, [0] * B), jnp.zeros((B, env.action_size)))
    geom = np.asarray(state.pipeline_state._impl.contact.geom)
    assert geom.shape[0] == B
    for group, ids in (("foot", env.robot.ids.foot_geoms), ("trunk", env.robot.ids.trunk_geoms)):
        rows = env.contact_rows[group]
        for k, g in enumerate(ids):
            assert np.all(geom[:, rows[k]] == [env.robot.ids.hfield_geom, g])


def test_reset_and_step_100_steps(env, fns):
    state = _reset(env, fns, [0, 1] * 4)
    rng = jax.random.PRNGKey(1)
    for _ in range(100):
        rng, k = jax.random.split(rng)
        state = fns["step"](state, jax.random.uniform(k, (B, 12), minval=-1, maxval=1))
    n = env.observation_size["state"][0]
    for key in ("state", "privileged_state"):
        assert state.obs[key].shape == (B, n) and state.obs[key].dtype == jnp.float32
        assert not np.isnan(np.asarray(state.obs[key])).any()
    assert state.reward.shape == (B,) and not np.isnan(np.asarray(state.reward)).any()
    assert state.done.shape == (B,)
    for term in rw.active_terms(env.config.rewards):
        assert f"reward/{term}" in state.metrics
    assert state.info["final_obs"]["privileged_state"].shape == (B, n)
    assert state.pipeline_state.qpos.shape == (B, 19)


def test_a_robot_whose_physics_blows_up_is_reset_and_the_others_step_on(env, fns):
    """The NaN guard: a robot whose step ends non-finite (here a joint speed of 1e20 rad/s)
    terminates with reward 0 and comes back reset; every other robot's step is the one it takes
    without the bad robot beside it; and the next step of all of them is finite throughout."""
    state = _reset(env, fns, [0] * B)
    ps = state.pipeline_state
    bad = state.replace(pipeline_state=ps.replace(qvel=ps.qvel.at[0, 6:].set(1e20)))
    action = jnp.zeros((B, env.action_size))
    clean, hit = fns["step"](state, action), fns["step"](bad, action)
    assert float(hit.metrics["nan_reset"][0]) == 1.0 and float(hit.done[0]) == 1.0
    assert float(hit.reward[0]) == 0.0
    assert not np.any(np.asarray(clean.metrics["nan_reset"]))
    for a, b in ((hit.pipeline_state.qpos, clean.pipeline_state.qpos), (hit.reward, clean.reward),
                 (hit.obs["state"], clean.obs["state"])):
        np.testing.assert_array_equal(np.asarray(a)[1:], np.asarray(b)[1:])
    fresh = np.asarray(hit.pipeline_state.qpos[0])
    assert np.all(np.isfinite(fresh)) and np.allclose(fresh[7:], rb.NOMINAL_JOINT_POS, atol=0.2)
    assert np.all(np.isfinite(np.asarray(hit.pipeline_state.ctrl)))
    for obs in (hit.obs, hit.info["final_obs"]):  # the final obs feeds the value bootstrap
        assert all(np.all(np.isfinite(np.asarray(v))) for v in obs.values())
    after = fns["step"](hit, action)
    for leaf in (after.pipeline_state.qpos, after.pipeline_state.qvel, after.pipeline_state.xpos,
                 after.reward, *after.obs.values(), *after.metrics.values()):
        assert np.all(np.isfinite(np.asarray(leaf)))
    assert not np.any(np.asarray(after.metrics["nan_reset"]))


def test_height_map_matches_numpy_reference(env, atlas):
    rng = np.random.default_rng(0)
    t = atlas.cols * 1  # the stair tile (level 7)
    ox, oy = atlas.origin[t]
    pos = np.stack(
        [ox + rng.uniform(2, 8, 16), oy + rng.uniform(2, 8, 16), rng.uniform(0.3, 1.5, 16)], -1
    )
    yaw = rng.uniform(-np.pi, np.pi, 16)
    got = np.asarray(
        jax.jit(jax.vmap(env.height_map, in_axes=(0, 0, None)))(
            jnp.asarray(pos, jnp.float32), jnp.asarray(yaw, jnp.float32), t
        )
    )
    hm = env.config.height_map
    half = 0.5 * (hm.size - 1) * hm.spacing
    gx, gy = np.meshgrid(np.linspace(-half, half, hm.size), np.linspace(-half, half, hm.size))
    for i in range(16):
        c, s = np.cos(yaw[i]), np.sin(yaw[i])
        extent = (atlas.tile_points - 1) * atlas.resolution  # the map reads this tile alone
        wx = np.clip(pos[i, 0] + c * gx - s * gy, ox, ox + extent)
        wy = np.clip(pos[i, 1] + s * gx + c * gy, oy, oy + extent)
        ref = terrains.sample_heights(atlas.heights, atlas.resolution, wx, wy)
        ref = np.clip(pos[i, 2] - ref - hm.offset, -hm.clip, hm.clip).ravel()
        np.testing.assert_allclose(got[i], ref, atol=2e-4)
    assert np.ptp(got) > 0.1  # the tile has stairs in view: the map is not flat


def test_nominal_pose_survives_5s_and_tilted_robot_terminates(env, fns):
    state = _reset(env, fns, [0] * B)  # flat tile
    zero = jnp.zeros((B, 12))
    for _ in range(int(5.0 / env.dt)):
        state = fns["step"](state, zero)
        assert not np.any(np.asarray(state.done)), "a standing robot was ended"
    z = np.asarray(state.pipeline_state.qpos[:, 2])
    assert np.all((z > 0.2) & (z < 0.4))

    tilted = _reset(env, fns, [0] * B, seed=3)
    angle = env.config.max_tilt + 0.3
    quat = jnp.array([np.cos(angle / 2), np.sin(angle / 2), 0.0, 0.0])  # roll past the limit
    qpos = tilted.pipeline_state.qpos.at[:4, 3:7].set(quat)
    tilted = tilted.replace(pipeline_state=tilted.pipeline_state.replace(qpos=qpos))
    after = fns["step"](tilted, zero)
    np.testing.assert_array_equal(np.asarray(after.metrics["terminated"]), [1] * 4 + [0] * 4)
    assert np.all(np.asarray(after.info["truncation"]) == 0)
    assert np.all(np.asarray(after.info["step"])[:4] == 0)  # auto-reset into a new episode


def test_episode_end_moves_level_and_reports_success(env, fns):
    state = _reset(env, fns, [0] * B)
    # Robots 0-3 stand still on the goal, 4-7 stay at the spawn; the episode is about to time out.
    goal = env.tiles.goal[state.info["tile"]]
    qpos = state.pipeline_state.qpos
    at_goal = qpos.at[:, 0:2].set(goal[:, :2]).at[:, 2].set(goal[:, 2] + 0.30)
    yaw = goal[:, 3]
    at_goal = at_goal.at[:, 3:7].set(
        jnp.stack([jnp.cos(yaw / 2), 0 * yaw, 0 * yaw, jnp.sin(yaw / 2)], -1)
    )
    near = jnp.arange(B) < 4
    qpos = jnp.where(near[:, None], at_goal, qpos)
    steps = env.episode_steps - 30
    info = dict(state.info, step=jnp.full(B, steps, jnp.int32))
    state = state.replace(pipeline_state=state.pipeline_state.replace(qpos=qpos), info=info)
    zero = jnp.zeros((B, 12))
    ended = None
    for _ in range(30):
        state = fns["step"](state, zero)
        if np.any(np.asarray(state.done)):
            ended = state
            break
    assert ended is not None
    assert np.all(np.asarray(ended.done) == 1) and np.all(np.asarray(ended.info["truncation"]) == 1)
    np.testing.assert_array_equal(np.asarray(ended.metrics["episode_success"]), [1] * 4 + [0] * 4)
    # Level 0 -> 1 for robots at the goal, stays 0 (clamped down) for the others.
    np.testing.assert_array_equal(np.asarray(ended.info["level"]), [1] * 4 + [0] * 4)


# ----------------------------------------------------------------------------- reward terms


def _quantities(**kw):
    base = dict(
        time=jnp.float32(8.0),
        goal_distance=jnp.float32(3.0),
        planar_goal_distance=jnp.float32(3.0),
        yaw_error=jnp.float32(0.0),
        centreline_distance=jnp.float32(0.0),
        path_to_goal=jnp.float32(3.0),
        lin_vel_body=jnp.zeros(3),
        ang_vel_body=jnp.zeros(3),
        gravity_body=jnp.array([0.0, 0.0, -1.0]),
        planar_speed=jnp.float32(0.0),
        torque=jnp.zeros(12),
        joint_pos=jnp.zeros(12),
        joint_vel=jnp.zeros(12),
        joint_acc=jnp.zeros(12),
        action=jnp.zeros(12),
        last_action=jnp.zeros(12),
        joint_lower=-jnp.ones(12),
        joint_upper=jnp.ones(12),
        joint_vel_limit=jnp.float32(27.0),
        trunk_contacts=jnp.zeros(4, bool),
        knee_contacts=jnp.zeros(4, bool),
        shin_contacts=jnp.zeros(4, bool),
        first_contact=jnp.zeros(4, bool),
        air_time=jnp.zeros(4),
        foot_contact=jnp.zeros(4, bool),
        sole_height=jnp.zeros(4),
        ground_under_foot=jnp.zeros(4),
        ground_ahead_of_foot=jnp.zeros(4),
    )
    base.update(kw)
    return rw.Quantities(**base)


def test_stall_penalty_fires_only_slow_and_away_from_goal():
    c = rw.STAGE2
    assert rw.stall(_quantities(planar_speed=jnp.float32(0.1)), c) == 1.0
    assert rw.stall(_quantities(planar_speed=jnp.float32(0.29)), c) == 1.0
    assert rw.stall(_quantities(planar_speed=jnp.float32(0.5)), c) == 0.0
    inside = _quantities(planar_speed=jnp.float32(0.0), planar_goal_distance=jnp.float32(0.3))
    assert rw.stall(inside, c) == 0.0
    total, terms = rw.compute(_quantities(planar_speed=jnp.float32(0.1)), c, 0.02)
    assert float(terms["stall"]) == pytest.approx(c.stall * 0.02)
    _, terms_off = rw.compute(_quantities(), dataclasses.replace(c, stall=0.0), 0.02)
    assert "stall" not in terms_off


def test_centreline_reward_highest_on_the_line():
    c = rw.STAGE2
    line = jnp.array([[0.0, 0.0], [4.0, 0.0], [4.0, 3.0]] + [[4.0, 3.0]] * 5)
    cum = jnp.concatenate(
        [jnp.zeros(1), jnp.cumsum(jnp.linalg.norm(jnp.diff(line, axis=0), axis=-1))]
    )
    values = []
    for offset in (0.0, 0.3, 0.8, 1.5):
        dc, arc = rw.centreline_geometry(jnp.array([2.0, offset]), line, cum)
        assert float(dc) == pytest.approx(offset, abs=1e-6) and float(arc) == pytest.approx(2.0)
        q = _quantities(centreline_distance=dc, path_to_goal=dc + cum[-1] - arc)
        values.append(float(rw.centreline(q, c)))
    assert values == sorted(values, reverse=True) and values[0] > values[-1] + 0.3
    # Further along the line toward the goal is better too.
    near = _quantities(path_to_goal=jnp.float32(1.0))
    far = _quantities(path_to_goal=jnp.float32(6.0))
    assert rw.centreline(near, c) > rw.centreline(far, c)


def test_navigation_terms_increase_as_goal_nears():
    c = rw.STAGE1
    ds = [6.0, 3.0, 1.0, 0.2]
    coarse = [float(rw.nav_coarse(_quantities(goal_distance=jnp.float32(d)), c)) for d in ds]
    fine = [float(rw.nav_fine(_quantities(goal_distance=jnp.float32(d)), c)) for d in ds]
    assert coarse == sorted(coarse) and fine == sorted(fine)
    assert rw.heading(_quantities(yaw_error=jnp.float32(1.0)), c) > rw.heading(_quantities(), c)
    late = rw.STAGE2  # fine and heading count only after fine_after_s
    assert (
        rw.nav_fine(_quantities(goal_distance=jnp.float32(0.2), time=jnp.float32(1.0)), late) == 0.0
    )


def test_base_motion_terms_read_the_bodys_rates_and_lean_not_the_stairs_pitch(env, fns):
    """lin_vel_z, ang_vel_xy and roll: zero for a level robot at rest, the squares of what they
    name otherwise, a pitch alone (a stair's) free of the roll term; off unless weighted. The
    env feeds them the base's body-frame rates and gravity (robot 0 after a step, rolled 20 deg
    and turning)."""
    c = dataclasses.replace(rw.STAGE2, lin_vel_z=-2.0, ang_vel_xy=-0.05, roll=-1.0)
    for term in (rw.lin_vel_z, rw.ang_vel_xy, rw.roll):
        assert float(term(_quantities(), c)) == 0.0
        assert term.__name__ not in rw.active_terms(rw.STAGE1) + rw.active_terms(rw.STAGE2)
    moving = _quantities(lin_vel_body=jnp.array([0.5, 0.1, 0.3]),
                         ang_vel_body=jnp.array([1.0, 2.0, 3.0]))
    assert float(rw.lin_vel_z(moving, c)) == pytest.approx(0.09)
    assert float(rw.ang_vel_xy(moving, c)) == pytest.approx(5.0)
    pitch, lean = np.radians(35.0), np.radians(20.0)
    pitched = _quantities(gravity_body=jnp.array([np.sin(pitch), 0.0, -np.cos(pitch)]))
    assert float(rw.roll(pitched, c)) == pytest.approx(0.0, abs=1e-12)
    _, terms = rw.compute(moving, c, 0.02)
    assert float(terms["ang_vel_xy"]) == pytest.approx(-0.05 * 0.02 * 5.0)
    state = fns["step"](_reset(env, fns, [0] * B), jnp.zeros((B, env.action_size)))
    one = jax.tree.map(lambda x: x[0], state)
    d = one.pipeline_state
    quat = jnp.array([np.cos(lean / 2), np.sin(lean / 2), 0.0, 0.0])  # about the body's x
    d = d.replace(qpos=d.qpos.at[3:7].set(quat),
                  qvel=d.qvel.at[3:6].set(jnp.array([1.0, 2.0, 3.0])))
    q, _, _ = env._quantities(d, base_kinematics(d.qpos, d.qvel), jnp.zeros(12), one.info)
    np.testing.assert_allclose(np.asarray(q.ang_vel_body), [1.0, 2.0, 3.0])
    assert float(rw.roll(q, c)) == pytest.approx(np.sin(lean) ** 2, rel=1e-5)


def _step_at(x0: float, rise: float):
    """A terrain height function with one step of `rise` (m) at x = x0 (jnp, like the env's)."""
    return lambda x, y: jnp.where(x > x0, rise, 0.0) + 0.0 * y


@pytest.mark.parametrize("case", ["stub", "lifted", "standing", "flat", "down", "facing_away"])
def test_foot_clearance_costs_a_swing_foot_carried_low_into_a_riser_alone(case):
    """foot_clearance through feet_quantities on a 19.7 cm step at x = 1: the swing foot 5 cm
    before it with its sole 5 cm up costs the rise + 5 cm target - 5 cm; lifted above the next
    tread + target, on the ground (in contact), on flat ground, facing a drop or facing away from
    the step, it costs nothing."""
    c = dataclasses.replace(rw.STAGE2, foot_clearance=-2.0)
    rise, yaw, sole, contact = 0.197, 0.0, 0.05, False
    if case == "lifted":
        sole = rise + c.clearance_target + 0.01
    rise = {"flat": 0.0, "down": -0.197}.get(case, rise)
    yaw = np.pi if case == "facing_away" else yaw
    contact = case == "standing"
    radius = jnp.full(4, 0.022)
    feet = jnp.array([[0.95, 0.1, sole + 0.022]] + [[0.0, 0.0, 0.022]] * 3)  # three feet far back
    f = rw.feet_quantities(_step_at(1.0, rise), feet, radius, jnp.float32(yaw),
                           jnp.array([contact, True, True, True]), c)
    q = _quantities(**f)
    want = 0.197 + c.clearance_target - 0.05 if case == "stub" else 0.0
    assert float(rw.foot_clearance(q, c)) == pytest.approx(want, abs=1e-6)
    _, terms = rw.compute(q, c, 0.02)
    assert float(terms["foot_clearance"]) == pytest.approx(-2.0 * 0.02 * want, abs=1e-7)
    assert "foot_clearance" not in rw.active_terms(rw.STAGE2)  # off in the paper's reward
    off = rw.feet_quantities(_step_at(1.0, rise), feet, radius, jnp.float32(yaw),
                             jnp.ones(4, bool), rw.STAGE2)
    assert not np.any(np.asarray(off["foot_contact"])) and float(rw.foot_clearance(
        _quantities(**off), c)) == 0.0  # no terrain read while unweighted


def test_foot_clearance_reads_the_feet_of_a_standing_robot_on_their_ground(env, fns, atlas):
    """The env's foot_clearance inputs for robots that stood 1 s on the flat tile: each foot
    touches, its sole (sphere centre - radius) within 5 mm of the terrain under it, which is the
    atlas's own height there (numpy reference); no riser ahead on flat ground, so no cost."""
    cfg = dataclasses.replace(env.config,
                              rewards=dataclasses.replace(env.config.rewards, foot_clearance=-2.0))
    weighted = StairEnv(atlas, cfg)
    state = _reset(env, fns, [0] * B)
    for _ in range(int(1.0 / env.dt)):
        state = fns["step"](state, jnp.zeros((B, 12)))
    one = jax.tree.map(lambda x: x[0], state)
    d = one.pipeline_state
    q, _, foot = weighted._quantities(d, base_kinematics(d.qpos, d.qvel), jnp.zeros(12), one.info)
    feet = np.asarray(d.geom_xpos[env.robot.ids.foot_geoms])
    ref = terrains.sample_heights(atlas.heights, atlas.resolution, feet[:, 0], feet[:, 1])
    np.testing.assert_allclose(np.asarray(q.ground_under_foot), ref, atol=2e-4)
    assert np.all(np.asarray(q.foot_contact)) and np.all(np.asarray(foot))
    np.testing.assert_allclose(np.asarray(q.sole_height), ref, atol=5e-3)
    assert float(rw.foot_clearance(q, cfg.rewards)) == 0.0


# ----------------------------------------------------------------------------- curriculum


def test_curriculum_rule_up_down_top_random_per_robot():
    cfg = cur.CurriculumConfig()
    n = 10
    level = jnp.array([0, 4, 4, 0, 9, 9, 9, 9])
    up = jnp.array([True, True, False, False, True, True, True, False])
    keys = jax.random.split(jax.random.PRNGKey(0), 8)
    new = jax.vmap(lambda lv, u, k: cur.next_level(lv, u, n, k, cfg))(level, up, keys)
    new = np.asarray(new)
    assert list(new[:4]) == [1, 5, 3, 0]  # up, up, down, down clamped at 0
    assert new[7] == 8  # failed at the top: down
    assert np.all((new[4:7] >= 0) & (new[4:7] < n))  # cleared the top: random levels
    many = jax.vmap(lambda k: cur.next_level(jnp.int32(9), jnp.bool_(True), n, k, cfg))(
        jax.random.split(jax.random.PRNGKey(1), 200)
    )
    assert len(set(np.asarray(many).tolist())) > 5
    no_random = dataclasses.replace(cfg, random_on_top=False)
    assert int(cur.next_level(jnp.int32(9), jnp.bool_(True), n, keys[0], no_random)) == 9
    assert bool(cur.reached(jnp.float32(0.7), jnp.float32(0.3), cfg))
    assert not bool(cur.reached(jnp.float32(0.9), jnp.float32(0.0), cfg))
    assert not bool(cur.reached(jnp.float32(0.1), jnp.float32(0.5), cfg))


def test_curriculum_random_level_prob_jumps_that_often_and_zero_is_the_rule():
    n, keys = 10, jax.random.split(jax.random.PRNGKey(2), 4000)

    def step(cfg, level, up):
        return np.asarray(jax.vmap(lambda k: cur.next_level(jnp.int32(level), jnp.bool_(up), n,
                                                            k, cfg))(keys))

    rule = cur.CurriculumConfig()
    assert np.all(step(dataclasses.replace(rule, random_level_prob=0.0), 4, False) == 3)
    assert np.all(step(rule, 4, True) == 5)
    mixed = step(dataclasses.replace(rule, random_level_prob=0.25), 4, True)
    moved = mixed != 5  # a jump lands on 5 one time in 10
    assert 0.25 * 0.9 - 0.03 < moved.mean() < 0.25 * 0.9 + 0.03
    assert set(mixed[moved].tolist()) == set(range(n)) - {5}
    every = step(dataclasses.replace(rule, random_level_prob=1.0), 0, False)
    assert np.abs(np.bincount(every, minlength=n) / len(every) - 0.1).max() < 0.03
    with pytest.raises(ConfigError, match="env.curriculum.random_level_prob"):
        cur.CurriculumConfig(random_level_prob=1.5)
    # jumps from a low level land on levels 7-9 only, uniformly; the rule's own moves unchanged
    high = step(dataclasses.replace(rule, random_level_prob=1.0, random_level_low=7), 2, False)
    assert set(high.tolist()) == {7, 8, 9}
    assert np.abs(np.bincount(high, minlength=n)[7:] / len(high) - 1 / 3).max() < 0.04
    some = step(dataclasses.replace(rule, random_level_prob=0.25, random_level_low=7), 2, False)
    assert set(some.tolist()) == {1, 7, 8, 9}
    top = step(dataclasses.replace(rule, random_level_prob=1.0, random_level_low=20), 2, False)
    assert np.all(top == n - 1)  # above the atlas: its top level
    with pytest.raises(ConfigError, match="env.curriculum.random_level_low"):
        cur.CurriculumConfig(random_level_low=-1)


def test_tile_table_keeps_family_columns():
    family = np.array([0, 0, 1, 1, 1, 0, 0, 1, 1, 1])  # 2 rows x 5 columns
    table = cur.TileTable(family, cols=5, num_families=2)
    keys = jax.random.split(jax.random.PRNGKey(0), 64)
    tiles = np.asarray(
        jax.vmap(lambda k: cur.pick_tile(jnp.int32(1), jnp.int32(1), table, k))(keys)
    )
    assert set(tiles.tolist()) == {7, 8, 9}
    with pytest.raises(ValueError, match="no column"):
        cur.TileTable(np.zeros(4, int), cols=2, num_families=2)


def test_packed_state_resumes_the_same_trajectory(env, fns):
    state = _reset(env, fns, [1] * B, seed=5)
    rng = jax.random.PRNGKey(2)
    for _ in range(5):
        rng, k = jax.random.split(rng)
        state = fns["step"](state, jax.random.uniform(k, (B, 12), minval=-1, maxval=1))
    packed = jax.jit(jax.vmap(env.pack_state))(state)
    size = sum(np.asarray(x).nbytes for x in jax.tree_util.tree_leaves(packed)) / B
    full = sum(np.asarray(x).nbytes for x in jax.tree_util.tree_leaves(state)) / B
    assert size < full / 10
    restored = jax.jit(jax.vmap(env.unpack_state))(packed)
    np.testing.assert_allclose(
        np.asarray(restored.obs["privileged_state"]), np.asarray(state.obs["privileged_state"]),
        atol=1e-5,
    )
    a = jax.random.uniform(rng, (B, 12), minval=-1, maxval=1)
    for _ in range(3):
        state, restored = fns["step"](state, a), fns["step"](restored, a)
    np.testing.assert_allclose(
        np.asarray(restored.pipeline_state.qpos), np.asarray(state.pipeline_state.qpos), atol=1e-4
    )
    np.testing.assert_allclose(np.asarray(restored.reward), np.asarray(state.reward), atol=1e-4)


@pytest.fixture(scope="session")
def u_atlas():
    return terrains.build_atlas(
        ["u_shaped"], "train", levels=[0], variants_per_family=2, resolution=0.05, tile_size=10.0
    )


def _point_at_arc(line, s):
    """Numpy reference: the polyline point at arc length s and the heading of its segment."""
    seg = np.diff(line, axis=0)
    length = np.linalg.norm(seg[:, :2], axis=1)
    keep = length > 1e-9
    seg, length, start = seg[keep], length[keep], line[:-1][keep]
    cum = np.concatenate([[0.0], np.cumsum(length)])
    i = min(np.searchsorted(cum, s, side="right") - 1, len(length) - 1)
    t = (s - cum[i]) / length[i]
    return start[i] + t * seg[i], np.arctan2(seg[i, 1], seg[i, 0]), cum[-1]


def test_waypoint_goal_follows_the_centreline_then_becomes_the_goal(u_atlas):
    env = StairEnv(u_atlas, EnvConfig(goal_mode="waypoint", waypoint_lookahead_m=1.0))
    final = StairEnv(u_atlas, EnvConfig())
    target = jax.jit(env.goal_target)
    for tile in range(2):  # left- and right-turning
        line = np.asarray(u_atlas.centreline[tile], np.float64)
        goal = np.asarray(u_atlas.goal[tile])
        total = _point_at_arc(line, 0.0)[2]
        for s in (0.0, 0.7, 2.5, total / 2, total - 1.5):
            p, yaw, _ = _point_at_arc(line, s)
            want, want_yaw, _ = _point_at_arc(line, s + 1.0)
            got = np.asarray(target(jnp.asarray([p[0], p[1], p[2] + 0.3], jnp.float32), tile))
            np.testing.assert_allclose(got[:3], want, atol=2e-3, err_msg=f"tile {tile} s {s}")
            assert abs(np.angle(np.exp(1j * (got[3] - want_yaw)))) < 1e-3
            # 1 m ahead along the line is 1 m or less away in a straight line (corners cut).
            assert np.linalg.norm(got[:2] - p[:2]) <= 1.0 + 2e-3
        # Closer than the lookahead along the line: the final goal itself, yaw included.
        p, _, _ = _point_at_arc(line, total - 0.6)
        got = np.asarray(target(jnp.asarray([p[0], p[1], p[2] + 0.3], jnp.float32), tile))
        np.testing.assert_allclose(got, goal, atol=1e-5)
        # The paper's mode always points at the goal.
        at_p = final.goal_target(jnp.asarray(p, jnp.float32), tile)
        np.testing.assert_allclose(np.asarray(at_p), goal)


@pytest.mark.parametrize("heading", ["here", "chord"])
def test_waypoint_heading_rules_turn_later_than_ahead_at_a_corner(u_atlas, heading):
    """env.waypoint_heading: the waypoint is the same point 1 m ahead; its yaw is the line's
    heading at the robot's own projection ("here") or from that projection to the point
    ("chord") instead of at the point ("ahead"); the robot-side rule (tools.contract, numpy)
    gives the same target."""
    import types

    from mjx_stairs.tools import contract

    ahead = jax.jit(StairEnv(u_atlas, EnvConfig(goal_mode="waypoint")).goal_target)
    rule_env = jax.jit(StairEnv(u_atlas, EnvConfig(goal_mode="waypoint",
                                                   waypoint_heading=heading)).goal_target)
    rule = types.SimpleNamespace(goal_mode="waypoint", lookahead=1.0, heading=heading)
    turned = 0
    for tile in range(2):  # left- and right-turning
        line = np.asarray(u_atlas.centreline[tile], np.float64)
        total = _point_at_arc(line, 0.0)[2]
        for s in np.linspace(0.13, total - 1.17, 23):
            p, yaw_here, _ = _point_at_arc(line, s)
            want, yaw_ahead, _ = _point_at_arc(line, s + 1.0)
            want_yaw = yaw_here if heading == "here" else np.arctan2(*(want - p)[1::-1])
            pos = jnp.asarray([p[0], p[1], p[2] + 0.3], jnp.float32)
            got_a, got = np.asarray(ahead(pos, tile)), np.asarray(rule_env(pos, tile))
            np.testing.assert_allclose(got[:3], want, atol=2e-3, err_msg=f"tile {tile} s {s}")
            np.testing.assert_allclose(got[:3], got_a[:3], atol=1e-6)
            assert abs(np.angle(np.exp(1j * (got[3] - want_yaw)))) < 2e-3
            assert abs(np.angle(np.exp(1j * (got_a[3] - yaw_ahead)))) < 1e-3
            robot_side = contract.goal_target(rule, p[:2], np.asarray(u_atlas.goal[tile]), line)
            np.testing.assert_allclose(robot_side, got, atol=2e-3)
            turned += abs(np.angle(np.exp(1j * (yaw_ahead - got[3])))) > 0.5
    assert turned >= 4  # a corner lay within the lookahead: the rules differ there


def test_waypoint_goal_is_what_the_policy_sees(u_atlas):
    env = StairEnv(u_atlas, EnvConfig(goal_mode="waypoint"))
    state = jax.jit(env.reset_at)(jax.random.PRNGKey(0), jnp.int32(0), jnp.int32(1))
    qpos = state.pipeline_state.qpos
    obs = np.asarray(env.observe(qpos, jnp.zeros(18), state.info)["privileged_state"])
    wp = np.asarray(env.goal_target(qpos[:3], state.info["tile"]))
    rot = np.asarray(quat_to_mat(qpos[3:7]))
    start = sum(t.size for t in observation.VECTOR[:-1])  # the goal is the last vector term
    goal_obs = obs[start:observation.N_VEC]
    np.testing.assert_allclose(goal_obs[:3], rot.T @ (wp[:3] - np.asarray(qpos[:3])), atol=1e-5)
    assert np.linalg.norm(goal_obs[:2]) < 1.2  # the waypoint, not the goal ~2 m across the wall


def test_bad_goal_mode_is_a_one_line_error(u_atlas):
    from mjx_stairs.config import from_dict

    with pytest.raises(ConfigError, match="config key 'env.goal_mode': expected one of"):
        from_dict(EnvConfig, {"goal_mode": "carrot"}, prefix="env")
    with pytest.raises(ValueError, match="env.waypoint_lookahead_m"):
        StairEnv(u_atlas, EnvConfig(goal_mode="waypoint", waypoint_lookahead_m=0.0))
    with pytest.raises(ConfigError, match="config key 'env.waypoint_heading'"):
        EnvConfig(goal_mode="waypoint", waypoint_heading="behind")


def test_per_family_metrics_split_level_top_and_success_by_family():
    from mjx_stairs.env import endings

    names = endings.metric_names(("dist",), False, ("building", "u_shaped"))
    assert "level/building#num" in names and "success/u_shaped#den" in names
    assert not any("#" in n for n in endings.metric_names(("dist",), False, ("u_shaped",)))
    family, level = jnp.asarray([0, 0, 1, 1]), jnp.asarray([9, 2, 9, 9])
    done, success = jnp.asarray([1, 0, 1, 1], bool), jnp.asarray([1.0, 0.0, 0.0, 1.0])
    e = endings.Endings(success, *([jnp.zeros(4)] * 7), jnp.zeros(4, bool), done)
    m = jax.vmap(lambda f, lv, ee: endings.family_metrics(("building", "u_shaped"), f, lv, 9,
                                                          ee))(family, level, e)
    ratio = {k[:-4]: float(m[k].sum() / m[k[:-4] + "#den"].sum())
             for k in m if k.endswith("#num")}
    assert ratio == {"level/building": 5.5, "at_top/building": 0.5, "success/building": 1.0,
                     "level/u_shaped": 9.0, "at_top/u_shaped": 1.0, "success/u_shaped": 0.5}
