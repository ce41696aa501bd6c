"""The trainer end to end on the toy env: it learns, resumes bit for bit, stops on budgets,
writes its run directory, and two forced host devices match one."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import textwrap
import time
from dataclasses import replace
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjx_stairs.rl import checkpoint, checkpointer, ppo, runner
from mjx_stairs.rl import policy as policy_lib
from mjx_stairs.rl import rollout as rollout_lib
from mjx_stairs.rl import trainer as train_lib
from mjx_stairs.rl.networks import NetworkConfig, ObsLayout
from mjx_stairs.rl.ppo import PPOConfig
from mjx_stairs.rl.trainer import LearnerConfig, TrainConfig
from tests.mjx_stairs.rl.toy_env import PointReach

ROOT = Path(__file__).resolve().parents[3]

SMALL_NET = NetworkConfig(conv_channels=(4, 4, 8), latent_size=16, actor_hidden=(32, 32),
                          critic_hidden=(32, 32))


def _leaves_equal(a, b) -> bool:
    la, lb = jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)
    return len(la) == len(lb) and all(
        np.array_equal(np.asarray(x), np.asarray(y)) for x, y in zip(la, lb, strict=True))


# ----------------------------------------------------------------------------- learning


LEARN_CFG = LearnerConfig(
    train=TrainConfig(num_envs=128, unroll_length=16, iterations_per_chunk=10),
)
TOY = PointReach()  # one env object: the trainer (and its compiled chunk) is cached per env
RANDOM_POLICY_RETURN = 3.5  # PointReach, episode 40 steps: measured mean return with lr = 0
THRESHOLD = 28.0  # a policy that reaches and holds the goal scores ~32


@pytest.fixture(scope="module")
def learner():
    return train_lib.make_train(LEARN_CFG, TOY)


@pytest.mark.parametrize("seed", [0, 1])
def test_ppo_learns_the_toy_task(learner, seed):
    init, chunk = learner
    t0 = time.time()
    state = init(jax.random.PRNGKey(seed))
    returns = []
    for _ in range(6):  # 60 iterations, 123k env steps
        state, metrics = chunk(state)
        returns.append(float(metrics["episode/return"]))
        if returns[-1] > THRESHOLD:
            break
    assert returns[-1] > THRESHOLD, returns
    assert returns[-1] > 5 * RANDOM_POLICY_RETURN
    assert time.time() - t0 < 60.0
    assert float(metrics["success"]) > 0.3
    assert 1e-5 * (1 - 1e-6) <= float(metrics["opt/lr"]) <= 1e-2  # floor 1e-5 in float32


def test_layout_from_env():
    assert rollout_lib.obs_layout(PointReach()) == ObsLayout(5, ())
    assert rollout_lib.obs_layout(PointReach(map_shape=(5, 5))) == ObsLayout(5, (5, 5))


def test_bad_sizes_are_clear_errors():
    cfg = replace(LEARN_CFG, ppo=PPOConfig(num_minibatches=7))
    with pytest.raises(ValueError, match="does not split into ppo.num_minibatches=7"):
        train_lib.make_train(cfg, PointReach())
    for coef, message in ((1.0, "needs an env with a left-right mirror"), (-0.5, ">= 0")):
        cfg = replace(LEARN_CFG, ppo=PPOConfig(mirror_loss_coef=coef))
        with pytest.raises(ValueError, match=message):  # the toy env has no mirror
            train_lib.build_trainer(cfg, PointReach())


def test_rollout_values_are_the_critics_values():
    """The critic's values computed after the rollout scan (one batched pass) are V(obs_t),
    V(final obs_t) (the pre-reset obs where an episode ended) and V(obs_T)."""
    env = PointReach(map_shape=(5, 5), episode_length=5)  # timeouts inside an 8-step rollout
    cfg = LearnerConfig(network=SMALL_NET,
                        train=TrainConfig(num_envs=16, unroll_length=8, iterations_per_chunk=1))
    trainer = train_lib.build_trainer(cfg, env)
    state = trainer.init(jax.random.PRNGKey(5))
    fn = jax.jit(lambda s, k: rollout_lib.rollout(s, k, config=cfg, env=env,
                                                  layout=trainer.layout, mesh=trainer.mesh))
    (env_state, _, _), tr, metrics, ep_stats, boot = fn(state, jax.random.PRNGKey(6))
    assert tr.final_critic_obs is None
    assert float(np.sum(tr.truncation)) >= 16  # every robot timed out once
    critic = jax.jit(lambda o: ppo.critic_value(state.params, state.normalizer, o, cfg.network,
                                                trainer.layout))
    np.testing.assert_allclose(np.asarray(tr.value), np.asarray(critic(tr.critic_obs)),
                               rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(np.asarray(boot),
                               np.asarray(critic(env_state.obs["privileged_state"])),
                               rtol=1e-5, atol=1e-5)
    # the final-obs values are the next step's values, except where an episode ended
    ended = np.asarray(tr.done[:-1]) > 0
    gap = np.asarray(tr.final_value[:-1]) - np.asarray(tr.value[1:])
    assert np.abs(gap[ended]).max() > 1e-3
    np.testing.assert_allclose(gap[~ended], 0.0, atol=1e-5)
    # the per-step metrics (one stacked reduction) are the robots' means, the episode stats sums
    reward, done = np.asarray(tr.reward), np.asarray(tr.done)
    np.testing.assert_allclose(np.asarray(metrics["reward/total"]), reward.mean(axis=1),
                               rtol=1e-6)
    np.testing.assert_array_equal(np.asarray(ep_stats["count"]), done.sum(axis=1))
    assert float(np.sum(ep_stats["count"])) >= 16 and set(metrics) > {"reward/total"}


# ----------------------------------------------------------------------------- resume


MAP_CFG = LearnerConfig(
    network=SMALL_NET,
    train=TrainConfig(num_envs=16, unroll_length=8, iterations_per_chunk=2),
    ppo=PPOConfig(num_minibatches=4, num_epochs=2),
)


def test_chunk_save_load_chunk_is_bit_exact(tmp_path):
    env = PointReach(map_shape=(5, 5))
    trainer = train_lib.build_trainer(MAP_CFG, env)
    s1, _ = trainer.chunk(trainer.init(jax.random.PRNGKey(3)))
    path = tmp_path / "state.npz"
    checkpointer.save_state(path, s1, MAP_CFG, trainer.layout)
    s2, m2 = trainer.chunk(s1)  # s1 is donated here
    restored, meta = checkpointer.load_state(path, trainer)
    assert meta["iteration"] == 2 and meta["layout"]["map_shape"] == [5, 5]
    assert meta["config"]["train"]["num_envs"] == 16
    s2b, m2b = trainer.chunk(restored)
    assert int(s2.iteration) == int(s2b.iteration) == 4
    assert _leaves_equal(s2, s2b)  # params, Adam moments, lr, normaliser, env state, rng, ...
    assert _leaves_equal(m2, m2b)


def test_a_state_saved_before_a_metric_was_added_resumes_as_it_would_have(tmp_path):
    """A per-step metric added after a state was saved (e.g. env.endings.CORNERS) starts as
    zeros, which the first step rewrites: the resumed chunk equals the one from the full state.
    Any other entry missing stays a clear error."""
    env = PointReach(map_shape=(5, 5))
    trainer = train_lib.build_trainer(MAP_CFG, env)
    s1, _ = trainer.chunk(trainer.init(jax.random.PRNGKey(3)))
    old = {k: v for k, v in s1.env_state.metrics.items() if k != "success"}
    path = tmp_path / "state.npz"
    checkpointer.save_state(path, s1._replace(env_state=s1.env_state.replace(metrics=old)),
                            MAP_CFG, trainer.layout)
    no_rng = tmp_path / "no_rng.npz"
    checkpointer.save_state(no_rng, s1._replace(env_state=s1.env_state.replace(
        info={k: v for k, v in s1.env_state.info.items() if k != "rng"})), MAP_CFG,
        trainer.layout)
    restored, _ = checkpointer.load_state(path, trainer)
    assert np.all(np.asarray(restored.env_state.metrics["success"]) == 0.0)
    s2, m2 = trainer.chunk(s1)
    s2b, m2b = trainer.chunk(restored)
    assert _leaves_equal(s2, s2b) and _leaves_equal(m2, m2b)
    with pytest.raises(checkpoint.CheckpointError, match=r"missing 1 entries .*\['rng'\]"):
        checkpointer.load_state(no_rng, trainer)


def test_a_packed_state_resumes_with_inputs_appended(tmp_path):
    """A run resumed with more observation at the end of its vector part (env.obs_action_delay
    over a run without it; checkpointer.load_state's widen): zero weights and Adam moments for
    the new input, its normaliser entry from the env's resets (not a unit one, which the saved
    count would hold for long), every other leaf as saved: it acts as it did, and trains on."""
    cfg = replace(MAP_CFG, train=replace(MAP_CFG.train, checkpoint_env="packed"))
    narrow, wide = PointReach(map_shape=(5, 5)), PointReach(map_shape=(5, 5), told=1)
    t1 = train_lib.build_trainer(cfg, narrow)
    s1, _ = t1.chunk(t1.init(jax.random.PRNGKey(3)))
    path = tmp_path / "state.npz"
    checkpointer.save_state(path, s1, cfg, t1.layout, env=narrow)
    t2 = train_lib.build_trainer(cfg, wide)
    with pytest.raises(checkpoint.CheckpointError, match="does not match expected"):
        checkpointer.load_state(path, t2)  # not allowed to widen: a clear error
    s2, meta = checkpointer.load_state(path, t2, widen=lambda saved_env: True)
    assert int(s2.iteration) == int(s1.iteration) == 2 and meta["layout"]["n_vec"] == 5
    feat = SMALL_NET.latent_size + 5  # the new input's row in the first layers
    for tree1, tree2 in ((s1.params, s2.params), (s1.opt_state.mu, s2.opt_state.mu),
                         (s1.opt_state.nu, s2.opt_state.nu)):
        for name in ("actor", "critic"):
            w1, w2 = np.asarray(tree1[name][0]["w"]), np.asarray(tree2[name][0]["w"])
            assert w2.shape[0] == w1.shape[0] + 1 and np.all(w2[feat] == 0.0)
            np.testing.assert_array_equal(np.delete(w2, feat, 0), w1)
    assert np.abs(np.asarray(s1.opt_state.mu["actor"][0]["w"])).max() > 0  # real moments
    st1, st2 = s1.normalizer["state"], s2.normalizer["state"]
    seen = np.asarray(jax.vmap(wide.reset)(jax.random.split(jax.random.PRNGKey(0), 256)).obs[
        "state"])[:, 5]
    assert seen.std() > 0.05  # one value per episode, as the delay
    assert float(st2.mean[5]) == pytest.approx(seen.mean(), abs=1e-5)
    assert float(st2.m2[5] / st2.count) == pytest.approx(seen.var(), rel=1e-3)
    np.testing.assert_array_equal(np.delete(np.asarray(st2.mean), 5), np.asarray(st1.mean))
    rng = np.random.default_rng(0)
    obs1 = rng.normal(size=(4, 30)).astype(np.float32)
    obs2 = np.insert(obs1, 5, rng.uniform(0, 1, 4), axis=1)
    np.testing.assert_allclose(
        ppo.policy_mean(s2.params, s2.normalizer, jnp.asarray(obs2), SMALL_NET, t2.layout),
        ppo.policy_mean(s1.params, s1.normalizer, jnp.asarray(obs1), SMALL_NET, t1.layout),
        atol=1e-5)
    s3, m3 = t2.chunk(s2)
    assert int(s3.iteration) == 4 and np.isfinite(float(m3["loss/total"]))


RUN_CFG = LearnerConfig(
    train=TrainConfig(num_envs=16, unroll_length=8, iterations_per_chunk=2),
    ppo=PPOConfig(num_minibatches=4, num_epochs=2),
)  # the runner's tests: chunks of 2 iterations of 128 env steps (cheap to run)


def _run_cfg(tmp_path, **kw):
    """RUN_CFG's compiled shapes (one compile serves every runner test) with host options."""
    t = replace(RUN_CFG.train, total_iterations=4, log_dir=str(tmp_path / "runs"),
                experiment="toy", seed=7, progress=False, console=False, checkpoint_every=1,
                keep_checkpoints=2)
    return replace(RUN_CFG, train=replace(t, **kw))


