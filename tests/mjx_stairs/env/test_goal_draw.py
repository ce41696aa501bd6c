"""Per-episode goals on the raised stairs (env.goal_draw, env.goals), the any-heading spawn and
the movement term: the authors' stage-2 set-up (issue 21)."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import terrains
from mjx_stairs.config import ConfigError, from_dict
from mjx_stairs.env import observation
from mjx_stairs.env import rewards as rw
from mjx_stairs.env.config import EnvConfig, GoalDrawConfig, evaluation_config
from mjx_stairs.env.geometry import quat_to_mat, quat_yaw
from mjx_stairs.env.stair_env import StairEnv

N = 400
PAPER = EnvConfig(goal_draw=GoalDrawConfig(enabled=True), spawn_yaw_half_range=float(np.pi),
                  episode_length_s=2.0)


@pytest.fixture(scope="module")
def u_atlas():
    # U-shaped level 5 of 10: 0.064 m risers, the top landing ~1.4 m up
    return terrains.build_atlas(["u_shaped"], "train", levels=[4], variants_per_family=2,
                                resolution=0.05, tile_size=10.0)


@pytest.fixture(scope="module")
def drawn(u_atlas):
    env = StairEnv(u_atlas, PAPER)
    keys = jax.random.split(jax.random.PRNGKey(1), N)
    states = jax.jit(jax.vmap(env.reset_at))(keys, jnp.zeros(N, jnp.int32),
                                             jnp.zeros(N, jnp.int32))
    return env, states


def _distance_to_line(p: np.ndarray, line: np.ndarray) -> float:
    a, b = line[:-1, :2], line[1:, :2]
    ab = b - a
    t = np.clip(((p[:2] - a) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-12), 0, 1)
    return float(np.linalg.norm(p[:2] - (a + t[:, None] * ab), axis=-1).min())


def test_goals_lie_on_the_raised_centreline_or_at_the_spawn(u_atlas, drawn):
    env, states = drawn
    goal = np.asarray(states.info["goal"])
    arc = np.asarray(states.info["goal_arc"])
    tile = np.asarray(states.info["tile"])
    qpos = np.asarray(states.pipeline_state.qpos)
    floor = np.asarray(u_atlas.floor_height)
    still = np.linalg.norm(goal[:, :2] - qpos[:, :2], axis=1) < 1e-4
    assert 0.01 < still.mean() < 0.10  # stationary_prob 0.05
    np.testing.assert_allclose(goal[still, 3], [float(quat_yaw(jnp.asarray(q[3:7])))
                                                for q in qpos[still]], atol=1e-5)
    for i in np.nonzero(~still)[0]:
        line = np.asarray(u_atlas.centreline[tile[i]])
        assert _distance_to_line(goal[i], line) < 2e-3
        assert goal[i, 2] >= floor[tile[i]] + 0.2 - 1e-4  # raised at least min_rise
        # the goal's z is the centre-line's (the terrain) at its arc length
        h = env.terrain_height(jnp.float32(goal[i, 0]), jnp.float32(goal[i, 1]))
        assert abs(float(h) - goal[i, 2]) < 0.07  # one riser of the step it stands on
    moving = arc[~still]
    total = float(env.tiles.line_len[0])
    # near goals (the first flight) as well as far ones (flight 2, the top landing)
    assert moving.min() < 0.35 * total and moving.max() > 0.9 * total
    assert np.ptp(goal[~still, 3]) > 5.5  # yaw drawn over [-pi, pi]


def test_the_spawn_heading_is_any_and_evaluation_restores_the_tiles(u_atlas, drawn):
    env, states = drawn
    yaw = np.asarray(jax.vmap(quat_yaw)(states.pipeline_state.qpos[:, 3:7]))
    spread = np.angle(np.exp(1j * (yaw - float(env.tiles.spawn[0, 5]))))
    assert np.abs(spread).max() > 2.8  # the tile's own half-range is pi / 4
    ev = StairEnv(u_atlas, evaluation_config(PAPER))
    s = jax.jit(jax.vmap(ev.reset_at))(jax.random.split(jax.random.PRNGKey(2), 64),
                                       jnp.zeros(64, jnp.int32), jnp.zeros(64, jnp.int32))
    assert "goal" not in s.info  # the tiles' goals on the top landing
    yaw = np.asarray(jax.vmap(quat_yaw)(s.pipeline_state.qpos[:, 3:7]))
    assert np.abs(np.angle(np.exp(1j * (yaw - float(ev.tiles.spawn[0, 5]))))).max() <= np.pi / 4


def test_the_policy_rewards_and_curriculum_see_the_drawn_goal(drawn):
    env, states = drawn
    one = jax.tree.map(lambda x: x[:8], states)
    goal = np.asarray(one.info["goal"])
    obs = np.asarray(one.obs["privileged_state"])
    qpos = np.asarray(one.pipeline_state.qpos)
    start = sum(t.size for t in observation.VECTOR[:-1])  # the goal is the last vector term
    for i in range(8):
        rot = np.asarray(quat_to_mat(jnp.asarray(qpos[i, 3:7])))
        np.testing.assert_allclose(obs[i, start:start + 3], rot.T @ (goal[i, :3] - qpos[i, :3]),
                                   atol=1e-4)
    after = jax.jit(jax.vmap(env.step))(one, jnp.zeros((8, 12)))
    moved = np.asarray(after.pipeline_state.qpos[:, :2])
    want = np.linalg.norm(goal[:, :2] - moved, axis=1)
    np.testing.assert_allclose(np.asarray(after.metrics["goal_distance"]), want, atol=1e-4)
    np.testing.assert_array_equal(np.asarray(after.info["goal"]), goal)  # fixed for the episode


def test_goal_draw_needs_the_final_goal_mode():
    with pytest.raises(ConfigError, match="config key 'env.goal_draw.enabled': must be false"):
        from_dict(EnvConfig, {"goal_mode": "waypoint", "goal_draw": {"enabled": True}},
                  prefix="env")
    with pytest.raises(ConfigError, match="env.goal_draw.stationary_prob"):
        GoalDrawConfig(stationary_prob=1.5)


SIZES = {"lin_vel_body": 3, "ang_vel_body": 3, "gravity_body": 3, "trunk_contacts": 4,
         "knee_contacts": 4, "shin_contacts": 4,
         "first_contact": 4, "air_time": 4, "torque": 12, "joint_pos": 12, "joint_vel": 12,
         "joint_acc": 12, "action": 12, "last_action": 12, "joint_lower": 12, "joint_upper": 12}


def _q(**kw):
    fields = {f: jnp.zeros(SIZES.get(f, ())) for f in rw.Quantities._fields}
    base = dict(time=jnp.float32(1.0), goal_distance=jnp.float32(3.0),
                planar_goal_distance=jnp.float32(3.0), planar_speed=jnp.float32(0.6),
                joint_lower=-jnp.ones(12), joint_upper=jnp.ones(12),
                joint_vel_limit=jnp.float32(27.0))
    return rw.Quantities(**{**fields, **base, **kw})


def test_movement_rewards_moving_early_and_away_from_the_goal():
    c = dataclasses.replace(rw.STAGE2, movement=0.2, fine_after_s=6.0)
    assert float(rw.movement(_q(), c)) == pytest.approx(np.tanh(2.5), abs=1e-6)
    assert float(rw.movement(_q(planar_speed=jnp.float32(0.05)), c)) == 0.0  # too slow
    assert float(rw.movement(_q(goal_distance=jnp.float32(0.3)), c)) == 0.0  # at the goal
    assert float(rw.movement(_q(time=jnp.float32(6.5)), c)) == 0.0  # late: fine terms' time
    _, terms = rw.compute(_q(), c, 0.02)
    assert float(terms["movement"]) == pytest.approx(0.2 * 0.02 * np.tanh(2.5), rel=1e-5)
    assert "movement" not in rw.active_terms(rw.STAGE2)  # off unless weighted
