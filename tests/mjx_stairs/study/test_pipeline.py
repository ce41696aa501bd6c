"""End to end on the CPU: the real stair env trained for two iterations through the CLI, then
evaluation, the EXP1 report, the transfer matrix and the bench on what it produced."""

import copy
import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from mjx_stairs import cli
from mjx_stairs.config import ConfigError
from mjx_stairs.env import observation
from mjx_stairs.rl.policy import load_policy, widen_for_history
from mjx_stairs.study import bench, critic_map, evaluate, exp1, experiment, plots, transfer

TINY = evaluate.EvalSpec(levels=(0, 5), robots_per_level=2, episode_length_s=1.0, resolution=0.05)


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    root = tmp_path_factory.mktemp("pipeline")
    code = cli.main(
        [
            "train",
            "experiments/stage1.toml",
            "train.num_envs=16",
            "train.total_iterations=2",
            "train.iterations_per_chunk=1",
            "ppo.num_epochs=1",  # one pass of the update: 5 took ~20 s more per iteration here
            f"train.log_dir={root / 'runs'}",
            f"publish_dir={root / 'stage1'}",
            "train.progress=false",
            "train.console=false",
            "terrain.resolution=0.05",
            "terrain.variants_per_family=1",
            "terrain.levels=[0, 4]",
        ]
    )
    assert code == 0
    return root


def test_stair_env_trains_two_iterations_with_16_robots(trained):
    rows = [json.loads(x) for x in (trained / "stage1" / "metrics.jsonl").read_text().splitlines()]
    assert [r["iteration"] for r in rows] == [1, 2]
    assert rows[-1]["env_steps"] == 2 * 16 * 24
    for key in ("episode/return", "loss/value", "level", "reward/nav_coarse", "success"):
        assert math.isfinite(rows[-1][key]), key
    facts = json.loads((trained / "stage1" / "run.json").read_text())
    assert facts["env_steps"] == 768 and facts["backend"] == "cpu"
    policy = load_policy(trained / "stage1" / "policy.npz")
    assert policy.layout.n_vec == observation.N_VEC and policy.layout.map_shape == (21, 21)
    assert policy.metadata["config"]["terrain"]["families"] == ["pyramid"]


def test_eval_and_exp1_report(trained, tmp_path):
    path = trained / "stage1" / "policy.npz"
    results = evaluate.evaluate([path], ["u_shaped"], TINY, tmp_path / "eval")
    r = results[0]
    assert r["levels"] == [1, 6] and len(r["success"]) == 2
    assert all(0.0 <= s <= 1.0 for s in r["success"] + r["fell"])
    assert all(0.0 <= e <= f for e, f in zip(r["fell_first_second"], r["fell"], strict=True))
    saved = json.loads((tmp_path / "eval" / "results.json").read_text())
    assert saved[0]["success"] == r["success"]
    assert "| u_shaped |" in (tmp_path / "eval" / "results.md").read_text()

    summary = exp1.report(path, tmp_path / "exp1", spec=TINY)
    assert (tmp_path / "exp1" / "fig2_u_success.png").stat().st_size > 5000
    assert (tmp_path / "exp1" / "fig4_critic_u.png").stat().st_size > 5000
    assert "paper (Table 1)" in (tmp_path / "exp1" / "exp1.md").read_text()
    assert set(summary["results"]) == {"stage 2 (stall penalty)"}


def test_falls_in_the_first_second_counted_by_the_step_that_ended_the_episode():
    """fell_within: a robot counts when its first episode ended in a fall by the step given;
    a later fall, a success or a timeout (end step -1) does not; shares per level row."""
    fell = np.array([True, True, False, True, False, True, True, False])
    end = np.array([3, 50, 2, 51, -1, 50, 1, -1])
    assert evaluate.fell_within(fell, end, 50, 2) == [0.5, 0.5]
    assert evaluate.fell_within(fell, end, 10, 2) == [0.25, 0.25]
    assert evaluate.fell_within(fell, end, 0, 2) == [0.0, 0.0]


def test_eval_env_overrides_change_the_physics_not_the_policy(trained):
    policy = load_policy(trained / "stage1" / "policy.npz")
    trained_cfg = evaluate.env_config_of(policy)
    ref = evaluate.env_config_of(policy, ["robot.shin_collision=false", "robot.ls_iterations=3"])
    assert trained_cfg.robot.shin_collision and trained_cfg.robot.ls_iterations == 5
    assert not ref.robot.shin_collision and ref.robot.ls_iterations == 3
    assert ref.robot.kp == trained_cfg.robot.kp and ref.goal_mode == trained_cfg.goal_mode
    with pytest.raises(Exception, match=r"unknown config key 'env\.robot\.shins'"):
        evaluate.env_config_of(policy, ["robot.shins=false"])
    with pytest.raises(Exception, match="not of the form"):
        evaluate.env_config_of(policy, ["robot.shin_collision"])


