"""The evaluation physics pins the physics step and keeps the policy's control period."""

import dataclasses

import pytest

from mjx_stairs.config import ConfigError, to_dict
from mjx_stairs.env.config import EnvConfig, env_config_from
from mjx_stairs.study.evaluate import keep_control_period


def _trained(timestep: float, decimation: int) -> dict:
    cfg = EnvConfig()
    cfg = dataclasses.replace(cfg, decimation=decimation,
                              robot=dataclasses.replace(cfg.robot, timestep=timestep))
    return to_dict(cfg)


@pytest.mark.parametrize("timestep,decimation", [(0.01, 2), (0.005, 4), (0.0025, 8)])
def test_evaluation_physics_runs_5ms_steps_at_the_policys_control_rate(timestep, decimation):
    saved = _trained(timestep, decimation)
    trained = env_config_from(saved)
    overrides = ("robot.physics=evaluation",)
    cfg = keep_control_period(env_config_from(saved, overrides), trained, overrides)
    assert cfg.robot.timestep == 0.005
    assert cfg.decimation == 4  # 20 ms, the policy's period
    assert cfg.robot.solver_iterations == 8 and cfg.robot.sunk_exit == "nearest"


def test_an_explicit_decimation_is_kept_and_an_odd_period_is_refused():
    saved = _trained(0.01, 2)
    trained = env_config_from(saved)
    overrides = ("robot.physics=evaluation", "decimation=3")
    cfg = keep_control_period(env_config_from(saved, overrides), trained, overrides)
    assert cfg.decimation == 3
    odd = ("robot.physics=evaluation", "robot.timestep=0.003")
    with pytest.raises(ConfigError, match="control period"):
        keep_control_period(env_config_from(saved, odd), trained, odd)
