"""experiments/generalist.toml (issue 24): it loads, its atlas holds every family walked up and
down on shared levels, bad values fail at load naming the key, and it trains (a few iterations
of a few robots on the CPU) into a policy whose sidecar says what it was trained to withstand."""

import dataclasses
import json
import math

import jax
import numpy as np
import pytest

import terrains
from mjx_stairs import cli
from mjx_stairs.config import ConfigError
from mjx_stairs.env import curriculum as cur
from mjx_stairs.rl.policy import load_policy
from mjx_stairs.study import experiment
from mjx_stairs.tools.sidecar import sidecar

TOML = "experiments/generalist.toml"
FAMILIES = ("building", "straight", "l_shaped", "u_shaped", "spiral")


def test_the_gpu_config_is_the_generalist():
    config, cpu = experiment.load(TOML, cpu=False)
    assert not cpu and config.terrain.families == FAMILIES
    assert config.terrain.directions == ("up", "down")
    assert config.terrain.variants == {"building": 22} and config.terrain.resolution == 0.025
    assert config.init_from == "experiments/results/stage1/policy.npz"
    env = config.env
    assert (env.robot.terrain_contacts, env.robot.solver_iterations) == ("columns", 8)
    assert env.goal_mode == "waypoint" and env.rewards.stall < 0  # stage 2's recipe
    assert env.randomization.joint_damping == (0.1, 2.0)
    assert env.randomization.action_delay_s == (0.0, 0.02)
    assert env.route.perturb_prob > 0 and env.noise.height_missing_edge > 0
    assert len(env.curriculum.family_weights) == len(FAMILIES)


def _flat(config) -> dict:
    """A config as {dotted key: value}, as experiment files and overrides name them."""
    return dict(experiment._flatten(dataclasses.asdict(config)))


def test_the_tall_start_and_today_s_control_differ_from_the_generalist_in_their_start_alone():
    base = _flat(experiment.load(TOML, cpu=False)[0])
    own = {"publish_dir", "train.experiment"}
    for name, init in (("generalist_tall", "experiments/results/stage1_tall/policy.npz"),
                       ("generalist_from_stage1", "experiments/results/stage1/policy.npz")):
        other = _flat(experiment.load(f"experiments/{name}.toml", cpu=False)[0])
        changed = {k for k in base if base[k] != other[k]}
        assert changed <= own | {"init_from"}, (name, changed)
        assert other["init_from"] == init and other["train.experiment"] == name
    stage1 = _flat(experiment.load("experiments/stage1.toml", cpu=False)[0])
    tall = experiment.load("experiments/stage1_tall.toml", cpu=False)[0]
    assert tall.terrain.families == ("pyramid_tall",)
    assert tall.init_from == "experiments/results/stage1/policy.npz"
    assert (tall.env.robot.terrain_contacts, tall.env.robot.contact_timeconst) == ("columns", 0.01)
    changed = {k for k, v in _flat(tall).items() if stage1[k] != v}
    assert {k for k in changed if not k.startswith("env.robot.")} <= own | {
        "init_from", "terrain.families", "train.total_iterations"}   # and the physics preset


@pytest.fixture(scope="module")
def atlas():
    config, cpu = experiment.load(TOML, cpu=True)
    assert cpu and config.terrain.resolution == 0.05
    return experiment.build_atlas(config.terrain)


def test_every_family_is_walked_up_and_down_on_every_level(atlas):
    assert atlas.families == FAMILIES and atlas.rows == 10
    table = cur.TileTable(atlas.family, atlas.cols, len(FAMILIES))
    building = [c for c in range(atlas.cols) if atlas.family[c] == 0]
    assert {int(atlas.variant[c]) for c in building} == set(range(11))  # every shape and turn
    pick = jax.jit(jax.vmap(cur.pick_tile, in_axes=(None, None, None, 0)), static_argnums=2)
    for family in range(len(FAMILIES)):
        for level in (0, 9):
            tiles = np.asarray(pick(level, family, table,
                                    jax.random.split(jax.random.PRNGKey(level), 200)))
            assert set(atlas.level[tiles]) == {level} and set(atlas.family[tiles]) == {family}
            ups = np.mean(atlas.direction[tiles] == 0)
            assert 0.3 < ups < 0.7, (family, level)  # one level, both directions