def test_critic_map_covers_the_tile_and_blanks_walls(trained):
    m = critic_map.critic_map(
        load_policy(trained / "stage1" / "policy.npz"), "u_shaped", 2, spacing=0.25, resolution=0.05
    )
    v = m["value"]
    assert v.shape == (len(m["y"]), len(m["x"]))
    walkable = np.isfinite(v)
    assert 0.1 < walkable.mean() < 0.9  # the staircase is walkable, the walls around it are not
    assert np.ptp(v[walkable]) > 0  # the critic sees different places differently
    # a policy with observation history (env.obs_history): valued standing at the nominal pose
    # with no earlier actions; the same policy widened for history values every cell as before
    plain = load_policy(trained / "stage1" / "policy.npz")
    wide = widen_for_history(plain, observation.n_vec(2) - observation.N_VEC)
    meta = copy.deepcopy(wide.metadata)
    meta["config"]["env"]["obs_history"] = 2
    h = critic_map.critic_map(wide._replace(metadata=meta), "u_shaped", 2, spacing=0.25,
                              resolution=0.05)
    np.testing.assert_allclose(h["value"], v, atol=1e-4)


def test_transfer_matrix_and_transferability(trained, tmp_path, monkeypatch):
    mean = {"u": {"u": 0.8, "s": 0.9}, "s": {"u": 0.02, "s": 0.95}}
    t = transfer.transferability(mean)
    assert t["u"]["s"] == pytest.approx(0.9 / 0.95) and t["s"]["u"] == pytest.approx(0.02 / 0.8)
    assert math.isnan(transfer.transferability({"a": {"a": 0.0}})["a"]["a"])
    path = str(trained / "stage1" / "policy.npz")
    policy = load_policy(path)
    # the overrides reach the evaluation env: another collider, other contact rows
    nearest = dataclasses.replace(TINY, env_overrides=("robot.terrain_contacts=nearest",))
    env, _ = evaluate.make_eval_env(policy, nearest)
    assert env.config.robot.terrain_contacts == "nearest" and env.num_contacts == 32
    # the matrix passes them to every evaluation and records them. An override that restates
    # the evaluation physics' collider keeps the program of test_eval_and_exp1_report (TINY on
    # u_shaped), which the session's compilation cache then serves without compiling it again
    spec = dataclasses.replace(TINY, env_overrides=("robot.terrain_contacts=columns",))
    assert evaluate.env_config_of(policy, evaluate.physics_overrides(spec)) == (
        evaluate.env_config_of(policy, evaluate.physics_overrides(TINY)))
    result = transfer.matrix({"u_shaped": path}, spec, tmp_path)
    assert result["levels"] == [1, 6]
    assert result["env_overrides"] == ["robot.terrain_contacts=columns"]
    assert result["success"]["u_shaped"]["u_shaped"]["env_overrides"] == list(spec.env_overrides)
    md = (tmp_path / "transfer.md").read_text()
    assert "Transferability" in md and "evaluated with robot.terrain_contacts=columns" in md
    cell = result["success"]["u_shaped"]["u_shaped"]
    assert cell["physics_settings"]["terrain_contacts"] == "columns"
    assert cell["physics_settings"]["sunk_exit"] == "nearest"  # the evaluation physics
    assert cell["physics_settings"]["contact_timeconst"] == 0.01  # the evaluation physics's
    # a matrix run again over the same folder keeps its finished cells (a killed run resumes)
    def no_evaluation(*_):
        raise AssertionError("a finished cell was evaluated again")

    monkeypatch.setattr(evaluate, "success_by_level", no_evaluation)
    again = transfer.matrix({"u_shaped": path}, spec, tmp_path)
    assert again["success"] == result["success"]
    # a part of the matrix (one GPU's cells): only the cells asked for, no matrix written over
    # the whole one; here from kept cells, and a straight column would be evaluated (and raise)
    cells = tmp_path / "cells"
    (cells / "straight__on__u_shaped.json").write_text(
        (cells / "u_shaped__on__u_shaped.json").read_text())
    before = (tmp_path / "transfer.json").read_text()
    part = transfer.matrix({"u_shaped": path, "straight": path}, spec, tmp_path,
                           columns=["u_shaped"])
    assert part == {"cells": {m: {"u_shaped": cell} for m in ("u_shaped", "straight")}}
    assert transfer.matrix({"u_shaped": path, "straight": path}, spec, tmp_path,
                           rows=["straight"], columns=["u_shaped"]) == {
        "cells": {"straight": {"u_shaped": cell}}}
    assert (tmp_path / "transfer.json").read_text() == before
    with pytest.raises(ConfigError, match="spiral not among its models"):
        transfer.matrix({"u_shaped": path}, spec, tmp_path, rows=["spiral"])
    # ... but not a cell of another policy file, other levels or other overrides
    saved = tmp_path / "cells" / "u_shaped__on__u_shaped.json"
    want = {k: cell[k] for k in ("family", "levels", "checkpoint", "checkpoint_sha256")}
    assert transfer._finished_cell(saved, want) == cell
    assert transfer._finished_cell(saved, {**want, "checkpoint_sha256": "0" * 64}) is None
    assert transfer._finished_cell(saved, {**want, "levels": [3, 4]}) is None
    with pytest.raises(AssertionError, match="evaluated again"):
        transfer.matrix({"u_shaped": path}, dataclasses.replace(spec, env_overrides=()), tmp_path)
    # ... nor one judged when the preset's name meant other physics (the MJCF's contact)
    soft = json.loads(saved.read_text())
    soft["physics_settings"]["contact_timeconst"] = 0.0
    saved.write_text(json.dumps(soft))
    assert transfer._finished_cell(saved, want) is not None  # the other fields still match
    with pytest.raises(AssertionError, match="evaluated again"):
        transfer.matrix({"u_shaped": path}, spec, tmp_path)
    saved.write_text("{not json")
    assert transfer._finished_cell(saved, want) is None
    with pytest.raises(Exception, match="unknown stair family"):
        bad = tmp_path / "bad.toml"
        bad.write_text('[models]\nzigzag = "x.npz"\n')
        transfer.load_models(bad)


