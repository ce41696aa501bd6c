"""Split one training iteration into its pieces, each timed alone as its own jitted program.

    python3 experiments/gpu/update_profile.py --config experiments/stage2_u_lean.toml \
        --out /tmp/out/update_profile.json [overrides...]

With the trainer's own functions and the config's sizes: the rollout (``rollout.rollout``), the
glue between rollout and update (GAE, the [T, B] -> [B, T] swap, the normaliser update), one
epoch's shuffle (permutation + gather of the whole batch), one minibatch step (loss, grads, Adam),
the whole PPO update (num_epochs x num_minibatches) and one whole training iteration. Median
milliseconds over ``--repeats`` calls after warm-up. Programs timed alone can differ from the
same work inside the trainer's chunk (fusion across the pieces, buffer reuse), so the sum is
checked against the whole iteration.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json

import jax
from encoder_bench import time_ms  # this folder, on sys.path when run as a script

from mjx_stairs import atomic
from mjx_stairs.rl import ppo, rollout
from mjx_stairs.rl import trainer as train
from mjx_stairs.study import experiment


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default="experiments/stage2_u_lean.toml")
    ap.add_argument("overrides", nargs="*")
    ap.add_argument("--repeats", type=int, default=10)
    ap.add_argument("--out", required=True)
    args = ap.parse_args()

    config, _ = experiment.load(args.config, args.overrides, cpu=False)
    env = experiment.make_env(config)
    trainer = train.build_trainer(config, env)
    layout, mesh = trainer.layout, trainer.mesh
    pc, nc = config.ppo, config.network
    state = trainer.init(jax.random.PRNGKey(0))
    kw = dict(config=config, env=env, layout=layout, mesh=mesh)
    out: dict = {"device": jax.devices()[0].device_kind, "jax": jax.__version__,
                 "config": args.config, "overrides": args.overrides,
                 "robots": config.train.num_envs, "unroll_length": config.train.unroll_length,
                 "ppo": {"num_epochs": pc.num_epochs, "num_minibatches": pc.num_minibatches},
                 "ms": {}}
    ms = out["ms"]

    roll = jax.jit(lambda s, k: rollout.rollout(s, k, **kw))
    ms["rollout"] = time_ms(roll, (state, jax.random.PRNGKey(1)), args.repeats)
    _, tr, _, _, bootstrap = roll(state, jax.random.PRNGKey(1))

    def glue(tr, bootstrap, norm):
        return train.rollout_batch(tr, bootstrap, pc, mesh)[0], train.updated_normalizer(
            norm, tr, nc)

    glue_j = jax.jit(glue)
    ms["glue_gae_swap_normaliser"] = time_ms(glue_j, (tr, bootstrap, state.normalizer),
                                             args.repeats)
    batch, _ = glue_j(tr, bootstrap, state.normalizer)
    n = batch.advantage.shape[0] * batch.advantage.shape[1]
    flat = jax.tree_util.tree_map(lambda x: x.reshape(n, *x.shape[2:]), batch)
    shuffle = jax.jit(functools.partial(ppo.shuffle_minibatches, m=pc.num_minibatches))
    ms["shuffle_one_epoch"] = time_ms(shuffle, (flat, jax.random.PRNGKey(2)), args.repeats)
    mb = jax.tree_util.tree_map(lambda x: x[: n // pc.num_minibatches], flat)
    step = jax.jit(functools.partial(
        ppo.minibatch_step, norm=state.normalizer, old_log_std=state.params["log_std"], cfg=pc,
        net_cfg=nc, layout=layout))
    ms["minibatch_step"] = time_ms(lambda c, b: step(c, b)[0], ((state.params, state.opt_state),
                                                                 mb), args.repeats)

    def update(params, opt_state, norm, batch, key, cfg):
        return ppo.update(params, opt_state, norm, batch, key, cfg, nc, layout)[:2]

    for name, cfg in (("update", pc),
                      ("update_1_epoch_1_minibatch",
                       dataclasses.replace(pc, num_epochs=1, num_minibatches=1))):
        fn = jax.jit(functools.partial(update, cfg=cfg))
        ms[name] = time_ms(fn, (state.params, state.opt_state, state.normalizer, batch,
                                 jax.random.PRNGKey(3)), args.repeats)

    it = jax.jit(lambda s: train.training_iteration(s, None, **kw)[0])
    ms["training_iteration"] = time_ms(it, (state,), args.repeats)
    ms["sum_of_pieces"] = ms["rollout"] + ms["glue_gae_swap_normaliser"] + ms["update"]
    print(json.dumps(out, indent=1), flush=True)
    atomic.write_text(args.out, json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
