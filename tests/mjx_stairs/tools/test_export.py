"""ONNX export: the graph matches the JAX policy (onnxruntime), the sidecar matches the env."""

from __future__ import annotations

import copy
import json
import types

import jax
import jax.numpy as jnp
import numpy as np
import pytest

onnx = pytest.importorskip("onnx")
ort = pytest.importorskip("onnxruntime")

from mjx_stairs import cli  # noqa: E402
from mjx_stairs.env import observation  # noqa: E402
from mjx_stairs.rl import networks, normalizer  # noqa: E402
from mjx_stairs.rl import policy as policy_lib  # noqa: E402
from mjx_stairs.sim import robot as rb  # noqa: E402
from mjx_stairs.study.experiment import ExperimentConfig  # noqa: E402
from mjx_stairs.tools import export  # noqa: E402

N_VEC, MAP = observation.N_VEC, (21, 21)  # the default height map
D = N_VEC + MAP[0] * MAP[1]


def _policy_state(seed: int = 0, history: int = 0, delay: bool = False):
    """Params of the real architecture with non-trivial biases and an actor output of order 1,
    and a normaliser with varied means and stds (some tiny, so the clip is active); `history`:
    the observation's steps of history (env.obs_history); `delay`: the action delay term."""
    cfg = ExperimentConfig()
    n_vec = observation.n_vec(history, delay)
    d = n_vec + MAP[0] * MAP[1]
    k = jax.random.split(jax.random.PRNGKey(seed), 8)
    params = networks.init_params(k[0], cfg.network, n_vec, MAP, 12)
    params["actor"][-1]["w"] = params["actor"][-1]["w"] * 20.0  # actions of order 1, as trained
    paths, treedef = jax.tree_util.tree_flatten_with_path(params)
    keys = jax.random.split(k[1], len(paths))
    leaves = [x + 0.1 * jax.random.normal(kk, x.shape) if jax.tree_util.keystr(path).endswith(
        "['b']") else x for (path, x), kk in zip(paths, keys, strict=True)]  # non-zero biases
    params = jax.tree_util.tree_unflatten(treedef, leaves)
    stats = normalizer.RunningStats(
        count=jnp.asarray(1000.0, jnp.float32),
        mean=jax.random.normal(k[2], (d,)),
        m2=1000.0 * jnp.exp(2.0 * jax.random.uniform(k[3], (d,), minval=-1.5, maxval=1.0)),
    )
    norm = {"state": stats, "privileged_state": normalizer.init_stats(d)}
    return types.SimpleNamespace(params=params, normalizer=norm,
                                 iteration=jnp.asarray(7, jnp.int32)), cfg


@pytest.fixture(scope="module")
def policy_file(tmp_path_factory):
    state, cfg = _policy_state()
    path = tmp_path_factory.mktemp("export") / "policy.npz"
    policy_lib.save_policy(path, state.params, state.normalizer, 7, cfg,
                           networks.ObsLayout(N_VEC, MAP))
    return path


@pytest.fixture(scope="module")
def policy(policy_file):
    return policy_lib.load_policy(policy_file)


@pytest.fixture(scope="module")
def exported(policy, tmp_path_factory):
    path = tmp_path_factory.mktemp("onnx") / "policy.onnx"
    side = export.export_policy(policy, path)
    return path, side


@pytest.fixture(scope="module")
def jax_action(policy):
    return jax.jit(lambda o: policy_lib.policy_action(policy, o))


