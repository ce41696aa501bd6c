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


def _reset(actor: bool = True, damping: bool = False):
    """16 robots reset with the delay drawn over 0-20 ms (0-4 physics steps) and observed (by
    the actor too, or the critic alone), with `damping` the joints' damping drawn over [0.1, 2]
    and observed by the critic alone."""
    atlas = terrains.build_cell_atlas([("straight", "test", 2)], 1, resolution=0.1,
                                      tile_size=10.0, border=1.0)
    cfg = EnvConfig(obs_action_delay=True, obs_action_delay_actor=actor, episode_length_s=6.0,
                    obs_joint_damping=damping, randomization=RandomizationConfig(
                        action_delay_s=(0.0, 0.02), joint_damping=(0.1, 2.0) if damping else ()))
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


def test_an_asymmetric_critic_alone_reads_the_delay_and_the_damping(reset_states):
    """env.obs_action_delay_actor false, env.obs_joint_damping: the actor reads 0 where the
    critic reads the delay and the damping each robot drew; every other entry as with the delay
    observed by both."""
    with pytest.raises(ConfigError, match="obs_action_delay_actor"):
        EnvConfig(obs_action_delay_actor=False)  # nothing to hide
    with pytest.raises(ConfigError, match="obs_joint_damping"):
        EnvConfig(obs_joint_damping=1)
    _, told = reset_states
    env, blind = _reset(actor=False, damping=True)  # and the damping the critic's alone
    at = observation.N_VEC  # the delay, then the damping
    state, priv = np.asarray(blind.obs["state"]), np.asarray(blind.obs["privileged_state"])
    np.testing.assert_array_equal(state[:, at:at + 2], 0.0)
    np.testing.assert_array_equal(np.delete(priv, at + 1, 1),
                                  np.asarray(told.obs["privileged_state"]))
    drawn = np.asarray(blind.info["joint_damping"])
    assert drawn.min() >= 0.1 and drawn.max() <= 2.0 and drawn.std() > 0.2
    np.testing.assert_allclose(priv[:, at + 1], drawn, rtol=1e-6)
    assert np.asarray(told.obs["state"])[:, at].max() > 0  # the draws reach the told actor
    widths = np.concatenate([np.full(t.size, getattr(env.config.noise, t.noise) if t.noise
                                     else 0.0) for t in observation.of_config(env.config)])
    gap = np.abs(np.delete(state - priv, [at, at + 1], 1))  # elsewhere the actor's noise alone
    assert np.all(gap <= np.delete(widths, [at, at + 1]) + 1e-6) and gap.max() > 0
    m = symmetry.of_config(blind_cfg := EnvConfig(obs_action_delay=True, obs_joint_damping=True))
    assert m.obs.index[at + 1] == at + 1 and observation.n_vec_of(blind_cfg) == at + 2


@pytest.mark.parametrize("saved, delay, damping, widens", [
    ({}, False, True, True),  # the damping added
    ({}, True, True, True),  # both added
    ({"obs_action_delay": True}, True, True, True),  # the damping after the saved delay
    ({"obs_joint_damping": True}, True, True, False),  # the delay would go before it
    ({"obs_joint_damping": True}, False, True, False),  # nothing added
])
def test_the_damping_term_widens_only_where_appended(saved, delay, damping, widens):
    assert trainer.appends_terms(saved, 0, delay, damping) is widens


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