def test_run_then_resume_equals_one_run(tmp_path):
    env = TOY
    full = runner.run(_run_cfg(tmp_path / "a"), env)
    assert full.stop_reason == "total_iterations" and int(full.state.iteration) == 4

    half = runner.run(_run_cfg(tmp_path / "b", total_iterations=2), env)
    assert int(half.state.iteration) == 2
    resumed = runner.run(_run_cfg(tmp_path / "b"), env, run_dir=half.run_dir, resume=True)
    assert resumed.run_dir == half.run_dir and int(resumed.state.iteration) == 4
    assert _leaves_equal(full.state, resumed.state)

    run_dir = resumed.run_dir
    assert re.fullmatch(r"toy__7__\d{8}-\d{6}", run_dir.name), run_dir.name
    lines = [json.loads(x) for x in (run_dir / "metrics.jsonl").read_text().splitlines()]
    assert [x["iteration"] for x in lines] == [2, 4]
    assert [x["env_steps"] for x in lines] == [256, 512]
    for key in ("wall_time", "perf/steps_per_s", "episode/return", "episode/length", "success",
                "level", "reward/dist", "loss/policy", "loss/value", "loss/kl", "opt/lr"):
        assert key in lines[-1], key
    assert list((run_dir / "tb").iterdir())
    ckpts = [p.name for p in checkpoint.list_checkpoints(run_dir / "checkpoints")]
    assert ckpts == ["state_00000002.npz", "state_00000004.npz"]
    assert json.loads((run_dir / "config.json").read_text())["train"]["seed"] == 7

    policy_file = run_dir / "policy.npz"
    assert policy_file.stat().st_size < 16 * 2**20
    policy = policy_lib.load_policy(policy_file)
    assert _leaves_equal(policy.params, resumed.state.params)
    assert policy.layout == ObsLayout(5, ()) and policy.action_size == 2
    obs = np.zeros((3, 5), np.float32)
    assert policy_lib.policy_action(policy, obs).shape == (3, 2)
    assert policy_lib.policy_value(policy, obs).shape == (3,)

    # resume from a state file carried elsewhere, into a fresh run directory
    ck = half.run_dir / "checkpoints" / "state_00000002.npz"
    moved = tmp_path / "carried.npz"
    moved.write_bytes(ck.read_bytes())
    other = runner.run(_run_cfg(tmp_path / "d"), env, run_dir=tmp_path / "d" / "r", resume=moved)
    assert _leaves_equal(full.state, other.state)
    assert (tmp_path / "d" / "r" / "checkpoints" / "state_00000004.npz").exists()
    # the fresh run directory gets the config, so the run can be published from it
    assert json.loads((tmp_path / "d" / "r" / "config.json").read_text())["train"]["seed"] == 7

    # resuming a finished run does nothing more; --resume without a run fails clearly
    again = runner.run(_run_cfg(tmp_path / "b"), env, resume=True)
    assert again.run_dir == run_dir and int(again.state.iteration) == 4
    with pytest.raises(FileNotFoundError, match="no run 'toy__7__"):
        runner.run(_run_cfg(tmp_path / "c"), env, resume=True)


