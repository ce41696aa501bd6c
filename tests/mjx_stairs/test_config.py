"""Config loader: TOML + overrides, type checks, clear errors, JSON round trip."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import pytest

from mjx_stairs.config import (
    ConfigError,
    apply_overrides,
    from_dict,
    from_json,
    load_config,
    parse_value,
    read_toml,
    to_dict,
    to_json,
)
from mjx_stairs.rl.trainer import LearnerConfig


@dataclass(frozen=True)
class Inner:
    rate: float = field(default=0.5, metadata={"help": "a rate"})
    sizes: tuple[int, ...] = (1, 2)
    mode: Literal["a", "b"] = "a"


@dataclass(frozen=True)
class Outer:
    name: str = "x"
    count: int = 3
    flag: bool = False
    limit: int | None = None
    inner: Inner = field(default_factory=Inner)
    custom: Inner = field(default_factory=lambda: Inner(rate=2.0))


def test_defaults_and_toml_file(tmp_path):
    p = tmp_path / "exp.toml"
    p.write_text('name = "run"\n[inner]\nrate = 1\nsizes = [4, 5, 6]\n')
    cfg = load_config(Outer, p)
    assert cfg == Outer(name="run", inner=Inner(rate=1.0, sizes=(4, 5, 6)))
    assert isinstance(cfg.inner.rate, float)
    hash(cfg)  # frozen and hashable: usable as a static jit argument


def test_overrides_parse_toml_literals_and_bare_strings(tmp_path):
    p = tmp_path / "exp.toml"
    p.write_text("count = 1\n")
    cfg = load_config(
        Outer, p,
        ["count=7", "flag=true", "name=stage1_run", "inner.sizes=[8, 16]", "inner.mode=b",
         "limit=10", 'custom.rate=3e-4'],
    )
    assert cfg.count == 7 and cfg.flag is True and cfg.name == "stage1_run"
    assert cfg.inner.sizes == (8, 16) and cfg.inner.mode == "b" and cfg.limit == 10
    # a partial table keeps the non-default default of the nested field
    assert cfg.custom == Inner(rate=3e-4)
    assert load_config(Outer, None, ["limit=none"]).limit is None
    assert parse_value("1e-3") == 1e-3 and parse_value("abc") == "abc"
    assert parse_value('"quoted"') == "quoted"


def test_partial_nested_table_keeps_parent_default():
    cfg = from_dict(Outer, {"custom": {"sizes": [9]}})
    assert cfg.custom == Inner(rate=2.0, sizes=(9,))


@pytest.mark.parametrize(
    "override, fragment",
    [
        ("inner.rte=1.0", "unknown config key 'inner.rte'"),
        ("nope=1", "unknown config key 'nope'"),
        ("count=1.5", "config key 'count': expected int, got float 1.5"),
        ("count=true", "config key 'count': expected int"),
        ("flag=1", "config key 'flag': expected bool"),
        ("inner.rate=fast", "config key 'inner.rate': expected float, got str 'fast'"),
        ("inner.sizes=[1, 2.5]", "config key 'inner.sizes[1]': expected int"),
        ("inner.mode=c", "config key 'inner.mode': expected one of ['a', 'b']"),
        ("inner=3", "config key 'inner': expected Inner"),
    ],
)
def test_bad_values_name_the_key_and_type(override, fragment):
    with pytest.raises(ConfigError) as e:
        load_config(Outer, None, [override])
    assert fragment in str(e.value)


def test_file_errors_name_the_file(tmp_path):
    with pytest.raises(ConfigError, match="config file not found"):
        load_config(Outer, tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("count = = 2\n")
    with pytest.raises(ConfigError, match="bad.toml: invalid TOML"):
        load_config(Outer, bad)
    typo = tmp_path / "typo.toml"
    typo.write_text("[inner]\nrat = 2\n")
    with pytest.raises(ConfigError, match=r"typo\.toml: unknown config key 'inner\.rat'"):
        load_config(Outer, typo)
    with pytest.raises(ConfigError, match="not of the form"):
        apply_overrides({}, ["count"])


def test_json_round_trip_of_the_learner_config():
    cfg = load_config(LearnerConfig, None, ["ppo.learning_rate=3e-4", "network.actor_hidden=[64]",
                                            "train.experiment=rt", "network.conv_impl=fused"])
    d = to_dict(cfg)
    assert d["network"]["actor_hidden"] == [64] and d["network"]["conv_impl"] == "fused"
    json.dumps(d)
    assert from_json(LearnerConfig, to_json(cfg)) == cfg
    assert from_dict(LearnerConfig, json.loads(json.dumps(d))) == cfg


def test_learner_defaults_are_the_protocol():
    cfg = LearnerConfig()
    p, n, t = cfg.ppo, cfg.network, cfg.train
    assert (t.unroll_length, p.learning_rate, p.desired_kl, p.num_epochs, p.num_minibatches) == (
        24, 1e-3, 0.01, 5, 4)
    assert (p.discount, p.gae_lambda, p.clip_eps, p.value_clip_eps) == (0.995, 0.995, 0.2, 0.2)
    assert (p.entropy_coef, p.max_grad_norm, p.value_loss_coef) == (0.005, 1.0, 1.0)
    assert n.conv_channels == (8, 16, 32) and n.latent_size == 128 and n.pool_size == 2
    assert n.actor_hidden == n.critic_hidden == (128, 128, 64) and n.init_std == 0.8


EXPERIMENT_FILES = sorted(
    p for p in Path("experiments").glob("*.toml") if not p.name.startswith("transfer_matrix")
)


@pytest.mark.parametrize("path", EXPERIMENT_FILES, ids=lambda p: p.name)
def test_every_experiment_file_loads_on_gpu_and_cpu_presets(path):
    from mjx_stairs.study import experiment

    for cpu in (False, True):
        cfg, _ = experiment.load(path, [], cpu=cpu)
        assert cfg.train.num_envs > 0
    cfg, _ = experiment.load(path, [], cpu=False)
    # the physics each file says it has: the lean preset, the evaluation physics (the issue-24
    # generalist, trained where the code risers are judged; issue 21's paper-as-written stage 2)
    # or the reference physics
    from mjx_stairs.sim.robot import PHYSICS

    paper = "_paper" in path.name  # stage2_u_paper.toml and its family / no-stall files
    named = {"generalist.toml": "evaluation", "stage2_u_robot.toml": "evaluation",
             "stage2_u_robot_corner.toml": "evaluation",
             "stage2_u_robot_history.toml": "evaluation", "generalist_history.toml": "evaluation",
             "stage2_u_robot_latency20.toml": "evaluation",
             "stage2_u_robot_stiff.toml": "evaluation", "stage1_tall.toml": "evaluation",
             "stage2_u_robot_stiff_s1.toml": "evaluation",
             "generalist_lean.toml": "lean_implicit",
             # resumes a state trained at go2.xml's contact: the std its one change
             "generalist_d2_stop_chord_landing_rstd.toml": "evaluation_soft"}
    want = PHYSICS[named.get(path.name, "lean" if path.name.endswith("_lean.toml")
                             else "evaluation_top" if paper
                             else "evaluation" if path.name.startswith("generalist_")  # variants
                             else "reference")]
    # a field a file sets over its base's preset (training's contact at go2.xml's 0.02 s)
    want = {**want, **{"generalist_from_stage1_mix_soft.toml": {"contact_timeconst": 0.02}}.get(
        path.name, {})}
    assert {k: getattr(cfg.env.robot, k) for k in want} == want
    # the bfloat16 encoder only where its stage-2 training was checked
    bf16 = path.name in ("stage2_u_lean.toml", "generalist_lean.toml")
    assert cfg.network.conv_impl == ("fused_bf16" if bf16 else "auto")
    assert experiment.load(path, [], cpu=True)[0].network.conv_impl == "auto"


@pytest.mark.parametrize("iterations", [1, 2, 3, 8])
def test_implicit_damping_needs_newton_iterations(iterations):
    """MJX's implicit damping takes the step from the constraint force, so an unconverged solve
    runs the joints away (sim.robot.IMPLICIT_MIN_ITERATIONS): refused below 3 iterations."""
    from mjx_stairs.env.config import env_config_from
    from mjx_stairs.study import experiment

    over = ["robot.implicit_damping=true", f"robot.solver_iterations={iterations}"]
    if iterations >= 3:
        assert env_config_from(None, over).robot.solver_iterations == iterations
    else:
        with pytest.raises(ConfigError, match=r"'env\.robot\.implicit_damping': must be false "
                           rf"unless env\.robot\.solver_iterations >= 3 \(it has {iterations}:"):
            env_config_from(None, over)
        # explicit damping keeps the reference and lean physics' single iteration
        assert env_config_from(None, over[1:]).robot.solver_iterations == iterations
    if iterations == 1:  # the generalist's implicit damping in the plain lean physics
        with pytest.raises(ConfigError, match="implicit_damping"):
            experiment.load("experiments/generalist_lean.toml", ["env.robot.physics=lean"],
                            cpu=False)


def test_a_file_inherits_from_its_base(tmp_path):
    (tmp_path / "a.toml").write_text('x = 1\n[inner]\nrate = 0.5\nname = "a"\n')
    (tmp_path / "b.toml").write_text('base = "a.toml"\n[inner]\nname = "b"\n')
    assert read_toml(tmp_path / "b.toml") == {"x": 1, "inner": {"rate": 0.5, "name": "b"}}
    (tmp_path / "c.toml").write_text('base = "c.toml"\n')
    with pytest.raises(ConfigError, match="inherits from itself"):
        read_toml(tmp_path / "c.toml")


def test_physics_presets_set_the_physics_fields_in_order():
    from mjx_stairs.sim.robot import PHYSICS
    from mjx_stairs.study import experiment

    lean, _ = experiment.load("experiments/stage2_u_lean.toml", [], cpu=False)
    robot = lean.env.robot
    assert {k: getattr(robot, k) for k in PHYSICS["lean"]} == PHYSICS["lean"]
    ref, _ = experiment.load("experiments/stage2_u_lean.toml", ["env.robot.physics=reference"],
                             cpu=False)
    assert {k: getattr(ref.env.robot, k) for k in PHYSICS["reference"]} == PHYSICS["reference"]
    later, _ = experiment.load("experiments/stage2_u_lean.toml",
                               ["env.robot.physics=reference", "env.robot.ls_iterations=4"],
                               cpu=False)
    assert later.env.robot.ls_iterations == 4 and later.env.robot.shin_collision
    with pytest.raises(ConfigError, match="'robot.physics': expected one of"):
        experiment.load("experiments/stage2_u.toml", ["env.robot.physics=fast"], cpu=False)


def test_a_field_a_file_sets_wins_over_its_base_physics_preset(tmp_path):
    # a preset in a base file once silently won over a field the inheriting file set
    # (generalist_from_stage1_mix_soft.toml's contact time constant)
    from mjx_stairs.sim.robot import PHYSICS
    from mjx_stairs.study import experiment

    (tmp_path / "a.toml").write_text('[env.robot]\nphysics = "evaluation"\n')
    (tmp_path / "b.toml").write_text('base = "a.toml"\n[env.robot]\ncontact_timeconst = 0.02\n')
    (tmp_path / "c.toml").write_text('base = "b.toml"\n[env.robot]\nphysics = "lean"\n')
    a, _ = experiment.load(tmp_path / "a.toml", cpu=False)
    b, _ = experiment.load(tmp_path / "b.toml", cpu=False)
    c, _ = experiment.load(tmp_path / "c.toml", cpu=False)
    evaluation = PHYSICS["evaluation"]["contact_timeconst"]
    assert a.env.robot.contact_timeconst == evaluation != 0.02
    assert b.env.robot.contact_timeconst == 0.02
    assert b.env.robot.sunk_exit == PHYSICS["evaluation"]["sunk_exit"]  # the rest of the preset
    # a file's own preset replaces its base's whole (the fields the evaluation preset set are
    # back at their defaults); the field b set stays, the lean preset not naming it
    default = experiment.load(None, cpu=False)[0].env.robot
    assert c.env.robot.contact_timeconst == 0.02
    assert c.env.robot.sunk_exit == default.sunk_exit != PHYSICS["evaluation"]["sunk_exit"]
    assert {k: getattr(c.env.robot, k) for k in PHYSICS["lean"]} == PHYSICS["lean"]
