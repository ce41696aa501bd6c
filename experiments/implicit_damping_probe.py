"""Why implicit joint damping needs several Newton iterations (sim.robot.IMPLICIT_MIN_ITERATIONS).

    JAX_PLATFORMS=cpu python experiments/implicit_damping_probe.py OUT.json [--robots 32]

The generalist's env (experiments/generalist.toml's CPU preset: its atlas at 5 cm, implicit
damping, the head) stepped from reset with random actions (0.5 x a unit normal, 150 policy
steps) in several physics settings; for each, the largest |qvel| any robot reached and the NaN
resets. MJX's Euler step with implicit damping takes the acceleration from
(M + h D) qacc = qfrc_smooth + qfrc_constraint, not from the solver's own qacc, so an unconverged
constraint force goes straight into the step. The env refuses implicit damping below
IMPLICIT_MIN_ITERATIONS; this probe builds those settings on purpose, past that check (each is
first validated with 8 iterations, then the frozen field is set), to show what the rule prevents.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mjx_stairs import atomic  # noqa: E402
from mjx_stairs.env.stair_env import StairEnv  # noqa: E402
from mjx_stairs.study import experiment  # noqa: E402

# (name, overrides, Newton iterations): lean = the lean preset; evaluation = 8 iterations
SETTINGS = [
    ("lean, implicit, 1 iteration", ["env.robot.physics=lean"], 1),
    ("lean, implicit, 2 iterations", ["env.robot.physics=lean"], 2),
    ("lean, implicit, 3 iterations", ["env.robot.physics=lean"], 3),
    ("lean, implicit, 4 iterations (lean_implicit)", ["env.robot.physics=lean_implicit"], 4),
    ("lean, explicit, 1 iteration", ["env.robot.physics=lean",
                                     "env.robot.implicit_damping=false"], 1),
    ("reference, implicit, 1 iteration", ["env.robot.physics=reference"], 1),
    ("evaluation, implicit, 8 iterations", ["env.robot.physics=evaluation"], 8),
]


def probe(overrides: list[str], iterations: int, robots: int, steps: int) -> dict:
    valid = overrides + ["env.robot.solver_iterations=8"]
    cfg, _ = experiment.load("experiments/generalist.toml", valid, cpu=True)
    object.__setattr__(cfg.env.robot, "solver_iterations", iterations)  # past the env's check
    env = StairEnv(experiment.build_atlas(cfg.terrain), cfg.env)
    state = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(0), robots))
    step = jax.jit(jax.vmap(env.step))
    key, nan_resets, qvel_max, t0 = jax.random.PRNGKey(1), 0.0, 0.0, time.time()
    for _ in range(steps):  # the sums stay on the device: one host read at the end
        key, k = jax.random.split(key)
        state = step(state, 0.5 * jax.random.normal(k, (robots, env.action_size)))
        nan_resets = nan_resets + jnp.sum(state.metrics["nan_reset"])
        qvel_max = jnp.maximum(qvel_max, jnp.nanmax(jnp.abs(state.pipeline_state.qvel)))
    return {"overrides": overrides, "solver_iterations": iterations,
            "max_abs_qvel": float(qvel_max), "nan_resets": float(nan_resets), "robots": robots,
            "policy_steps": steps,
            "seconds": round(time.time() - t0, 1)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--robots", type=int, default=32)
    ap.add_argument("--steps", type=int, default=150)
    args = ap.parse_args()
    rows = {}
    for name, overrides, iterations in SETTINGS:
        rows[name] = probe(overrides, iterations, args.robots, args.steps)
        print(f"{name:48s} max |qvel| {rows[name]['max_abs_qvel']:10.1f}  NaN resets "
              f"{rows[name]['nan_resets']:.0f}", flush=True)
    atomic.write_text(args.out, json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