def test_a_run_started_from_a_policy_keeps_or_resets_its_std(tmp_path):
    """init_from (trainer.start_from_policy) takes the published policy's params and normaliser;
    with init_from_std > 0 only its exploration std is replaced (a fine-tune that explores
    again), every other weight is the policy's."""
    first = runner.run(_run_cfg(tmp_path / "a", total_iterations=2), TOY)
    published = policy_lib.load_policy(first.run_dir / "policy.npz")
    trainer = train_lib.build_trainer(_run_cfg(tmp_path / "b"), TOY)
    fresh = trainer.init(jax.random.PRNGKey(3))
    kept = train_lib.start_from_policy(fresh, first.run_dir / "policy.npz", trainer)
    assert _leaves_equal(kept.params, published.params)
    assert _leaves_equal(kept.normalizer, published.normalizer)
    reset = train_lib.start_from_policy(fresh, first.run_dir / "policy.npz", trainer, std=0.3)
    np.testing.assert_allclose(np.exp(np.asarray(reset.params["log_std"])), 0.3, rtol=1e-6)
    assert not np.allclose(np.asarray(published.params["log_std"]), np.log(0.3))
    others = lambda p: {k: v for k, v in p.items() if k != "log_std"}  # noqa: E731
    assert _leaves_equal(others(reset.params), others(published.params))