def _obs(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    obs = rng.standard_normal((n, D)).astype(np.float32) * 2.0
    obs[:, N_VEC:] = rng.uniform(-3.0, 3.0, (n, D - N_VEC))  # height map range
    obs[: n // 2, :5] *= 100.0  # far outside the normaliser's clip
    return obs


def test_onnx_matches_jax_on_random_observations(policy, exported, jax_action):
    path, _ = exported
    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    for n, seed in ((1, 0), (5, 1), (64, 2)):
        obs = _obs(n, seed)
        got = sess.run(["action"], {"obs": obs})[0]
        want = np.asarray(jax_action(obs))
        assert got.shape == (n, 12) and got.dtype == np.float32
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-5)
    # the comparison has teeth: actions of order 1, vary with the obs, and the clip matters
    obs = _obs(64, 3)
    want = np.asarray(jax_action(obs))
    assert np.std(want) > 0.1
    mean, denom, clip = policy_lib.normaliser_constants(policy)
    assert np.mean(np.abs((obs - mean) / denom) > clip) > 0.01
    no_clip = networks.actor_mean(policy.params, jnp.asarray((obs - mean) / denom), policy.layout)
    assert np.max(np.abs(np.asarray(no_clip) - want)) > 1e-2
    # and the map half of the input reaches the output
    moved = obs.copy()
    moved[:, N_VEC:] += 0.5
    assert np.max(np.abs(sess.run(["action"], {"obs": moved})[0] - want)) > 1e-3


def test_verify_reports_the_difference(policy, exported):
    assert export.verify(policy, exported[0], n=16) <= 1e-5


def test_verify_compares_the_applied_action(policy, exported, tmp_path):
    """verify judges the action a robot applies, clipped to the sidecar's action.clip, relative to
    the largest raw action: with the clip at 1e-3 every action is clipped on both sides and they
    agree exactly; a wrong graph (the policy's actions plus 0.01) is still caught inside the clip;
    no sidecar is a clear error."""
    onnx_path, side = exported
    side_path = export.sidecar_path(onnx_path)
    obs = (3.0 * np.random.default_rng(0).standard_normal((16, D))).astype(np.float32)
    want = np.asarray(jax.jit(lambda o: policy_lib.policy_action(policy, o))(obs))
    assert np.mean(np.abs(want) > side["action"]["clip"]) < 0.5  # the clip leaves most inside
    tight = tmp_path / "tight.onnx"
    tight.write_bytes(onnx_path.read_bytes())
    export.sidecar_path(tight).write_text(json.dumps({**side, "action": {**side["action"],
                                                                          "clip": 1e-3}}))
    assert export.verify(policy, tight, n=16) == 0.0
    model = onnx.load(str(onnx_path))  # the graph's output shifted by 0.01
    out = model.graph.output[0].name
    for n in model.graph.node:
        n.output[:] = [o + "_raw" if o == out else o for o in n.output]
    model.graph.initializer.append(onnx.numpy_helper.from_array(np.float32(0.01), "shift"))
    model.graph.node.append(onnx.helper.make_node("Add", [out + "_raw", "shift"], [out]))
    wrong = tmp_path / "wrong.onnx"
    onnx.save(model, str(wrong))
    export.sidecar_path(wrong).write_text(side_path.read_text())
    scale = max(1.0, float(np.max(np.abs(want))))
    assert 0.009 / scale < export.verify(policy, wrong, n=16) <= 0.0101 / scale
    assert 0.01 / scale > 1e-4  # far above the CLI's 1e-5
    bare = tmp_path / "bare.onnx"
    bare.write_bytes(onnx_path.read_bytes())
    with pytest.raises(export.ExportError, match="action.clip"):
        export.verify(policy, bare, n=16)


def test_graph_structure(exported):
    model = onnx.load(str(exported[0]))
    onnx.checker.check_model(model)
    assert model.opset_import[0].version == export.OPSET
    (inp,), (out,) = model.graph.input, model.graph.output
    assert inp.name == "obs" and out.name == "action"
    dims = lambda v: [d.dim_param or d.dim_value for d in v.type.tensor_type.shape.dim]
    assert dims(inp) == ["batch", D] and dims(out) == ["batch", 12]
    ops = {n.op_type for n in model.graph.node}
    assert {"Sub", "Div", "Clip", "Slice", "Reshape", "Conv", "MaxPool", "Elu", "Gemm",
            "Concat"} <= ops
    assert sum(n.op_type == "Conv" for n in model.graph.node) == 3


def test_sidecar_layout_matches_the_env(exported):
    """Every named range of the sidecar holds what the env's observation puts there."""
    import terrains
    from mjx_stairs.env.config import EnvConfig
    from mjx_stairs.env.geometry import quat_to_mat, wrap_angle
    from mjx_stairs.env.stair_env import StairEnv

    _, side = exported
    layout = side["observation"]["layout"]
    assert layout[0]["start"] == 0 and layout[-1]["stop"] == D
    assert all(a["stop"] == b["start"] for a, b in zip(layout, layout[1:], strict=False))
    atlas = terrains.build_atlas(["pyramid"], "train", levels=[4], variants_per_family=1,
                                 resolution=0.1, tile_size=10.0, border=1.0)
    env = StairEnv(atlas, EnvConfig())
    rng = np.random.default_rng(0)
    sp = atlas.spawn[0]
    q = rng.normal(size=4)
    qpos = np.concatenate([[sp[0] + 0.3, sp[1] - 0.2, sp[2] + 0.35], q / np.linalg.norm(q),
                           rb.NOMINAL_JOINT_POS + rng.uniform(-0.3, 0.3, 12)]).astype(np.float32)
    qvel = rng.normal(size=18).astype(np.float32)
    last = rng.uniform(-1, 1, 12).astype(np.float32)
    info = {"tile": jnp.int32(0), "last_action": jnp.asarray(last)}
    obs = np.asarray(env.observe(jnp.asarray(qpos), jnp.asarray(qvel), info)["state"])
    part = {e["name"]: obs[e["start"]:e["stop"]] for e in layout}
    rot = np.asarray(quat_to_mat(jnp.asarray(qpos[3:7])))
    yaw = np.arctan2(rot[1, 0], rot[0, 0])
    goal = np.asarray(atlas.goal[0])
    tol = dict(rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(part["base_lin_vel"], rot.T @ qvel[:3], **tol)
    np.testing.assert_allclose(part["base_ang_vel"], qvel[3:6], **tol)
    np.testing.assert_allclose(part["projected_gravity"], rot.T @ [0, 0, -1.0], **tol)
    np.testing.assert_allclose(part["joint_pos"], qpos[7:] - rb.NOMINAL_JOINT_POS, **tol)
    np.testing.assert_allclose(part["joint_vel"], qvel[6:], **tol)
    np.testing.assert_allclose(part["last_action"], last, **tol)
    np.testing.assert_allclose(part["goal"][:3], rot.T @ (goal[:3] - qpos[:3]), **tol)
    np.testing.assert_allclose(part["goal"][3], float(wrap_angle(goal[3] - yaw)), **tol)
    # height map: row i = y, column j = x of the yaw frame, at -2 + 0.2 * index
    hm = side["height_map"]
    n, s = hm["size"][0], hm["spacing_m"]
    grid = part["height_map"].reshape(n, n)
    for i, j in ((0, 0), (3, 17), (20, 5), (10, 10)):
        x, y = -2.0 + s * j, -2.0 + s * i
        wx = qpos[0] + np.cos(yaw) * x - np.sin(yaw) * y
        wy = qpos[1] + np.sin(yaw) * x + np.cos(yaw) * y
        h = float(env.terrain_height(jnp.float32(wx), jnp.float32(wy)))
        want = np.clip(qpos[2] - h - hm["offset_m"], -hm["clip_m"], hm["clip_m"])
        assert grid[i, j] == pytest.approx(want, abs=1e-4)


def test_sidecar_robot_facts(exported, policy):
    _, side = exported
    assert side["joints"]["names"] == list(rb.JOINT_NAMES)
    np.testing.assert_allclose(side["joints"]["nominal_pos_rad"], rb.NOMINAL_JOINT_POS)
    cfg = ExperimentConfig().env
    assert side["rates"]["control_hz"] == pytest.approx(50.0)
    assert side["rates"]["physics_dt_s"] == cfg.robot.timestep
    assert side["pd"]["kp"] == cfg.robot.kp and side["pd"]["kd"] == cfg.robot.kd
    np.testing.assert_allclose(side["pd"]["torque_limit_nm"], rb.TORQUE_LIMIT)
    assert side["action"]["scale"] == cfg.robot.action_scale
    assert side["action"]["clip"] == cfg.action_clip
    assert side["height_map"]["size"] == [21, 21] and side["height_map"]["spacing_m"] == 0.2
    assert side["height_map"]["offset_m"] == 0.4 and side["height_map"]["clip_m"] == 3.0
    assert side["policy"]["iteration"] == 7
    assert side["normalizer"]["clip"] == policy.network.obs_clip


def test_cli_export_writes_both_files(policy_file, tmp_path, capsys):
    out = tmp_path / "sub" / "p.onnx"
    assert cli.main(["export", "--checkpoint", str(policy_file), "--onnx", str(out)]) == 0
    text = capsys.readouterr().out
    assert "max |diff|" in text
    side = json.loads((tmp_path / "sub" / "p.onnx.json").read_text())
    import hashlib

    assert side["onnx"]["sha256"] == hashlib.sha256(out.read_bytes()).hexdigest()
    assert sorted(p.name for p in out.parent.iterdir()) == ["p.onnx", "p.onnx.json"]


@pytest.mark.parametrize("damage", ["missing", "corrupt"])
def test_cli_export_bad_checkpoint(tmp_path, capsys, damage):
    ck = tmp_path / "policy.npz"
    if damage == "corrupt":
        ck.write_bytes(b"PK\x03\x04 not really a zip")
    code = cli.main(["export", "--checkpoint", str(ck), "--onnx", str(tmp_path / "p.onnx")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and err[0].startswith("mjx-stairs export: error:")
    assert ("not found" if damage == "missing" else "corrupt") in err[0]
    assert not (tmp_path / "p.onnx").exists()


def test_sidecar_says_what_the_goal_input_is(policy, exported):
    _, side = exported
    (goal,) = [e for e in side["observation"]["layout"] if e["name"] == "goal"]
    assert "waypoint" not in goal["description"]  # the default, final-goal policy
    meta = copy.deepcopy(policy.metadata)
    meta["config"]["env"].update(goal_mode="waypoint", waypoint_lookahead_m=1.5)
    side = export.sidecar(policy._replace(metadata=meta))
    (goal,) = [e for e in side["observation"]["layout"] if e["name"] == "goal"]
    assert "waypoint" in goal["description"] and "1.5 m" in goal["description"]
    assert side["goal"]["heading"] == "ahead" and "heading there" in goal["description"]
    meta["config"]["env"].update(waypoint_heading="here")
    side = export.sidecar(policy._replace(metadata=meta))
    (goal,) = [e for e in side["observation"]["layout"] if e["name"] == "goal"]
    assert side["goal"]["heading"] == "here" and "projection as its yaw" in goal["description"]


def test_the_contract_reads_the_waypoint_heading_rule(exported, tmp_path):
    """goal.heading: 'ahead' where a sidecar predates it, 'here' and 'chord' read back, anything
    else a one-line error naming it."""
    from mjx_stairs.tools import contract as ct

    path, side = exported
    for heading, want in ((None, "ahead"), ("here", "here"), ("chord", "chord"), ("behind", None)):
        s = copy.deepcopy(side)
        s["goal"].pop("heading")
        if heading is not None:
            s["goal"]["heading"] = heading
        bad = tmp_path / f"p_{heading}.onnx"
        bad.write_bytes(path.read_bytes())
        ct.sidecar_path(bad).write_text(json.dumps(s))
        if want is None:
            with pytest.raises(ct.ContractError, match="goal heading must be 'ahead', 'here'"):
                ct.load_contract(bad)
        else:
            assert ct.load_contract(bad).heading == want


def test_sidecar_v2_fields_a_robot_program_needs(exported, policy):
    """Each field beyond v1: clip ranges, the SDK motor order, the map's points, the goal rule,
    the evaluation rules, the base velocity and the versions; read back by the robot side."""
    import importlib.metadata

    import mujoco

    from mjx_stairs.tools import contract as ct
    from mjx_stairs.tools import sidecar

    path, side = exported
    assert side["format"] == sidecar.FORMAT == ct.FORMAT
    clips = {e["name"]: e["clip"] for e in side["observation"]["layout"]}
    cfg = ExperimentConfig().env
    assert clips["last_action"] == [-cfg.action_clip, cfg.action_clip]
    assert clips["height_map"] == [-cfg.height_map.clip, cfg.height_map.clip]
    assert clips["base_lin_vel"] is None
    assert [e["scale"] for e in side["observation"]["layout"]] == [1.0] * 8
    units = {e["name"]: e["unit"] for e in side["observation"]["layout"]}
    assert units["joint_vel"] == "rad/s" and units["height_map"] == "m"
    j = side["joints"]
    # the Go2 SDK's motor order: FR, FL, RR, RL x (hip, thigh, calf)
    assert j["sdk_names"][:4] == ["FR_hip_joint", "FR_thigh_joint", "FR_calf_joint",
                                  "FL_hip_joint"]
    assert [j["sdk_names"][k] for k in j["sdk_index"]] == j["names"]
    assert j["sdk_index"][:3] == [3, 4, 5] and j["sdk_index"][6:9] == [9, 10, 11]
    c = ct.load_contract(path)
    x = np.arange(12.0)
    np.testing.assert_array_equal(ct.from_sdk(c, ct.to_sdk(c, x)), x)
    assert ct.to_sdk(c, x)[0] == j["names"].index("FR_hip_joint")
    assert j["nominal_pos_rad"][:3] == [0.1, 0.8, -1.5]  # decimals, not float32 noise
    hm = side["height_map"]
    np.testing.assert_allclose(np.diff(hm["x_m"]), hm["spacing_m"])
    assert hm["x_m"][0] == -2.0 and hm["y_m"][-1] == 2.0 and len(hm["y_m"]) == 21
    assert side["goal"]["mode"] == cfg.goal_mode and "waypoint" in side["goal"]
    assert side["goal"]["heading"] == "ahead" and c.heading == "ahead"
    ev = side["evaluation"]
    assert (ev["success_distance_m"], ev["success_speed_m_s"], ev["success_hold_s"]) == (
        cfg.success_distance, cfg.success_speed, cfg.success_hold_s)
    assert (ev["max_tilt_rad"], ev["min_base_height_m"], ev["low_line_m"], ev["tilt_slope_m"]) == (
        cfg.max_tilt, cfg.min_base_height, cfg.low_line_m, cfg.tilt_slope_m)
    assert ev["spawn_height_m"] == cfg.spawn_height
    assert "base frame" in side["base_velocity"]
    v = side["versions"]
    assert v["mujoco"] == mujoco.__version__ and v["jax"] == jax.__version__
    assert v["mjx_stairs"] == importlib.metadata.version("mjx_stairs") and v["python"]
    assert c.kp == side["pd"]["kp"] and c.control_dt == pytest.approx(0.02)
    # the robot it trained as: the MJCF's damping, integrated explicitly, no head (defaults)
    t = side["training"]
    assert t["joint_damping_nms_rad"] == [0.1, 0.1] and t["joint_damping_draw"] == "fixed"
    assert t["joint_damping_integration"] == "explicit" and t["head_collision"] is False
    assert t["calf_collision"] is False
    assert t["thigh_collision"] is False
    assert t["contact_timeconst_s"] == 0.02  # go2.xml's solref (env.robot.contact_timeconst 0)


def test_cli_export_with_the_wall_rule_writes_it_into_the_sidecar(policy_file, tmp_path):
    """`--observation`: the sidecar's height map carries the rule and says the policy did not
    train with it; the graph is the same."""
    plain, ruled = tmp_path / "plain.onnx", tmp_path / "ruled.onnx"
    assert cli.main(["export", "--checkpoint", str(policy_file), "--onnx", str(plain),
                     "--no-verify"]) == 0
    assert cli.main(["export", "--checkpoint", str(policy_file), "--onnx", str(ruled),
                     "--no-verify", "--observation", "height_map.occlusion_samples=16",
                     "height_map.sensor_height=0.05"]) == 0
    side0, side = (json.loads((tmp_path / f"{n}.onnx.json").read_text())
                   for n in ("plain", "ruled"))
    assert side0["height_map"]["occlusion"] is None
    assert side0["policy"]["observation_overrides"] == []
    occ = side["height_map"]["occlusion"]
    assert (occ["samples"], occ["sensor_height_m"]) == (16, 0.05)
    assert side["policy"]["observation_overrides"] == ["height_map.occlusion_samples=16",
                                                       "height_map.sensor_height=0.05"]
    assert side["policy"]["config"]["env"]["height_map"]["occlusion_samples"] == 16
    assert plain.read_bytes() == ruled.read_bytes()
    # the contract (the robot side) reads the rule from this sidecar alone
    from mjx_stairs.tools import contract
    assert contract.load_contract(ruled).hm_occlusion == 16


def test_cli_export_with_the_robots_kd_writes_it_and_the_trained_gains(policy_file, tmp_path):
    """`--pd kd=VALUE`: the sidecar's PD law carries the robot's damping gain, says what the
    policy trained with, and the robot side (the contract) runs it; the graph is the same."""
    plain, damped = tmp_path / "plain.onnx", tmp_path / "damped.onnx"
    assert cli.main(["export", "--checkpoint", str(policy_file), "--onnx", str(plain),
                     "--no-verify"]) == 0
    assert cli.main(["export", "--checkpoint", str(policy_file), "--onnx", str(damped),
                     "--no-verify", "--pd", "kd=2.5"]) == 0
    side0, side = (json.loads((tmp_path / f"{n}.onnx.json").read_text())
                   for n in ("plain", "damped"))
    kp, kd = side0["pd"]["kp"], side0["pd"]["kd"]
    trained = {"kp": kp, "kd": kd, "kd_per_delay_s": 0.0}
    assert kd != 2.5 and side0["pd"]["trained"] == trained
    assert side0["policy"]["pd_overrides"] == []
    assert (side["pd"]["kp"], side["pd"]["kd"], side["pd"]["kd_per_delay_s"]) == (kp, 2.5, 0.0)
    assert side["pd"]["trained"] == trained
    assert side["policy"]["pd_overrides"] == ["robot.kd=2.5"]
    assert plain.read_bytes() == damped.read_bytes()
    from mjx_stairs.tools import contract
    c = contract.load_contract(damped)
    q, qd = np.zeros(12), np.full(12, 0.1)
    np.testing.assert_allclose(contract.pd_torque(c, q, q, qd), -0.25 * np.ones(12))
    np.testing.assert_allclose(contract.pd_torque(c, q, q, qd, delay_s=0.02), -0.25)  # no rise
    # the damping scheduled by the robot's measured delay: kd + kd_per_delay * delay
    scheduled = tmp_path / "scheduled.onnx"
    assert cli.main(["export", "--checkpoint", str(policy_file), "--onnx", str(scheduled),
                     "--no-verify", "--pd", "kd_per_delay=75"]) == 0
    side = json.loads((tmp_path / "scheduled.onnx.json").read_text())
    assert (side["pd"]["kd"], side["pd"]["kd_per_delay_s"]) == (kd, 75.0)
    assert side["pd"]["trained"] == trained and "kd_per_delay_s" in side["pd"]["law"]
    c = contract.load_contract(scheduled)
    for delay_s in (0.0, 0.02):
        np.testing.assert_allclose(contract.pd_torque(c, q, q, qd, delay_s=delay_s),
                                   -0.1 * (kd + 75.0 * delay_s), rtol=1e-12)


@pytest.mark.parametrize("flag,item,why", [
    ("--observation", "height_map.size=11", "expected KEY=VALUE with KEY one of"),
    ("--observation", "robot.joint_damping=2.0", "expected KEY=VALUE with KEY one of"),
    ("--observation", "height_map.occlusion_samples", "expected KEY=VALUE with KEY one of"),
    ("--observation", "height_map.occlusion_samples=many", "occlusion_samples"),
    ("--pd", "kp=20", "expected KEY=VALUE with KEY one of kd"),
    ("--pd", "kd", "expected KEY=VALUE with KEY one of kd"),
    ("--pd", "kd=-1", "kd must be a finite number >= 0"),
    ("--pd", "kd=soft", "kd must be a finite number >= 0"),
    ("--pd", "kd_per_delay=-75", "kd_per_delay must be a finite number >= 0"),
    ("--pd", "kd=nan", "kd must be a finite number >= 0"),
])
def test_cli_export_refuses_a_setting_it_cannot_carry(policy_file, tmp_path, capsys, flag, item,
                                                      why):
    """`--observation` takes only observation settings, `--pd` only a finite kd >= 0."""
    code = cli.main(["export", "--checkpoint", str(policy_file), "--onnx",
                     str(tmp_path / "p.onnx"), flag, item])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("mjx-stairs export: error:")
    assert why in err[0]
    assert not (tmp_path / "p.onnx").exists()
