"""Step the env of this tree and the env of another git revision side by side and compare.

    JAX_PLATFORMS=cpu python experiments/env_equivalence.py REV [--steps 120] [--robots 16]
        [--family u_shaped] [--env goal_mode=waypoint ...]

Both envs are built on the same small atlas (the family's levels 1 and 7; pyramid by default),
reset the same robots and step them with the same random actions for ``--steps`` policy steps
(2 s episodes, so every robot ends an episode and is reset on the way); ``--env`` overrides the
env config (as eval's). Prints, for qpos, reward, done and the actor's and critic's observations,
whether the two trajectories are bit for bit the same and their largest difference; exits 1 if
any differs. Used for changes meant to leave the env's numbers alone (NOTES.md,
Change 10: the NaN guard; issue 20: the package's new layout). REV is checked out with
``git archive`` and stepped in a process of its own, so the two trees may lay the package out
differently.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
from train_equivalence import ROOT, _module, rev_tree, run_worker

import terrains


def trajectory(robots: int, steps: int, family: str = "pyramid",
               overrides: tuple[str, ...] = ()) -> dict[str, np.ndarray]:
    """This process's env (whichever layout its tree has) stepped with random actions."""
    import jax
    import jax.numpy as jnp

    module = _module("mjx_stairs.env.stair_env", "mjx_stairs.env")
    atlas = terrains.build_atlas([family], "train", levels=[0, 6], variants_per_family=1,
                                 resolution=0.05, tile_size=10.0, border=1.0)
    config = module.EnvConfig(episode_length_s=2.0)
    if overrides:
        from mjx_stairs.config import to_dict
        try:
            from mjx_stairs.env.config import env_config_from
        except ImportError:  # the flat layout before issue 20 (e.g. f894b78)
            from mjx_stairs.config import apply_overrides, from_dict

            def env_config_from(data, extra):
                return from_dict(module.EnvConfig, apply_overrides(data, extra))

        config = env_config_from(to_dict(config), overrides)
    env = module.StairEnv(atlas, config)
    reset, step = jax.jit(jax.vmap(env.reset_at)), jax.jit(jax.vmap(env.step))
    rows = jnp.asarray([0, 1] * (robots // 2) + [0] * (robots % 2), jnp.int32)
    state = reset(jax.random.split(jax.random.PRNGKey(0), robots), rows,
                  jnp.zeros(robots, jnp.int32))
    key, out = jax.random.PRNGKey(1), {"qpos": [], "reward": [], "done": [], "actor_obs": [],
                                       "critic_obs": []}
    for _ in range(steps):
        key, k = jax.random.split(key)
        state = step(state, jax.random.normal(k, (robots, env.action_size)))
        out["qpos"].append(np.asarray(state.pipeline_state.qpos))
        out["reward"].append(np.asarray(state.reward))
        out["done"].append(np.asarray(state.done))
        out["actor_obs"].append(np.asarray(state.obs["state"]))
        out["critic_obs"].append(np.asarray(state.obs["privileged_state"]))
    return {k: np.stack(v) for k, v in out.items()}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("rev", nargs="?", help="git revision whose env to compare with")
    ap.add_argument("--steps", type=int, default=120)
    ap.add_argument("--robots", type=int, default=16)
    ap.add_argument("--family", default="pyramid")
    ap.add_argument("--env", nargs="*", default=[], help="env overrides, KEY=VALUE")
    ap.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        np.savez(args.worker, **trajectory(args.robots, args.steps, args.family, tuple(args.env)))
        return 0
    if not args.rev:
        ap.error("REV is required")
    tmp = Path(tempfile.mkdtemp())
    flags = ["--steps", str(args.steps), "--robots", str(args.robots), "--family", args.family,
             *(["--env", *args.env] if args.env else [])]
    now = run_worker(__file__, ROOT, tmp / "now.npz", flags)
    then = run_worker(__file__, rev_tree(args.rev), tmp / "then.npz", flags)
    print(f"{args.robots} robots x {args.steps} steps, {int(now['done'].sum())} episode ends")
    same = True
    for k in now:
        equal = np.array_equal(now[k], then[k])
        same &= equal
        diff = np.abs(now[k] - then[k])
        print(f"  {k:10s} {'identical' if equal else 'DIFFERENT'}  max |diff| {diff.max():.3g}")
        if not equal and diff.ndim == 3:  # [step, robot, feature]: which features, how often
            cols = np.nonzero(diff.max((0, 1)) > 1e-6)[0]
            share = (diff > 1e-6).any(-1).mean()
            print(f"    features {cols[:12].tolist()}{' ...' if len(cols) > 12 else ''} "
                  f"({len(cols)} of {diff.shape[-1]}), in {100 * share:.1f} % of robot-steps")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