def test_a_policy_started_with_an_input_appended_scales_it_as_the_env_gives_it(tmp_path):
    """init_from into an observation with a term appended (env.obs_action_delay over a policy
    without it): zero weights for the new input, and its normaliser entry the mean and variance
    of 256 fresh resets of the env, the others the published policy's."""
    first = runner.run(_run_cfg(tmp_path / "a", total_iterations=2), TOY)
    published = policy_lib.load_policy(first.run_dir / "policy.npz")
    wide = PointReach(told=1)
    trainer = train_lib.build_trainer(_run_cfg(tmp_path / "b"), wide)
    state = train_lib.start_from_policy(trainer.init(jax.random.PRNGKey(3)),
                                        first.run_dir / "policy.npz", trainer, delay=True)
    assert np.all(np.asarray(state.params["actor"][0]["w"])[5] == 0.0)
    seen = np.asarray(jax.vmap(wide.reset)(jax.random.split(jax.random.PRNGKey(0), 256)).obs[
        "privileged_state"])[:, 5]
    st, old = state.normalizer["privileged_state"], published.normalizer["privileged_state"]
    assert float(st.mean[5]) == pytest.approx(seen.mean(), abs=1e-5) and seen.std() > 0.05
    assert float(st.m2[5] / st.count) == pytest.approx(seen.var(), rel=1e-3)
    np.testing.assert_array_equal(np.delete(np.asarray(st.mean), 5), np.asarray(old.mean))