def test_the_building_levels_climb_the_risers(atlas):
    top_riser = [atlas.goal_height[r * atlas.cols] for r in range(atlas.rows)]
    assert top_riser[-1] > top_riser[0]
    down = atlas.direction == 1  # walked down: the goal on the floor, the spawn on top
    assert np.all(atlas.goal_height[down] < atlas.floor_height[down])


def test_family_weights_pick_families_at_their_rates():
    keys = jax.random.split(jax.random.PRNGKey(0), 2000)
    weighted = cur.CurriculumConfig(family_weights=(0.6, 0.1, 0.1, 0.1, 0.1))
    got = np.asarray(jax.vmap(lambda k: cur.pick_family(k, 5, weighted))(keys))
    assert 0.55 < np.mean(got == 0) < 0.65 and set(got) == set(range(5))
    uniform = jax.vmap(lambda k: cur.pick_family(k, 5, cur.CurriculumConfig()))(keys)
    same = jax.vmap(lambda k: jax.random.randint(k, (), 0, 5))(keys)  # as before issue 24
    np.testing.assert_array_equal(np.asarray(uniform), np.asarray(same))
    with pytest.raises(ConfigError, match="env.curriculum.family_weights"):
        cur.pick_family(keys[0], 4, weighted)


@pytest.mark.parametrize("override, key", [
    ("terrain.directions=['up', 'up']", "terrain.directions"),
    ("terrain.directions=['sideways']", "terrain.directions[0]"),
    ("terrain.variants={zigzag = 2}", "terrain.variants"),
    ("env.curriculum.family_weights=[1.0, 2.0]", "env.curriculum.family_weights"),
    ("env.curriculum.family_weights=[-1.0, 1, 1, 1, 1]", "env.curriculum.family_weights"),
    ("env.randomization.joint_damping=[2.0, 0.1]", "env.randomization.joint_damping"),
    ("env.randomization.action_delay_s=[0.0, 0.03]", "env.randomization.action_delay_s"),
    ("env.noise.height_missing_body=1.5", "env.noise.height_missing_body"),
    ("env.noise.height_offset=-0.1", "env.noise.height_offset"),
    ("env.route.lateral=0.8", "env.route.lateral"),
    ("env.route.coarse_points=[1, 4]", "env.route.coarse_points"),
    ("env.goal_mode=final", "env.route.perturb_prob"),
    ("env.robot.joint_damping=-2.0", "env.robot.joint_damping"),
    ("terrain.building_landing=[0.9]", "terrain.building_landing"),
    ("terrain.building_landing=[1.5, 1.0]", "terrain.building_landing"),
    ("terrain.building_landing=[-0.9, 1.8]", "terrain.building_landing"),
    ("init_from_std=-0.5", "init_from_std"),
])
def test_bad_values_fail_at_load_naming_the_key(override, key):
    with pytest.raises(ConfigError) as e:
        experiment.load(TOML, [override], cpu=True)
    assert f"'{key}'" in str(e.value) and len(str(e.value).splitlines()) == 1


