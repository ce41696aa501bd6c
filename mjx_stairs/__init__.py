"""mjx_stairs: a fully jitted JAX/MJX trainer that teaches a Unitree Go2 to climb stairs.

Layers, each importing only those before it:
  sim/    the Go2 on MJX: model, terrain heightfield, collision (no env, no learning)
  env/    the stair env: observation, rewards, endings, curriculum (imports sim)
  rl/     PPO, networks, the compiled trainer, checkpoints and policy files (no env, no sim)
  study/  experiments, evaluation, the paper's figures and tables, benchmarks
  tools/  play (video, MCAP), export (ONNX + sidecar), sim2sim (the ONNX policy in MuJoCo)
terrains/ (a sibling package) builds the staircases and imports nothing of mjx_stairs.
"""

import os as _os

# XLA's CPU backend (jaxlib 0.10.2) can deadlock when two batched LAPACK calls run at once: each
# Cholesky splits its batch over the intra-op thread pool (jax::ParallelBatchMap) and waits for
# the pieces, and on a 2-core machine the pool's threads are the two waiting calls (every thread
# asleep, no CPU used; gdb, 2026-11-26). MJX's step has two such calls when the joints' damping
# is integrated implicitly (robot.implicit_damping: a factor of M and one of M + h D), from 256
# robots up. XLA's concurrency-optimised scheduler is what runs them at once; without it they
# run in turn, at the same speed here (MJX step, 256 robots: 15.0 s both ways). The flag only
# touches programs compiled for the CPU; one already in XLA_FLAGS wins. Set before JAX's backend
# starts (it reads XLA_FLAGS once), so import mjx_stairs before the first computation.
_FLAG = "--xla_cpu_enable_concurrency_optimized_scheduler"
if _FLAG not in _os.environ.get("XLA_FLAGS", ""):
    _os.environ["XLA_FLAGS"] = f"{_os.environ.get('XLA_FLAGS', '')} {_FLAG}=false".strip()