def test_resume_under_another_seed_draws_another_stream(tmp_path):
    """A state resumed under the seed it was saved with continues exactly (above); under another
    train.seed its key is folded with the new seed: the continuation differs, and is itself
    reproducible."""
    env = TOY
    half = runner.run(_run_cfg(tmp_path / "a", total_iterations=2), env)
    ck = half.run_dir / "checkpoints" / "state_00000002.npz"
    same = runner.run(_run_cfg(tmp_path / "b"), env, run_dir=tmp_path / "b" / "r", resume=ck)
    other = [runner.run(_run_cfg(tmp_path / f"c{i}", seed=8), env,
                        run_dir=tmp_path / f"c{i}" / "r", resume=ck) for i in range(2)]
    assert int(other[0].state.iteration) == 4
    assert not _leaves_equal(same.state.params, other[0].state.params)
    assert _leaves_equal(other[0].state, other[1].state)
    assert not _leaves_equal(same.state.rng, other[0].state.rng)


def test_packed_env_checkpoints_resume(tmp_path):
    env = TOY
    full = runner.run(_run_cfg(tmp_path / "a", checkpoint_env="packed"), env)
    half = runner.run(_run_cfg(tmp_path / "b", total_iterations=2, checkpoint_env="packed"), env)
    ck = checkpoint.latest_checkpoint(half.run_dir / "checkpoints")
    assert checkpoint.load_metadata(ck)["env_format"] == "packed"
    assert not any("final_obs" in k for k in checkpoint.load(ck)[0])
    resumed = runner.run(_run_cfg(tmp_path / "b", checkpoint_env="packed"), env,
                        run_dir=half.run_dir, resume=True)
    # the toy env recomputes the clean obs exactly, so here the resume is still bit-exact
    assert _leaves_equal(full.state.params, resumed.state.params)
    with pytest.raises(ValueError, match="needs env.pack_state"):
        checkpointer.save_state(tmp_path / "x.npz", resumed.state,
                         _run_cfg(tmp_path, checkpoint_env="packed"), ObsLayout(5), env=None)


