"""env.obs_action_delay: the observation carries the robot's action delay (the table, the env's
reset draws, the mirror, and the fine-tune from a policy that did not observe it)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import terrains
from mjx_stairs.config import ConfigError
from mjx_stairs.env import observation, symmetry
from mjx_stairs.env.config import EnvConfig, HeightMapConfig, RandomizationConfig
from mjx_stairs.env.stair_env import StairEnv
from mjx_stairs.rl import trainer
from mjx_stairs.rl.policy import load_policy, policy_action, widen_for_history

B = 16


def test_the_delay_term_is_the_vector_parts_last_entry():
    hm = HeightMapConfig()
    names = [t.name for t in observation.terms(hm, 2, delay=True)]
    assert names[-5:] == ["goal", "joint_pos_history", "action_history", "action_delay",
                          "height_map"]
    assert observation.n_vec(0, True) == observation.N_VEC + 1
    assert observation.terms(hm, 0, False) == observation.terms(hm)  # off: the published layout
    with pytest.raises(ConfigError, match="obs_action_delay"):
        EnvConfig(obs_action_delay=1)
    m = symmetry.of_config(EnvConfig(obs_action_delay=True))
    at = observation.N_VEC  # a time, the same in the mirror
    assert m.obs.index[at] == at and m.obs.sign[at] == 1.0


def _reset(actor: bool = True):
    """16 robots reset with the delay drawn over 0-20 ms (0-4 physics steps) and observed (by
    the actor too, or the critic alone)."""
    atlas = terrains.build_cell_atlas([("straight", "test", 2)], 1, resolution=0.1,
                                      tile_size=10.0, border=1.0)
    cfg = EnvConfig(obs_action_delay=True, obs_action_delay_actor=actor, episode_length_s=6.0,
                    randomization=RandomizationConfig(action_delay_s=(0.0, 0.02)))
    env = StairEnv(atlas, cfg)
    reset = jax.jit(jax.vmap(env.reset_at))
    return env, reset(jax.random.split(jax.random.PRNGKey(0), B), jnp.zeros(B, jnp.int32),
                      jnp.zeros(B, jnp.int32))


@pytest.fixture(scope="module")
def reset_states():
    return _reset()


def test_each_robot_observes_the_delay_it_drew(reset_states):
    env, s = reset_states
    steps = np.asarray(s.info["delay_steps"])
    assert len(set(steps.tolist())) >= 3  # drawn per robot: a real comparison
    at = observation.N_VEC
    want = steps * env.config.robot.timestep * observation.DELAY_SCALE
    for key in ("state", "privileged_state"):  # no noise on it
        np.testing.assert_allclose(np.asarray(s.obs[key])[:, at], want, atol=1e-6)
    assert set(np.round(want, 6).tolist()) <= {0.0, 0.25, 0.5, 0.75, 1.0}


def test_an_asymmetric_critic_alone_reads_the_delay(reset_states):
    """env.obs_action_delay_actor false: the actor reads 0 where the critic reads the delay;
    every other entry as with the delay observed by both."""
    with pytest.raises(ConfigError, match="obs_action_delay_actor"):
        EnvConfig(obs_action_delay_actor=False)  # nothing to hide
    _, told = reset_states
    _, blind = _reset(actor=False)
    at = observation.N_VEC
    np.testing.assert_array_equal(np.asarray(blind.obs["state"])[:, at], 0.0)
    np.testing.assert_array_equal(np.asarray(blind.obs["privileged_state"]),
                                  np.asarray(told.obs["privileged_state"]))
    assert np.asarray(told.obs["state"])[:, at].max() > 0  # the draws reach the told actor
    np.testing.assert_array_equal(np.delete(np.asarray(blind.obs["state"]), at, 1),
                                  np.delete(np.asarray(told.obs["state"]), at, 1))


@pytest.mark.parametrize("saved, history, delay, widens", [
    ({}, 0, True, True),  # the published layout, the delay added
    ({"obs_history": 3}, 3, True, True),  # a history policy, the delay added
    ({}, 3, True, True),  # both added
    ({}, 3, False, True),  # history added (the rule before the delay term)
    ({"obs_action_delay": True}, 3, True, False),  # history would go before the saved delay
    ({"obs_history": 3}, 2, True, False),  # less history
    ({"obs_action_delay": True}, 0, True, False),  # nothing added
    ({"obs_action_delay": True}, 0, False, False),  # the delay taken away
])
def test_a_fine_tune_widens_only_where_terms_are_appended(saved, history, delay, widens):
    assert trainer.appends_terms(saved, history, delay) is widens


def test_a_published_policy_widened_for_the_delay_acts_as_before():
    """The delay's input gets zero weights: the widened policy acts as the published one
    whatever delay it is told."""
    policy = load_policy("experiments/results/stage2_u_robot/policy.npz")
    wide = widen_for_history(policy, 1)
    rng = np.random.default_rng(3)
    obs = rng.normal(size=(8, policy.layout.obs_size)).astype(np.float32)
    n = policy.layout.n_vec
    told = rng.uniform(0.0, 1.0, (8, 1)).astype(np.float32)
    wide_obs = np.concatenate([obs[:, :n], told, obs[:, n:]], 1)
    np.testing.assert_allclose(policy_action(wide, jnp.asarray(wide_obs)),
                               policy_action(policy, jnp.asarray(obs)), atol=1e-5)