def test_published_transfer_models_load():
    """The committed matrix's models file names policies that exist and load, one per family,
    all with the same observation layout and the training physics their configs recorded."""
    models = transfer.load_models("experiments/results/transfer_lean/models.toml")
    assert set(models) == {"u_shaped", "straight", "l_shaped", "spiral"}
    layouts = {str(load_policy(p).layout) for p in models.values()}
    assert len(layouts) == 1
    for fam in ("straight", "l_shaped", "spiral"):
        cfg = json.loads((Path(models[fam]).parent / "config.json").read_text())
        assert cfg["terrain"]["families"] == [fam]
        assert cfg["env"]["robot"]["terrain_contacts"] == "nearest"


def test_bench_measures_physics_and_env():
    config, _ = experiment.load(
        "experiments/stage2_u.toml",
        [
            "terrain.resolution=0.05",
            "terrain.variants_per_family=1",
            "terrain.levels=[0]",
        ],
        cpu=False,
    )
    out = bench.run_bench(config, [4], steps=2, repeats=1, parts=("physics", "env"))
    row = out["results"][0]
    assert row["physics"]["steps_per_s"] > 0 and row["env"]["steps_per_s"] > 0
    split = row["seconds_per_iteration"]  # T x B steps at each rate, layered
    assert set(split) == {"physics", "env_overhead"}
    assert split["physics"] == pytest.approx(4 * config.train.unroll_length
                                             / row["physics"]["steps_per_s"])
    with pytest.raises(ValueError, match="unknown parts"):
        bench.run_bench(config, [4], parts=("physics", "rolout"))
    assert out["contacts"] == 64  # 16 spheres x 4 heightfield contacts
    assert out["solver"]["terrain_contacts"] == "mjx"


def test_cli_errors_are_one_line(capsys, tmp_path):
    assert cli.main(["train", str(tmp_path / "missing.toml")]) == 2
    assert "config file not found" in capsys.readouterr().err
    assert cli.main(["train", "experiments/stage1.toml", "train.bogus=1"]) == 2
    assert "train.bogus" in capsys.readouterr().err
    assert cli.main(["eval", "--checkpoint", str(tmp_path / "none.npz")]) == 2
    err = capsys.readouterr().err
    assert "none.npz" in err and len(err.strip().splitlines()) == 1


def test_training_curves_from_published_runs(trained, tmp_path, capsys):
    out = tmp_path / "curves.png"
    assert cli.main(["curves", f"stage 1={trained / 'stage1'}", "--out", str(out)]) == 0
    assert out.stat().st_size > 5000
    rows = plots.read_metrics(trained / "stage1")
    assert [r["iteration"] for r in rows] == [1, 2]
    broken = tmp_path / "broken.jsonl"
    broken.write_text('{"env_steps": 1}\n{not json\n')
    assert cli.main(["curves", str(broken), "--out", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert "broken.jsonl:2: not a JSON line" in err and len(err.strip().splitlines()) == 1
    assert cli.main(["curves", str(tmp_path / "nothing"), "--out", str(tmp_path / "x.png")]) == 2
    assert "metrics file not found" in capsys.readouterr().err
    assert not (tmp_path / "x.png").exists()


def test_ablation_gets_the_budget_stage2_had(tmp_path):
    run = tmp_path / "run.json"
    assert exp1.ablation_budget(run) == ()  # stage 2 not published: the config's own budget
    run.write_text(json.dumps({"iterations": 290, "stop_reason": "time_budget"}))
    assert exp1.ablation_budget(run) == ("train.total_iterations=290",)
    run.write_text(json.dumps({"iterations": 1500, "stop_reason": "total_iterations"}))
    assert exp1.ablation_budget(run) == ()
    published = "experiments/results/stage2_u/run.json"  # the committed GPU run
    assert exp1.ablation_budget(published) == ("train.total_iterations=290",)
