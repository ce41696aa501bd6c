"""env.obs_history: the observation keeps the joint positions and actions of earlier policy steps
(the table, the env's step, and the CPU ground truth's controller, which must keep them as the
env does)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import terrains
from mjx_stairs.config import ConfigError
from mjx_stairs.env import observation
from mjx_stairs.env.config import EnvConfig, HeightMapConfig
from mjx_stairs.env.stair_env import StairEnv
from mjx_stairs.rl import networks, normalizer
from mjx_stairs.rl.policy import (
    Policy,
    load_policy,
    policy_action,
    policy_value,
    widen_for_history,
)
from mjx_stairs.sim import robot as rb
from mjx_stairs.study import ground_truth

H, B = 2, 2


def test_history_terms_extend_the_vector_before_the_height_map():
    hm = HeightMapConfig()
    assert observation.terms(hm, 0) == observation.terms(hm)  # none at 0: the published layout
    names = [t.name for t in observation.terms(hm, H)]
    assert names[-4:] == ["goal", "joint_pos_history", "action_history", "height_map"]
    assert observation.n_vec(H) == observation.N_VEC + 2 * 12 * H
    assert observation.size(hm, H) == observation.size(hm) + 2 * 12 * H
    for bad in (-1, 51, 1.5):
        with pytest.raises(ConfigError, match="obs_history"):
            EnvConfig(obs_history=bad)


@pytest.fixture(scope="module")
def env():
    atlas = terrains.build_cell_atlas([("straight", "test", 2)], 1, resolution=0.1,
                                      tile_size=10.0, border=1.0)
    return StairEnv(atlas, EnvConfig(obs_history=H, episode_length_s=6.0))


@pytest.fixture(scope="module")
def run(env):
    """Two robots reset, then stepped with two known actions: the states, the actions."""
    reset = jax.jit(jax.vmap(env.reset_at))
    step = jax.jit(jax.vmap(env.step))
    s0 = reset(jax.random.split(jax.random.PRNGKey(0), B), jnp.zeros(B, jnp.int32),
               jnp.zeros(B, jnp.int32))
    rng = np.random.default_rng(0)
    a1, a2 = (jnp.asarray(rng.uniform(-0.5, 0.5, (B, 12)), jnp.float32) for _ in range(2))
    s1 = step(s0, a1)
    s2 = step(s1, a2)
    return (s0, s1, s2), (a1, a2)


def _joints(env, state):
    qpos = np.asarray(state.pipeline_state.qpos)
    return qpos[:, env.robot.ids.qpos_joints] - rb.NOMINAL_JOINT_POS


def test_the_env_keeps_earlier_steps_newest_first(env, run):
    (s0, s1, s2), (a1, _) = run
    assert not np.asarray(s2.done).any()  # no reset in between: one episode
    q0, q1 = _joints(env, s0), _joints(env, s1)
    assert np.abs(q1 - q0).max() > 1e-3  # the joints moved: a real comparison
    zero = np.zeros((B, 12))
    for state, joints, actions in ((s0, [q0, q0], [zero, zero]), (s1, [q0, q0], [zero, zero]),
                                   (s2, [q1, q0], [np.asarray(a1), zero])):
        np.testing.assert_allclose(state.info["joint_pos_history"], np.stack(joints, 1),
                                   atol=1e-6)
        np.testing.assert_allclose(state.info["action_history"], np.stack(actions, 1), atol=0)
        # and the observation carries them at the table's place (the critic's: no noise)
        at = {t.name: i for i, t in enumerate(observation.terms(env.config.height_map, H))}
        start = sum(t.size for t in observation.terms(env.config.height_map, H)[
            :at["joint_pos_history"]])
        obs = np.asarray(state.obs["privileged_state"])
        np.testing.assert_allclose(obs[:, start:start + 12 * H],
                                   np.stack(joints, 1).reshape(B, -1), atol=1e-6)
        np.testing.assert_allclose(obs[:, start + 12 * H:start + 24 * H],
                                   np.stack(actions, 1).reshape(B, -1), atol=1e-6)


def test_ground_truth_controller_keeps_the_history_as_the_env(env, run):
    """The CPU ground truth observes through env.observe with its own info: called once per
    control step with the robots' state and last action, it must hold the same history the
    env's step does (here from the env's own states, so the two can be compared exactly)."""
    (s0, s1, s2), _ = run
    n_vec, shape = observation.n_vec(H), env.map_shape
    net = networks.NetworkConfig()
    d = n_vec + shape[0] * shape[1]
    policy = Policy(networks.init_params(jax.random.PRNGKey(1), net, n_vec, shape, 12),
                    {k: normalizer.init_stats(d) for k in ("state", "privileged_state")},
                    net, networks.ObsLayout(n_vec, shape), 12, {})
    info = {k: v for k, v in s0.info.items() if k != "final_obs"}
    control = ground_truth._Controller(env, policy, info)
    for state in (s0, s1, s2):
        q, v = np.asarray(state.pipeline_state.qpos), np.asarray(state.pipeline_state.qvel)
        control(q, v, np.asarray(state.info["last_action"]))
        for key in ("joint_pos_history", "action_history"):
            np.testing.assert_allclose(control._info[key], state.info[key], atol=1e-6)


def test_a_published_policy_widened_for_history_acts_as_before():
    """A history policy fine-tunes from a published one (trainer.start_from_policy): the new
    inputs get zero weights and a unit normaliser, so whatever the history holds, the widened
    policy's actions and values are the published policy's."""
    policy = load_policy("experiments/results/stage2_u_robot/policy.npz")
    extra = observation.n_vec(H) - observation.N_VEC
    wide = widen_for_history(policy, extra)
    assert wide.layout.n_vec == observation.n_vec(H) and wide.layout.map_shape == (21, 21)
    rng = np.random.default_rng(3)
    obs = rng.normal(size=(16, policy.layout.obs_size)).astype(np.float32)
    obs[:, policy.layout.n_vec:] = rng.uniform(-1.0, 1.0, (16, 21 * 21))
    history = rng.uniform(-3.0, 3.0, (16, extra)).astype(np.float32)
    wide_obs = np.concatenate([obs[:, :policy.layout.n_vec], history,
                               obs[:, policy.layout.n_vec:]], 1)
    np.testing.assert_allclose(policy_action(wide, jnp.asarray(wide_obs)),
                               policy_action(policy, jnp.asarray(obs)), atol=1e-5)
    np.testing.assert_allclose(policy_value(wide, jnp.asarray(wide_obs)),
                               policy_value(policy, jnp.asarray(obs)), atol=1e-4)
    # and the history reaches the network once its weights are not zero (a real widening)
    first = wide.params["actor"][0]
    bumped = wide._replace(params={**wide.params, "actor": [
        {**first, "w": first["w"].at[policy.network.latent_size + policy.layout.n_vec].set(1.0)},
        *wide.params["actor"][1:]]})
    assert np.abs(np.asarray(policy_action(bumped, jnp.asarray(wide_obs)))
                  - np.asarray(policy_action(wide, jnp.asarray(wide_obs)))).max() > 1e-3
