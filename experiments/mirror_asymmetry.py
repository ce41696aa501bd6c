"""How lopsided a policy is: along its own rollouts, its mean action on the mirrored observation
against its mirrored mean action (env.symmetry; ppo.mirror_loss, the quantity PPO's
`ppo.mirror_loss_coef` weighs), on a straight flight made exactly its own mirror image about its
centre-line (MJX on the CPU, the policy's evaluation env: its trained env config in the
evaluation physics and settings, study.evaluate.eval_env). A left-right symmetric policy scores 0.

    PYTHONPATH=. JAX_PLATFORMS=cpu python experiments/mirror_asymmetry.py \
        experiments/results/generalist_from_stage1_more/policy.npz --levels 2 6 --out asym.json
"""

from __future__ import annotations

import argparse
import dataclasses
import json

import jax
import jax.numpy as jnp
import numpy as np

import terrains
from mjx_stairs.atomic import write_text
from mjx_stairs.rl import ppo
from mjx_stairs.rl.policy import load_policy, policy_action
from mjx_stairs.study import evaluate
from mjx_stairs.study.specs import EvalSpec


def mirrored_straight_atlas(level: int):
    """A straight test-level flight (1-based `level`) whose heights are made symmetric about the
    grid's middle row, its centre-line (the atlas puts a wall's edge on one side's node only)."""
    atlas = terrains.build_cell_atlas([("straight", "test", level - 1)], 1, resolution=0.05,
                                      tile_size=10.0, border=1.0)
    h = np.asarray(atlas.heights)
    return dataclasses.replace(atlas, heights=np.maximum(h, h[::-1]))


def asymmetry(path: str, level: int, robots: int, steps: int, seed: int) -> dict:
    policy = load_policy(path)
    env = evaluate.eval_env(policy, mirrored_straight_atlas(level), EvalSpec())
    act = jax.jit(lambda o: policy_action(policy, o))
    loss = jax.jit(lambda o, a: ppo.mirror_loss(policy.params, policy.normalizer,
                                                o.astype(jnp.float32), a, policy.network,
                                                policy.layout, env.mirror))
    state = jax.jit(jax.vmap(env.reset_at))(jax.random.split(jax.random.PRNGKey(seed), robots),
                                            jnp.zeros(robots, jnp.int32),
                                            jnp.zeros(robots, jnp.int32))
    step = jax.jit(jax.vmap(env.step))
    gap, size = [], []  # per step, means over the robots (kept on the device until the end)
    for _ in range(steps):
        obs = state.obs["privileged_state"]
        a = act(obs)
        gap.append(loss(obs, a))
        size.append(jnp.mean(jnp.sum(a ** 2, -1)))
        state = step(state, a)
    return {"policy": path, "level": level, "robots": robots, "steps": steps,
            "mirror_loss": round(float(np.mean(jax.device_get(gap))), 3),
            "mean_squared_action": round(float(np.mean(jax.device_get(size))), 3)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("policies", nargs="+", help="policy.npz files")
    ap.add_argument("--levels", type=int, nargs="+", default=[2, 6], help="straight test levels")
    ap.add_argument("--robots", type=int, default=16)
    ap.add_argument("--steps", type=int, default=100, help="policy steps of each rollout")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=None, help="JSON file of the rows")
    args = ap.parse_args()
    rows = []
    for path in args.policies:
        for level in args.levels:
            rows.append(asymmetry(path, level, args.robots, args.steps, args.seed))
            print(json.dumps(rows[-1]), flush=True)
    if args.out:
        write_text(args.out, json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
