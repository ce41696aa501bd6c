"""Learning: networks, PPO, the compiled trainer, its host runner, checkpoints, policy files.

Knows an env only through reset/step and observation shapes: imports neither sim nor env.
"""