def test_building_landing_reaches_the_building_tiles_only():
    """terrain.building_landing (docs/diagnosis_code_suite.md change 3): off in the file; on,
    the building columns are those of terrains.build_atlas(building_landing=), the paper
    family's are unchanged."""
    assert experiment.load(TOML, cpu=True)[0].terrain.building_landing == ()
    config, _ = experiment.load(TOML, ["terrain.building_landing=[0.9, 0.9]"], cpu=True)
    assert config.terrain.building_landing == (0.9, 0.9)
    small = experiment.TerrainConfig(families=("building", "u_shaped"), levels=(4,),
                                     variants_per_family=1, variants={"building": 11},
                                     resolution=0.1)
    base = experiment.build_atlas(small)
    tight = experiment.build_atlas(dataclasses.replace(small, building_landing=(0.9, 0.9)))
    want = terrains.build_atlas(["building"], levels=[4], variants_per_family=11,
                                resolution=0.1, building_landing=(0.9, 0.9))
    for t in range(tight.cols):
        if tight.family[t] == 0:
            np.testing.assert_array_equal(tight.tile_heights(t), want.tile_heights(t))
        else:
            np.testing.assert_array_equal(tight.tile_heights(t), base.tile_heights(t))
    assert not np.array_equal(tight.heights, base.heights)


def test_a_bad_value_is_one_line_from_the_cli(capsys):
    assert cli.main(["train", TOML, "env.randomization.action_delay_s=[0.0, 0.05]"]) == 2
    err = capsys.readouterr().err.strip()
    assert "env.randomization.action_delay_s" in err and len(err.splitlines()) == 1


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    root = tmp_path_factory.mktemp("generalist")
    code = cli.main(["train", TOML, "init_from=experiments/results/stage1/policy.npz",
                     "train.num_envs=8", "train.unroll_length=8", "train.total_iterations=2",
                     "train.iterations_per_chunk=1", "ppo.num_epochs=1",
                     f"train.log_dir={root / 'runs'}",
                     f"publish_dir={root / 'out'}", "train.progress=false",
                     "train.console=false", "train.tensorboard=false", "terrain.levels=[0, 9]",
                     "terrain.variants.building=11", "env.episode_length_s=1.0"])
    assert code == 0
    return root / "out"


def test_the_generalist_trains_a_few_iterations(trained):
    rows = [json.loads(x) for x in (trained / "metrics.jsonl").read_text().splitlines()]
    assert [r["iteration"] for r in rows] == [1, 2] and rows[-1]["env_steps"] == 2 * 8 * 8
    for key in ("episode/return", "loss/value", "level", "reward/centreline", "success_down"):
        assert math.isfinite(rows[-1][key]), key
    # the level per family (env.endings.FAMILY_RATIOS): a robot-step mean in [0, 9] where the
    # family had robots, null where it had none; the num / den parts are not logged
    families = ("building", "straight", "l_shaped", "u_shaped", "spiral")
    levels = [rows[-1][f"level/{f}"] for f in families]
    assert any(v is not None for v in levels)
    assert all(v is None or 0 <= v <= 9 for v in levels), levels
    assert all(f"{r}/{f}" in rows[-1] for r in ("at_top", "success") for f in families)
    assert not any("#" in k for k in rows[-1])
    saved = load_policy(trained / "policy.npz").metadata["config"]
    assert saved["terrain"]["directions"] == ["up", "down"]
    assert saved["env"]["randomization"]["joint_damping"] == [0.1, 2.0]


def test_the_sidecar_says_what_the_policy_withstands(trained):
    side = sidecar(load_policy(trained / "policy.npz"))
    t = side["training"]
    assert t["joint_damping_nms_rad"] == [0.1, 2.0] and t["action_delay_s"] == [0.0, 0.02]
    assert t["joint_damping_draw"] == "uniform"
    assert t["joint_damping_integration"] == "implicit" and t["head_collision"]
    assert t["pushes"]["on_stairs_only"] and t["route"]["lateral_fraction_of_width"] == 0.33
    assert t["height_map"]["missing_under_body"] == 0.3
    assert side["height_map"]["missing_value_m"] == side["height_map"]["clip_m"] == 3.0
    n = side["observation"]["size"]
    assert n == 490  # the observation layout is the stage-2 policy's: nothing to change on a robot
