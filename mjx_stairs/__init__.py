"""mjx_stairs: a fully jitted JAX/MJX trainer that teaches a Unitree Go2 to climb stairs.

Layers, each importing only those before it:
  sim/    the Go2 on MJX: model, terrain heightfield, collision (no env, no learning)
  env/    the stair env: observation, rewards, endings, curriculum (imports sim)
  rl/     PPO, networks, the compiled trainer, checkpoints and policy files (no env, no sim)
  study/  experiments, evaluation, the paper's figures and tables, benchmarks
  tools/  play (video, MCAP), export (ONNX + sidecar), sim2sim (the ONNX policy in MuJoCo)
terrains/ (a sibling package) builds the staircases and imports nothing of mjx_stairs.
"""