def test_stops_on_env_steps_and_time_budget(tmp_path):
    env = TOY
    r = runner.run(_run_cfg(tmp_path, total_iterations=100, max_env_steps=300), env)
    # whole chunks of 256 steps: stops once 300 are reached
    assert r.stop_reason == "max_env_steps" and int(r.state.iteration) == 4
    assert checkpoint.latest_checkpoint(r.run_dir / "checkpoints").name == "state_00000004.npz"
    r = runner.run(_run_cfg(tmp_path, total_iterations=100, time_budget_s=0.5), env)
    assert r.stop_reason == "time_budget" and int(r.state.iteration) == 0
    stops = []
    r = runner.run(_run_cfg(tmp_path, total_iterations=100),
                  env, on_chunk=lambda rec: stops.append(rec["iteration"]) or len(stops) == 3)
    assert r.stop_reason == "on_chunk" and stops == [2, 4, 6]
    assert checkpoint.latest_checkpoint(r.run_dir / "checkpoints").name == "state_00000006.npz"


class BlowsUp(PointReach):
    """The toy task whose reward goes NaN from the third step of an episode, as a physics
    blow-up's rewards do."""

    def step(self, state, action):
        out = super().step(state, action)
        t = state.info["phys"]["t"]
        return out.replace(reward=jax.numpy.where(t >= 2, jax.numpy.nan, out.reward))


def test_a_non_finite_update_stops_the_run_and_saves_nothing_of_it(tmp_path):
    with pytest.raises(runner.TrainingDiverged,
                       match=r"training diverged \(loss/.* is nan.*\) in the chunk ending at "
                             r"iteration 2 .*the newest checkpoint is none"):
        runner.run(_run_cfg(tmp_path), BlowsUp())
    run_dir = next((tmp_path / "runs").iterdir())
    assert not list((run_dir / "checkpoints").glob("state_*.npz"))
    assert not (run_dir / "policy.npz").exists()
    rows = [json.loads(x) for x in (run_dir / "metrics.jsonl").read_text().splitlines()]
    assert [r["iteration"] for r in rows] == [2] and rows[0]["loss/total"] is None


# ----------------------------------------------------------------------------- devices


DEVICES_SCRIPT = textwrap.dedent("""
    import os, sys
    flags = os.environ.get("XLA_FLAGS", "")  # the session's (tests/conftest.py), plus 2 devices
    os.environ["XLA_FLAGS"] = flags + " --xla_force_host_platform_device_count=2"
    os.environ["JAX_PLATFORMS"] = "cpu"
    sys.path.insert(0, {root!r})
    import jax, numpy as np
    from mjx_stairs.rl import sharding
    from mjx_stairs.rl import trainer as train_lib
    from tests.mjx_stairs.rl.test_train import MAP_CFG
    from tests.mjx_stairs.rl.toy_env import PointReach
    assert len(jax.devices()) == 2, jax.devices()
    env = PointReach(map_shape=(5, 5))
    out = {{}}
    for n in (2, 1):
        t = train_lib.build_trainer(MAP_CFG, env, mesh=sharding.make_mesh(jax.devices()[:n]))
        s = t.init(jax.random.PRNGKey(0))
        shard_devs = {{len(x.sharding.device_set) for x in jax.tree_util.tree_leaves(s.env_state)}}
        assert shard_devs == {{n}}, shard_devs
        for _ in range(2):
            s, m = t.chunk(s)
        out[n] = (jax.device_get(s), {{k: float(v) for k, v in m.items()}})
    (s2, m2), (s1, m1) = out[2], out[1]
    pa, pb = jax.tree_util.tree_leaves(s2.params), jax.tree_util.tree_leaves(s1.params)
    worst = max(float(np.max(np.abs(a - b))) for a, b in zip(pa, pb))
    for a, b in zip(pa, pb):
        np.testing.assert_allclose(a, b, rtol=1e-3, atol=1e-4)
    np.testing.assert_allclose(s2.env_state.obs["state"], s1.env_state.obs["state"],
                               rtol=1e-3, atol=1e-4)
    for k in m1:
        np.testing.assert_allclose(m2[k], m1[k], rtol=1e-3, atol=1e-4, err_msg=k)
    print("OK max param diff", worst)
""")


