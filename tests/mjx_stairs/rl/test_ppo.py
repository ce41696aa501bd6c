"""PPO pieces: GAE against a plain loop (and brax), the clipped loss by hand, the update step."""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from brax.training.agents.ppo.losses import compute_gae as brax_compute_gae

from mjx_stairs.env import symmetry
from mjx_stairs.rl import networks, normalizer, optim, ppo
from mjx_stairs.rl.networks import NetworkConfig, ObsLayout
from mjx_stairs.rl.ppo import Batch, PPOConfig


def gae_loop(truncation, termination, rewards, values, bootstrap, lam, gamma, trunc_values):
    """The definition, one robot and one step at a time."""
    T, B = rewards.shape
    adv = np.zeros((T, B))
    for b in range(B):
        next_adv = 0.0
        for t in reversed(range(T)):
            if termination[t, b]:
                next_v, boundary = 0.0, True
            elif truncation[t, b]:
                next_v, boundary = trunc_values[t, b], True
            else:
                next_v = values[t + 1, b] if t + 1 < T else bootstrap[b]
                boundary = False
            delta = rewards[t, b] + gamma * next_v - values[t, b]
            adv[t, b] = delta + (0.0 if boundary else gamma * lam * next_adv)
            next_adv = adv[t, b]
    return adv, adv + values


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_gae_matches_python_loop(seed):
    rng = np.random.default_rng(seed)
    T, B = 17, 6
    u = rng.uniform(size=(T, B))
    termination = (u < 0.1).astype(np.float32)
    truncation = ((u >= 0.1) & (u < 0.2)).astype(np.float32)
    truncation[3, 0] = termination[3, 0] = 1.0  # both set: termination wins
    truncation[T - 1, 1], termination[T - 1, 1] = 1.0, 0.0  # timeout on the last step
    termination[T - 1, 2], truncation[T - 1, 2] = 1.0, 0.0
    rewards = rng.normal(size=(T, B)).astype(np.float32)
    values = rng.normal(size=(T, B)).astype(np.float32)
    bootstrap = rng.normal(size=B).astype(np.float32)
    trunc_values = rng.normal(size=(T, B)).astype(np.float32)
    lam, gamma = 0.95, 0.99
    adv, target = jax.jit(ppo.compute_gae, static_argnums=(5, 6))(
        truncation, termination, rewards, values, bootstrap, lam, gamma, trunc_values)
    want_adv, want_target = gae_loop(truncation, termination, rewards, values, bootstrap, lam,
                                     gamma, trunc_values)
    np.testing.assert_allclose(adv, want_adv, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(target, want_target, rtol=1e-5, atol=1e-5)
    # truncation values matter only where truncated
    other = trunc_values + 10.0 * (1 - truncation)
    adv2, _ = ppo.compute_gae(truncation, termination, rewards, values, bootstrap, lam, gamma,
                              other)
    np.testing.assert_allclose(adv2, adv, rtol=1e-6, atol=1e-6)


def test_gae_equals_brax_without_truncation():
    rng = np.random.default_rng(5)
    T, B = 12, 4
    termination = (rng.uniform(size=(T, B)) < 0.15).astype(np.float32)
    zeros = np.zeros((T, B), np.float32)
    rewards, values = rng.normal(size=(2, T, B)).astype(np.float32)
    bootstrap = rng.normal(size=B).astype(np.float32)
    adv, target = ppo.compute_gae(zeros, termination, rewards, values, bootstrap, 0.9, 0.97,
                                  zeros)
    vs, _ = brax_compute_gae(zeros, termination, rewards, values, bootstrap, 0.9, 0.97)
    np.testing.assert_allclose(target, vs, rtol=1e-5, atol=1e-5)


LAYOUT = ObsLayout(3, (5, 5))
NET = NetworkConfig(conv_channels=(2, 2, 4), latent_size=8, actor_hidden=(16,),
                    critic_hidden=(16,))


def _batch(params, norm, n=32, seed=0, value_shift=0.0):
    k = jax.random.split(jax.random.PRNGKey(seed), 5)
    obs = jax.random.normal(k[0], (n, 28))
    cobs = obs + 0.1 * jax.random.normal(k[1], (n, 28))
    mean = ppo.policy_mean(params, norm, obs, NET, LAYOUT)
    action = networks.sample(k[2], mean, params["log_std"])
    value = ppo.critic_value(params, norm, cobs, NET, LAYOUT) + value_shift
    adv = jax.random.normal(k[3], (n,))
    return Batch(obs=obs, critic_obs=cobs, action=action,
                 log_prob=networks.log_prob(mean, params["log_std"], action), mean=mean,
                 value=value, advantage=adv, target=value + adv + jax.random.normal(k[4], (n,)))


@pytest.fixture(scope="module")
def setup():
    params = jax.jit(networks.init_params, static_argnums=(1, 2, 3, 4))(
        jax.random.PRNGKey(0), NET, 3, (5, 5), 2)
    norm = {k: normalizer.init_stats(28) for k in ("state", "privileged_state")}
    return params, norm


def _loss_by_hand(params, norm, batch, cfg):
    mean = ppo.policy_mean(params, norm, batch.obs, NET, LAYOUT)
    lp = np.asarray(networks.log_prob(mean, params["log_std"], batch.action))
    v = np.asarray(ppo.critic_value(params, norm, batch.critic_obs, NET, LAYOUT))
    adv = np.asarray(batch.advantage)
    adv = (adv - adv.mean()) / (adv.std() + 1e-8)
    ratio = np.exp(lp - np.asarray(batch.log_prob))
    surr = np.minimum(ratio * adv, np.clip(ratio, 1 - cfg.clip_eps, 1 + cfg.clip_eps) * adv)
    old_v, tgt = np.asarray(batch.value), np.asarray(batch.target)
    v_clip = old_v + np.clip(v - old_v, -cfg.value_clip_eps, cfg.value_clip_eps)
    v_loss = np.maximum((v - tgt) ** 2, (v_clip - tgt) ** 2).mean()
    ent = float(np.sum(np.asarray(params["log_std"]) + 0.5 * (1 + np.log(2 * np.pi))))
    return -surr.mean() + cfg.value_loss_coef * v_loss - cfg.entropy_coef * ent, v_loss


def test_loss_at_the_behaviour_policy(setup):
    params, norm = setup
    cfg = PPOConfig()
    batch = _batch(params, norm)
    loss, aux = ppo.ppo_loss(params, norm, batch, params["log_std"], cfg, NET, LAYOUT)
    assert float(aux["loss/kl"]) == pytest.approx(0.0, abs=1e-6)
    assert float(aux["loss/clip_fraction"]) == 0.0
    assert float(aux["loss/policy"]) == pytest.approx(0.0, abs=1e-6)  # ratio 1, normalised adv
    want, _ = _loss_by_hand(params, norm, batch, cfg)
    assert float(loss) == pytest.approx(want, rel=1e-5)


def test_loss_clipping_by_hand(setup):
    params, norm = setup
    cfg = PPOConfig(clip_eps=0.1, value_clip_eps=0.05, entropy_coef=0.01, value_loss_coef=0.5)
    batch = _batch(params, norm, value_shift=0.3)  # old values far from current: clip active
    moved = jax.tree_util.tree_map(lambda x: x * 1.0, params)
    moved["actor"][-1]["w"] = moved["actor"][-1]["w"] + 0.3  # policy moved: ratios clip
    moved["log_std"] = moved["log_std"] - 0.2
    loss, aux = ppo.ppo_loss(moved, norm, batch, params["log_std"], cfg, NET, LAYOUT)
    want, v_loss = _loss_by_hand(moved, norm, batch, cfg)
    assert float(aux["loss/clip_fraction"]) > 0.1
    assert float(aux["loss/kl"]) > 0.0
    assert float(aux["loss/value"]) == pytest.approx(v_loss, rel=1e-5)
    assert float(loss) == pytest.approx(want, rel=1e-5)
    unclipped = dataclasses.replace(cfg, value_clip_eps=0.0)
    _, aux2 = ppo.ppo_loss(moved, norm, batch, params["log_std"], unclipped, NET, LAYOUT)
    assert float(aux2["loss/value"]) < float(aux["loss/value"])


def test_update_runs_epochs_and_adapts_lr(setup):
    params, norm = setup
    cfg = PPOConfig(num_epochs=3, num_minibatches=4, learning_rate=1e-3)
    data = jax.tree_util.tree_map(lambda x: x.reshape(8, 8, *x.shape[1:]),
                                  _batch(params, norm, n=64))
    opt = optim.adam_init(params, cfg.learning_rate)
    update = jax.jit(ppo.update, static_argnums=(5, 6, 7))
    new_params, new_opt, metrics = update(params, opt, norm, data, jax.random.PRNGKey(1), cfg,
                                          NET, LAYOUT)
    assert int(new_opt.count) == 12  # epochs x minibatches Adam steps
    assert float(new_opt.lr) != pytest.approx(1e-3)  # the KL rule moved it
    assert 1e-5 <= float(new_opt.lr) <= 1e-2
    for a, b in zip(jax.tree_util.tree_leaves(new_params), jax.tree_util.tree_leaves(params),
                    strict=True):
        assert not np.array_equal(np.asarray(a), np.asarray(b))
    assert all(np.isfinite(float(v)) for v in metrics.values())
    fixed = dataclasses.replace(cfg, lr_schedule="fixed")
    _, opt2, _ = update(params, opt, norm, data, jax.random.PRNGKey(1), fixed, NET, LAYOUT)
    assert float(opt2.lr) == pytest.approx(1e-3)
    with pytest.raises(ValueError, match="does not split into 5 minibatches"):
        ppo.update(params, opt, norm, data, jax.random.PRNGKey(1),
                   dataclasses.replace(cfg, num_minibatches=5), NET, LAYOUT)


def test_max_std_bounds_the_std_after_each_step(setup):
    """ppo.max_std projects log_std after every Adam step: an entropy bonus that alone pushes
    the std up (zero advantages) moves it above the bound without it, not with it."""
    params, norm = setup
    params = dict(params, log_std=jnp.full_like(params["log_std"], np.log(0.99)))
    data = _batch(params, norm, n=64)
    data = jax.tree_util.tree_map(lambda x: x.reshape(8, 8, *x.shape[1:]),
                                  data._replace(advantage=jnp.zeros_like(data.advantage)))
    cfg = PPOConfig(num_epochs=2, num_minibatches=2, learning_rate=1e-2, lr_schedule="fixed",
                    entropy_coef=1.0)
    opt = optim.adam_init(params, cfg.learning_rate)
    free = ppo.update(params, opt, norm, data, jax.random.PRNGKey(1), cfg, NET, LAYOUT)[0]
    bound = ppo.update(params, opt, norm, data, jax.random.PRNGKey(1),
                       dataclasses.replace(cfg, max_std=1.0), NET, LAYOUT)[0]
    assert float(jnp.exp(free["log_std"]).min()) > 1.01
    np.testing.assert_allclose(np.exp(np.asarray(bound["log_std"])), 1.0, rtol=1e-6)


def test_network_conv_impl_reaches_the_encoder(setup):
    """net_cfg.conv_impl ('fused') is threaded through the PPO loss: the same loss and
    gradients as lax.conv, the fused encoder's written-out backward pass included."""
    params, norm = setup
    cfg = PPOConfig()
    batch = _batch(params, norm, value_shift=0.3)
    row = dataclasses.replace(NET, conv_impl="fused")
    grad = jax.jit(jax.grad(ppo.ppo_loss, has_aux=True), static_argnums=(4, 5, 6))
    ga, aux_a = grad(params, norm, batch, params["log_std"], cfg, NET, LAYOUT)
    gb, aux_b = grad(params, norm, batch, params["log_std"], cfg, row, LAYOUT)
    assert float(aux_b["loss/value"]) == pytest.approx(float(aux_a["loss/value"]), rel=1e-5)
    for a, b in zip(jax.tree_util.tree_leaves(ga), jax.tree_util.tree_leaves(gb), strict=True):
        np.testing.assert_allclose(b, a, rtol=1e-4, atol=1e-6)
    with pytest.raises(ValueError, match="network.conv_impl"):
        ppo.policy_mean(params, norm, batch.obs, dataclasses.replace(NET, conv_impl="x"), LAYOUT)


# The mirror of LAYOUT's observation (3 vector entries, the second flips sign; the 5 x 5 map's
# rows reversed) and of its 2 actions (swapped), as env.symmetry builds the Go2's.
TOY_MIRROR = symmetry.Mirror(
    obs=symmetry.Signed(np.concatenate([[0, 1, 2], 3 + np.arange(25).reshape(5, 5)[::-1].ravel()]),
                        np.array([1.0, -1.0, 1.0] + [1.0] * 25)),
    act=symmetry.Signed(np.array([1, 0]), np.ones(2)))


def _asymmetric(params):
    """The network with its actor's last layer drawn at full scale (init draws it near 0)."""
    params = jax.tree_util.tree_map(lambda x: x * 1.0, params)
    w = params["actor"][-1]["w"]
    params["actor"][-1]["w"] = 0.5 * jax.random.normal(jax.random.PRNGKey(7), w.shape)
    return params


def _mirror_loss_by_hand(params, norm, obs):
    mean = np.asarray(ppo.policy_mean(params, norm, obs, NET, LAYOUT))
    o = np.asarray(obs)[:, TOY_MIRROR.obs.index] * TOY_MIRROR.obs.sign
    mirrored = np.asarray(ppo.policy_mean(params, norm, jnp.asarray(o), NET, LAYOUT))
    return np.mean(np.sum((mirrored - mean[:, ::-1]) ** 2, axis=-1))


def test_mirror_loss_by_hand_and_off_by_default(setup):
    params, norm = _asymmetric(setup[0]), setup[1]
    batch = _batch(params, norm)
    base, aux0 = ppo.ppo_loss(params, norm, batch, params["log_std"], PPOConfig(), NET, LAYOUT)
    assert "loss/mirror" not in aux0
    cfg = PPOConfig(mirror_loss_coef=2.0)
    loss, aux = ppo.ppo_loss(params, norm, batch, params["log_std"], cfg, NET, LAYOUT, TOY_MIRROR)
    want = _mirror_loss_by_hand(params, norm, batch.obs)
    assert want > 1e-2  # a random network is not symmetric
    assert float(aux["loss/mirror"]) == pytest.approx(want, rel=1e-4)
    assert float(loss) == pytest.approx(float(base) + 2.0 * want, rel=1e-5)
    with pytest.raises(ValueError, match="left-right mirror"):
        ppo.ppo_loss(params, norm, batch, params["log_std"], cfg, NET, LAYOUT)


def test_the_mirror_loss_makes_the_policy_symmetric(setup):
    """Updates on zero advantages: with the mirror loss the policy's asymmetry falls to a small
    part of where it started; without it, it does not."""
    params, norm = _asymmetric(setup[0]), setup[1]
    data = _batch(params, norm, n=64)
    start = _mirror_loss_by_hand(params, norm, data.obs)
    data = jax.tree_util.tree_map(lambda x: x.reshape(8, 8, *x.shape[1:]),
                                  data._replace(advantage=jnp.zeros_like(data.advantage)))
    cfg = PPOConfig(num_epochs=8, num_minibatches=2, learning_rate=3e-3, lr_schedule="fixed",
                    entropy_coef=0.0, value_loss_coef=0.0)
    opt = optim.adam_init(params, cfg.learning_rate)
    update = jax.jit(functools.partial(ppo.update, mirror=TOY_MIRROR), static_argnums=(5, 6, 7))
    after = {}
    for coef in (0.0, 1.0):
        new = update(params, opt, norm, data, jax.random.PRNGKey(1),
                     dataclasses.replace(cfg, mirror_loss_coef=coef), NET, LAYOUT)[0]
        after[coef] = _mirror_loss_by_hand(new, norm, data.obs.reshape(64, -1))
    assert after[1.0] < 0.2 * start
    assert after[0.0] > 0.5 * start
