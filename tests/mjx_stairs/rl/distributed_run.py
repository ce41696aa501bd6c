"""One process of a small training run, for test_distributed (run as a script).

    python -m tests.mjx_stairs.rl.distributed_run OUT_DIR [STATE_FILE]

trains the toy task (16 robots with a 5 x 5 map, 2 iterations of one chunk each, a checkpoint
after each) into ``OUT_DIR/run``, then, given a STATE_FILE, resumes from it into
``OUT_DIR/resumed``. With MJX_STAIRS_COORDINATOR / _NUM_PROCESSES / _PROCESS_ID set it is one of
several processes (rl.distributed); XLA_FLAGS decides its devices. Each process writes
``OUT_DIR/process_<i>.json``: its view of the devices, every chunk's record, and whether the
robot's MJX model (sim.robot.build) lies on this process's devices.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from mjx_stairs.rl import distributed

STEADY = ("wall_time", "perf/")  # record keys that are timings, not results


def config(out: Path):
    from mjx_stairs.rl.networks import NetworkConfig
    from mjx_stairs.rl.ppo import PPOConfig
    from mjx_stairs.rl.trainer import LearnerConfig, TrainConfig

    net = NetworkConfig(conv_channels=(4, 4, 8), latent_size=16, actor_hidden=(32, 32),
                        critic_hidden=(32, 32))
    train = TrainConfig(num_envs=16, unroll_length=8, iterations_per_chunk=1, total_iterations=2,
                        experiment="mp", seed=3, log_dir=str(out / "runs"), checkpoint_every=1,
                        keep_checkpoints=0, tensorboard=False, progress=False, console=False)
    return LearnerConfig(network=net, train=train, ppo=PPOConfig(num_minibatches=4, num_epochs=2))


def main(out: Path, resume: str = "") -> None:
    distributed.initialize_from_env()  # before any JAX computation
    import jax
    import numpy as np

    from mjx_stairs.rl import runner
    from mjx_stairs.sim import robot
    from tests.mjx_stairs.rl.toy_env import PointReach

    cfg, env = config(out), PointReach(map_shape=(5, 5))
    records, resumed = [], []
    keep = lambda into: lambda r: into.append(
        {k: v for k, v in r.items() if not k.startswith(STEADY)})
    result = runner.run(cfg, env, run_dir=out / "run", on_chunk=keep(records))
    if resume:
        runner.run(cfg, env, run_dir=out / "resumed", resume=resume, on_chunk=keep(resumed))
    model = robot.build(np.zeros((5, 5), np.float32), 0.1).mjx_model
    arrays = [x for x in jax.tree_util.tree_leaves(model) if isinstance(x, jax.Array)]
    facts = {"robot_model_addressable": all(x.is_fully_addressable for x in arrays),
             "process_index": jax.process_index(), "process_count": jax.process_count(),
             "devices": len(jax.devices()), "local_devices": len(jax.local_devices()),
             "mesh_devices": int(result.state.params["log_std"].sharding.mesh.devices.size),
             "records": records, "resumed_records": resumed, "stop_reason": result.stop_reason}
    (out / f"process_{jax.process_index()}.json").write_text(json.dumps(facts))


if __name__ == "__main__":
    main(Path(sys.argv[1]), *sys.argv[2:])
