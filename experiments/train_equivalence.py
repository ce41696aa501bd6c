"""Train, evaluate and act with this tree's code and with another git revision's, and compare.

    JAX_PLATFORMS=cpu python experiments/train_equivalence.py REV [--experiments stage1 stage2_u]

REV is checked out with ``git archive`` into a temporary directory; each tree then runs, in a
process of its own (its own ``PYTHONPATH``, its own experiments/*.toml), the same worker:

- a short training run of each experiment's CPU preset (4 iterations in 2 chunks of 2, stage 2
  starting from the published experiments/results/stage1/policy.npz): every logged metric but
  the timings, and the final params, Adam moments and normaliser;
- published policies (stage2_u, stage2_u_lean): loaded, their mean action and value on fixed
  random observations, and an evaluation of 8 robots per level on U-shaped test levels 3 and 4
  (4 s episodes, 5 cm terrain).

Prints per item whether both trees give the same numbers bit for bit; exits 1 if any differs.
The worker finds the modules under either layout (flat ``mjx_stairs.train`` or the subpackages
``mjx_stairs.rl`` / ``mjx_stairs.study``), so a revision on either side of the refactor of issue
20 compares with the other.
"""

from __future__ import annotations

import argparse
import importlib
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
POLICIES = ("stage2_u", "stage2_u_lean")


def rev_tree(rev: str) -> Path:
    """A temporary directory holding the files of git revision ``rev``."""
    out = Path(tempfile.mkdtemp(prefix="rev_"))
    archive = subprocess.run(["git", "archive", rev], cwd=ROOT, capture_output=True)
    if archive.returncode:
        raise SystemExit(f"git archive {rev}: {archive.stderr.decode().strip()}")
    subprocess.run(["tar", "-x", "-C", str(out)], input=archive.stdout, check=True)
    return out


def _module(*names: str):
    """The first of ``names`` that this tree has (new layout first, then the flat one)."""
    for name in names:
        try:
            return importlib.import_module(name)
        except ModuleNotFoundError as e:
            if e.name is None or not name.startswith(e.name):
                raise
    raise ModuleNotFoundError(names[-1])


def _flat(prefix: str, tree) -> dict[str, np.ndarray]:
    import jax

    leaves = jax.tree_util.tree_flatten_with_path(tree)[0]
    return {prefix + jax.tree_util.keystr(p): np.asarray(v) for p, v in leaves}


def _train(name: str, log_dir: str) -> dict[str, np.ndarray]:
    experiment = _module("mjx_stairs.study.experiment", "mjx_stairs.experiment")
    runner = _module("mjx_stairs.rl.runner", "mjx_stairs.train")
    overrides = [f"train.log_dir={log_dir}", "train.total_iterations=4",
                 "train.iterations_per_chunk=2", "train.tensorboard=false",
                 "train.progress=false", "train.console=false", "publish_dir="]
    if name != "stage1":
        overrides.append("init_from=experiments/results/stage1/policy.npz")
    config, _ = experiment.load(f"experiments/{name}.toml", overrides, cpu=True)
    records: list[dict] = []
    result = runner.run(config, experiment.make_env(config), on_chunk=records.append)
    out = {}
    for i, rec in enumerate(records):
        for k, v in rec.items():
            if not (k.startswith("perf/") or k == "wall_time"):
                out[f"{name}/chunk{i}/{k}"] = np.asarray(v)
    st = result.state
    out.update(_flat(f"{name}/params", st.params))
    out.update(_flat(f"{name}/opt_state", st.opt_state))
    out.update(_flat(f"{name}/normalizer", st.normalizer))
    return out


def _policies() -> dict[str, np.ndarray]:
    import jax

    policy_mod = _module("mjx_stairs.rl.policy", "mjx_stairs.policy", "mjx_stairs.train")
    evaluate = _module("mjx_stairs.study.evaluate", "mjx_stairs.evaluate")
    out = {}
    for name in POLICIES:
        policy = policy_mod.load_policy(f"experiments/results/{name}/policy.npz")
        obs = jax.random.normal(jax.random.PRNGKey(3), (64, policy.layout.obs_size))
        out[f"{name}/action"] = np.asarray(policy_mod.policy_action(policy, obs))
        out[f"{name}/value"] = np.asarray(policy_mod.policy_value(policy, obs))
        spec = evaluate.EvalSpec(levels=(2, 3), robots_per_level=8, episode_length_s=4.0,
                                 resolution=0.05)
        r = evaluate.success_by_level(policy, spec)
        out[f"{name}/eval_success"] = np.asarray(r["success"])
        out[f"{name}/eval_fell"] = np.asarray(r["fell"])
    return out


def worker(out_path: str, experiments: list[str]) -> None:
    out = {}
    with tempfile.TemporaryDirectory() as log_dir:
        for name in experiments:
            out.update(_train(name, log_dir))
    out.update(_policies())
    np.savez(out_path, **out)


def run_worker(script: str, tree: Path, out: Path, flags: list[str]) -> dict[str, np.ndarray]:
    """Run ``script --worker out *flags`` on the code and files of ``tree``; its arrays."""
    env = dict(os.environ, PYTHONPATH=str(tree), JAX_PLATFORMS="cpu")
    cmd = [sys.executable, str(Path(script).resolve()), "--worker", str(out), *flags]
    subprocess.run(cmd, cwd=tree, env=env, check=True)
    with np.load(out) as f:
        return dict(f)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("rev", nargs="?", help="git revision to compare with")
    ap.add_argument("--experiments", nargs="+", default=["stage1", "stage2_u"])
    ap.add_argument("--then", default=None,
                    help="the worker's .npz of REV from an earlier call (skips rerunning REV)")
    ap.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        worker(args.worker, args.experiments)
        return 0
    if not args.rev:
        ap.error("REV is required")
    tmp = Path(tempfile.mkdtemp())
    flags = ["--experiments", *args.experiments]
    now = run_worker(__file__, ROOT, tmp / "now.npz", flags)
    if args.then:
        with np.load(args.then) as f:
            then = dict(f)
    else:
        then = run_worker(__file__, rev_tree(args.rev), tmp / "then.npz", flags)
    print(f"this tree's numbers: {tmp / 'now.npz'}")
    same = set(now) == set(then)
    for k in sorted(set(now) - set(then)) + sorted(set(then) - set(now)):
        print(f"  {k}: only in {'this tree' if k in now else args.rev}")
    groups: dict[str, list[str]] = {}
    for k in sorted(set(now) & set(then)):
        groups.setdefault(k.split("/")[0] + "/" + k.split("/")[1].split("[")[0], []).append(k)
    for group, keys in groups.items():
        diff = max(float(np.max(np.abs(now[k].astype(np.float64) - then[k].astype(np.float64)),
                                initial=0.0)) for k in keys)
        equal = all(np.array_equal(now[k], then[k]) for k in keys)
        same &= equal
        print(f"  {group:32s} {len(keys):4d} arrays  {'identical' if equal else 'DIFFERENT'}"
              f"  max |diff| {diff:.3g}")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
