"""The left-right mirror (env.symmetry) against the env itself: on a straight flight, which is its
own mirror image about its centre-line, the observation of a robot's mirrored state is the
mirrored observation of its state, every term and the height map; mirroring twice is nothing."""

import dataclasses
import types

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import terrains
from mjx_stairs.env import observation, symmetry
from mjx_stairs.env.config import EnvConfig
from mjx_stairs.env.stair_env import StairEnv

H, B = 2, 3


@pytest.fixture(scope="module")
def env():
    """A straight flight made exactly its own mirror image about its centre-line (the grid's
    middle row: the atlas puts a wall's edge on one side's node and not the other's)."""
    atlas = terrains.build_cell_atlas([("straight", "test", 3)], 1, resolution=0.1,
                                      tile_size=10.0, border=1.0)
    h = np.asarray(atlas.heights)
    assert h.shape[0] % 2 == 1 and np.allclose(atlas.centreline[0][:, 1],
                                               (h.shape[0] - 1) // 2 * atlas.resolution)
    atlas = dataclasses.replace(atlas, heights=np.maximum(h, h[::-1]))
    return StairEnv(atlas, EnvConfig(obs_history=H, episode_length_s=6.0))


@pytest.fixture(scope="module")
def states(env):
    """B robots after 6 random-action steps (off-centre, turned, moving, with a history)."""
    state = jax.jit(jax.vmap(env.reset_at))(jax.random.split(jax.random.PRNGKey(3), B),
                                            jnp.zeros(B, jnp.int32), jnp.zeros(B, jnp.int32))
    step = jax.jit(jax.vmap(env.step))
    key = jax.random.PRNGKey(4)
    for _ in range(6):
        key, k = jax.random.split(key)
        state = step(state, 0.6 * jax.random.normal(k, (B, 12)))
    return state


def _mirrored(qpos, qvel, info, y_line, m):
    """The robot's state reflected in the vertical plane y = y_line."""
    mirror_joints = m.act.apply
    w, x, y, z = qpos[3:7]
    qpos = jnp.concatenate([jnp.array([qpos[0], 2 * y_line - qpos[1], qpos[2], w, -x, y, -z]),
                            mirror_joints(qpos[7:])])
    qvel = jnp.concatenate([qvel[:3] * jnp.array([1.0, -1.0, 1.0]),
                            qvel[3:6] * jnp.array([-1.0, 1.0, -1.0]), mirror_joints(qvel[6:])])
    info = dict(info, **{k: mirror_joints(info[k])
                         for k in ("last_action", "joint_pos_history", "action_history")})
    return qpos, qvel, info


def test_the_observation_of_a_mirrored_robot_is_the_mirrored_observation(env, states):
    m = env.mirror
    observe = jax.jit(env.observe)
    y_line = float(env.tiles.line3[0][0, 1])
    assert np.allclose(np.asarray(env.tiles.line3[0])[:, 1], y_line)  # a straight centre-line
    table = observation.terms(env.config.height_map, H)
    bounds = np.cumsum([0] + [t.size for t in table])
    for r in range(B):
        info = jax.tree_util.tree_map(lambda x, r=r: x[r], states.info)
        qpos, qvel = states.pipeline_state.qpos[r], states.pipeline_state.qvel[r]
        assert abs(float(qpos[1]) - y_line) > 0.02 and np.abs(np.asarray(qvel[:6])).max() > 0.05
        obs = observe(qpos, qvel, info)["privileged_state"]
        seen = np.asarray(observe(*_mirrored(qpos, qvel, info, y_line, m))["privileged_state"])
        want = np.asarray(m.obs.apply(obs))
        assert not np.allclose(want, np.asarray(obs), atol=1e-3)  # the mirror changes it
        for t, a, b in zip(table, bounds[:-1], bounds[1:], strict=True):
            np.testing.assert_allclose(seen[a:b], want[a:b], atol=2e-4, err_msg=t.name)


def test_mirroring_twice_is_nothing_and_an_unknown_term_is_refused(env):
    m = env.mirror
    x = jax.random.normal(jax.random.PRNGKey(0), (4, len(m.obs.index)))
    np.testing.assert_array_equal(m.obs.apply(m.obs.apply(x)), x)
    a = jax.random.normal(jax.random.PRNGKey(1), (4, 12))
    np.testing.assert_array_equal(m.act.apply(m.act.apply(a)), a)
    assert sorted(m.obs.index) == list(range(len(m.obs.index)))  # a permutation
    new = types.SimpleNamespace(name="foot_forces", size=4)
    with pytest.raises(ValueError, match="'foot_forces' has no left-right mirror"):
        symmetry.mirror_of([*observation.terms(env.config.height_map), new], 21)
