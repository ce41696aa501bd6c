"""Policy files: a file saved with options retired since (issue 20) still loads and acts."""

import jax
import numpy as np

from mjx_stairs.rl import checkpoint, networks, normalizer
from mjx_stairs.rl import policy as policy_lib
from mjx_stairs.rl.networks import NetworkConfig, ObsLayout
from mjx_stairs.rl.trainer import LearnerConfig

NET = NetworkConfig(conv_channels=(4, 4, 8), latent_size=16, actor_hidden=(32,),
                    critic_hidden=(32,))
LAYOUT = ObsLayout(5, (9, 9))


def _save(path, network_meta: dict):
    params = networks.init_params(jax.random.PRNGKey(0), NET, LAYOUT.n_vec, LAYOUT.map_shape, 3)
    norm = {k: normalizer.init_stats(LAYOUT.obs_size) for k in policy_lib.OBS_KEYS}
    policy_lib.save_policy(path, params, norm, 5, LearnerConfig(network=NET), LAYOUT)
    tree, meta = checkpoint.load(path)
    meta["network"].update(network_meta)
    checkpoint.save(path, {"params": params, "normalizer": norm}, meta)


def test_policy_with_retired_options_loads_as_float32_auto(tmp_path):
    _save(tmp_path / "now.npz", {})
    _save(tmp_path / "old.npz", {"conv_impl": "row", "init": "orthogonal"})
    now, old = (policy_lib.load_policy(tmp_path / f"{n}.npz") for n in ("now", "old"))
    assert old.network == now.network and old.network.conv_impl == "auto"
    assert old.metadata["network"]["conv_impl"] == "row"  # what it was trained with
    obs = jax.random.normal(jax.random.PRNGKey(1), (4, LAYOUT.obs_size))
    np.testing.assert_array_equal(policy_lib.policy_action(old, obs),
                                  policy_lib.policy_action(now, obs))
    assert policy_lib.policy_value(old, obs).shape == (4,)
    assert policy_lib.saved_config(old, "network")["conv_impl"] == "auto"
