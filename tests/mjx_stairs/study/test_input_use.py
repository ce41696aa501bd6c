"""input_use: how much a policy reads each observation term, on a published policy widened for
the action delay (zero weights on the new input, then a weight put there)."""

import copy

import numpy as np
import pytest

from mjx_stairs.rl.policy import load_policy, widen_for_history
from mjx_stairs.study import input_use


@pytest.fixture(scope="module")
def told():
    """stage2_u_robot widened with the delay input, its saved config saying so."""
    policy = load_policy("experiments/results/stage2_u_robot/policy.npz")
    meta = copy.deepcopy(policy.metadata)
    meta["config"]["env"]["obs_action_delay"] = True
    return widen_for_history(policy, 1)._replace(metadata=meta)


def test_an_input_with_zero_weights_is_not_read_and_one_with_weights_is(told):
    use = input_use.input_use(told, samples=64)
    assert list(use)[-2:] == ["action_delay", "height_map"]
    assert use["action_delay"]["row_norm"] == 0.0
    assert use["action_delay"]["d_action_1std"] < 1e-6
    assert use["action_delay"]["d_action_0_to_20ms"] < 1e-6
    assert min(u["d_action_1std"] for n, u in use.items() if n != "action_delay") > 0.01

    params = copy.deepcopy(told.params)
    w = np.array(params["actor"][0]["w"])
    w[-1] = w[-2]  # the delay read as the term before it is
    params["actor"][0]["w"] = w
    read = input_use.input_use(told._replace(params=params), samples=64)["action_delay"]
    assert read["row_norm"] == pytest.approx(np.linalg.norm(w[-2]), rel=1e-6)
    assert read["d_action_0_to_20ms"] > 0.01


def test_a_policy_whose_saved_config_disagrees_with_its_layout_is_refused(told):
    meta = copy.deepcopy(told.metadata)
    meta["config"]["env"]["obs_action_delay"] = False
    with pytest.raises(ValueError, match="vector inputs"):
        input_use.term_slices(told._replace(metadata=meta))


def test_the_critic_columns_read_the_critic_alone(told):
    """The widened delay row is zero in both heads; a weight put in the critic's row moves the
    value and leaves the actor's columns as they were."""
    use = input_use.input_use(told, samples=64)
    assert use["action_delay"]["critic_row_norm"] == 0.0
    assert use["action_delay"]["d_value_1std"] < 1e-6
    assert min(u["d_value_1std"] for n, u in use.items() if n != "action_delay") > 1e-4

    params = copy.deepcopy(told.params)
    w = np.array(params["critic"][0]["w"])
    w[-1] = w[-2]
    params["critic"][0]["w"] = w
    read = input_use.input_use(told._replace(params=params), samples=64)
    assert read["action_delay"]["critic_row_norm"] == pytest.approx(np.linalg.norm(w[-2]),
                                                                    rel=1e-6)
    assert read["action_delay"]["d_value_1std"] > 1e-4
    assert read["action_delay"]["d_action_1std"] == use["action_delay"]["d_action_1std"]
    assert "critic's first-layer row norm" in input_use.markdown(read).splitlines()[0]