def test_two_host_devices_match_one():
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.run([sys.executable, "-c", DEVICES_SCRIPT.format(root=str(ROOT))],
                          capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert "OK max param diff" in proc.stdout



def test_chunk_metrics_pool_an_envs_ratio_metrics():
    """`X#num` over `X#den` (env.endings.family_metrics' per-family level, top share and
    success) is logged as X, pooled over the chunk's iterations like success; nan where X#den is
    0; the raw parts are not logged."""
    per_iter = {"opt/lr": jnp.asarray([1e-3, 2e-3]), "_ep/count": jnp.asarray([1.0, 1.0]),
                "_ep/return_sum": jnp.asarray([2.0, 4.0]), "_ep/length_sum": jnp.ones(2),
                "episode/terminations": jnp.zeros(2), "episode/truncations": jnp.zeros(2),
                "level": jnp.asarray([3.0, 3.0]),
                "level/a#num": jnp.asarray([0.5, 1.5]), "level/a#den": jnp.asarray([0.25, 0.25]),
                "level/b#num": jnp.zeros(2), "level/b#den": jnp.zeros(2)}
    out = {k: float(v) for k, v in train_lib.reduce_chunk_metrics(per_iter).items()}
    assert out["level/a"] == pytest.approx(4.0) and np.isnan(out["level/b"])
    assert out["level"] == 3.0 and out["episode/return"] == 3.0
    assert not any("#" in k for k in out)


def test_a_resume_says_which_changed_keys_it_cannot_act_on(tmp_path, monkeypatch):
    """The resume warning lists every changed key, and one the env names in RESUME_INERT (drawn
    at a robot's first reset and kept in the state) with why it does nothing; the stair env's
    inert keys are keys of an experiment's config, so that its changes are the ones marked."""
    from mjx_stairs.env.stair_env import StairEnv
    from mjx_stairs.rl.policy import config_dict
    from mjx_stairs.study import experiment

    half = runner.run(_run_cfg(tmp_path / "a", total_iterations=2), TOY)
    ck = half.run_dir / "checkpoints" / "state_00000002.npz"
    monkeypatch.setattr(TOY, "RESUME_INERT", {"train.keep_checkpoints": "a toy reason"},
                        raising=False)
    with pytest.warns(UserWarning) as caught:
        runner.run(_run_cfg(tmp_path / "b", keep_checkpoints=3, checkpoint_every=2), TOY,
                   run_dir=tmp_path / "b" / "r", resume=ck)
    (said,) = [str(w.message) for w in caught if "changed config" in str(w.message)]
    assert "train.keep_checkpoints: 2 -> 3 (no effect on a resumed run: a toy reason)" in said
    assert "train.checkpoint_every: 1 -> 2" in said  # a change it acts on: no remark
    assert said.count("no effect") == 1

    config = experiment.load(ROOT / "experiments" / "generalist_from_stage1_mix_told_log.toml")[0]
    before = config_dict(config)
    after = config_dict(replace(config, env=replace(config.env, curriculum=replace(
        config.env.curriculum, family_weights=(0.2, 0.2, 0.2, 0.2, 0.2)))))
    diff = runner._config_diff(before, after, inert=StairEnv.RESUME_INERT)
    assert diff == ["env.curriculum.family_weights: [0.6, 0.1, 0.1, 0.1, 0.1] -> "
                    "[0.2, 0.2, 0.2, 0.2, 0.2] (no effect on a resumed run: each robot keeps the "
                    "family drawn at its first reset)"]
    for key in StairEnv.RESUME_INERT:
        section = before
        for part in key.split("."):
            section = section[part]  # a KeyError: a renamed key the warning would miss
