"""play: a CPU rollout through the CLI, its MCAP read back, its video read back, bad inputs."""

from __future__ import annotations

import base64
import dataclasses
import types

import jax
import mujoco
import numpy as np
import pytest

from mjx_stairs import cli
from mjx_stairs.env import observation
from mjx_stairs.rl import networks, normalizer
from mjx_stairs.rl import policy as policy_lib
from mjx_stairs.sim import robot as rb
from mjx_stairs.study.experiment import ExperimentConfig
from mjx_stairs.tools import mcap_log, play

ROBOTS, SECONDS, W, H = 2, 1.0, 160, 120
FRAMES = 50  # SECONDS / 0.02
ARGS = ["--family", "straight", "--level", "3", "--robots", str(ROBOTS), "--seconds",
        str(SECONDS), "--resolution", "0.05", "--seed", "3"]

N_VEC, MAP = observation.N_VEC, (21, 21)  # the default height map
D = N_VEC + MAP[0] * MAP[1]


@pytest.fixture(scope="module")
def policy_file(tmp_path_factory):
    """A fresh (untrained) policy whose actions are of order 1, so the robots move."""
    cfg = ExperimentConfig()
    params = networks.init_params(jax.random.PRNGKey(0), cfg.network, N_VEC, MAP, 12)
    params["actor"][-1]["w"] = params["actor"][-1]["w"] * 30.0
    norm = {k: normalizer.init_stats(D) for k in policy_lib.OBS_KEYS}
    path = tmp_path_factory.mktemp("play") / "policy.npz"
    policy_lib.save_policy(path, params, norm, 0, cfg, networks.ObsLayout(N_VEC, MAP))
    return path


@pytest.fixture(scope="module")
def played(policy_file, tmp_path_factory):
    """`mjx-stairs play` with --video and --mcap; the Rollout it recorded is captured."""
    out = tmp_path_factory.mktemp("out")
    captured = {}
    real_rollout, real_make_env = play.rollout, play.make_play_env

    def spy_rollout(*a, **k):
        captured["rollout"] = real_rollout(*a, **k)
        return captured["rollout"]

    def spy_env(*a, **k):
        captured["env"] = real_make_env(*a, **k)
        return captured["env"]

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(play, "rollout", spy_rollout)
        mp.setattr(play, "make_play_env", spy_env)
        code = cli.main(["play", "--checkpoint", str(policy_file), *ARGS,
                         "--video", str(out / "v.mp4"), "--mcap", str(out / "r.mcap"),
                         "--width", str(W), "--height", str(H)])
    assert code == 0
    return types.SimpleNamespace(dir=out, video=out / "v.mp4", mcap=out / "r.mcap",
                                 rollout=captured["rollout"], env=captured["env"])


@pytest.fixture(scope="module")
def log(played):
    return mcap_log.read_mcap(played.mcap)


def test_rollout_shapes_and_consistency(played):
    r = played.rollout
    assert r.num_frames == FRAMES and r.num_robots == ROBOTS and r.dt == pytest.approx(0.02)
    assert r.qpos.shape == (FRAMES, ROBOTS, 19) and r.obs.shape == (FRAMES, ROBOTS, D)
    assert np.isfinite(r.qpos).all() and np.isfinite(r.reward).all()
    # the observation of each frame belongs to that frame's qpos
    np.testing.assert_allclose(r.obs[..., 9:21], r.qpos[..., 7:] - rb.NOMINAL_JOINT_POS,
                               atol=1e-5)
    # the reward is the sum of the logged terms; the robots moved
    np.testing.assert_allclose(r.reward, sum(r.terms.values()), rtol=1e-4, atol=1e-6)
    assert np.abs(np.diff(r.qpos[:, :, 7:], axis=0)).max() > 1e-2
    assert set(np.unique(r.tile)) == {0}  # one tile: the family and level asked for
    assert played.env.families == ("straight",) and played.env.num_levels == 1


def test_mcap_topics_and_counts(played, log):
    per_step = ["/tf"] + [t for i in range(ROBOTS) for t in mcap_log.robot_topics(i)]
    assert set(log) == set(per_step) | {"/terrain", "/robot_model"}
    for topic in per_step:
        assert len(log[topic]) == FRAMES, topic
        times = [t for t, _ in log[topic]]
        assert times == [round((k + 1) * 0.02 * 1e9) for k in range(FRAMES)], topic
    assert len(log["/terrain"]) == 1 and len(log["/robot_model"]) == 1


def test_mcap_schemas_are_foxglove_types(played):
    from mcap.reader import make_reader

    with open(played.mcap, "rb") as f:
        summary = make_reader(f).get_summary()
    schemas = {s.id: s for s in summary.schemas.values()}
    by_topic = {c.topic: (c, schemas[c.schema_id]) for c in summary.channels.values()}
    want = {"/tf": "foxglove.FrameTransforms", "/terrain": "foxglove.SceneUpdate",
            "/robot0/goal": "foxglove.PoseInFrame", "/robot0/path": "foxglove.PosesInFrame",
            "/robot1/height_map": "foxglove.Grid"}
    for topic, name in want.items():
        channel, schema = by_topic[topic]
        assert schema.name == name and schema.encoding == "jsonschema"
        assert channel.message_encoding == "json"
    assert summary.statistics.message_count == (1 + 8 * ROBOTS) * FRAMES + 2


def _conform(msg, schema, where="") -> list[str]:
    """Where `msg` breaks its JSON schema (types, known keys, array items, min/max items)."""
    kind = schema.get("type")
    types_ = {"object": dict, "array": list, "string": str, "boolean": bool,
              "integer": int, "number": (int, float)}
    if kind and (not isinstance(msg, types_[kind]) or (kind in ("integer", "number")
                                                       and isinstance(msg, bool))):
        return [f"{where}: {type(msg).__name__} is not {kind}"]
    bad = []
    if kind == "object":
        props = schema.get("properties", {})
        bad += [f"{where}.{k}: not in the schema" for k in msg if k not in props]
        for k, v in msg.items():
            if k in props:
                bad += _conform(v, props[k], f"{where}.{k}")
    elif kind == "array":
        if not schema.get("minItems", 0) <= len(msg) <= schema.get("maxItems", len(msg)):
            bad.append(f"{where}: {len(msg)} items")
        for i, v in enumerate(msg[:50]):
            bad += _conform(v, schema["items"], f"{where}[{i}]")
    return bad


def test_mcap_messages_fit_their_schemas(played):
    import json

    from mcap.reader import make_reader

    seen = set()
    with open(played.mcap, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            if channel.topic in seen:
                continue
            seen.add(channel.topic)
            problems = _conform(json.loads(message.data), json.loads(schema.data))
            assert not problems, (channel.topic, problems[:5])
    assert len(seen) == 3 + 8 * ROBOTS  # /tf, /terrain, /robot_model, 8 per robot


def test_mcap_poses_equal_the_rollout(played, log):
    r = played.rollout
    f32 = lambda v: np.asarray(v, np.float32)
    for i in range(ROBOTS):
        base = [next(t for t in m["transforms"] if t["child_frame_id"] == f"robot{i}/base")
                for _, m in log["/tf"]]
        pos = f32([[t["translation"][a] for a in "xyz"] for t in base])
        quat = f32([[t["rotation"][a] for a in "wxyz"] for t in base])
        np.testing.assert_array_equal(pos, r.qpos[:, i, :3])
        np.testing.assert_array_equal(quat, r.qpos[:, i, 3:7])
        last = f32([[m["poses"][-1]["position"][a] for a in "xyz"]
                    for _, m in log[f"/robot{i}/path"]])
        np.testing.assert_array_equal(last, r.qpos[:, i, :3])
        joints = [m for _, m in log[f"/robot{i}/joint_states"]]
        assert joints[0]["name"] == list(rb.JOINT_NAMES)
        np.testing.assert_array_equal(f32([m["position"] for m in joints]), r.qpos[:, i, 7:])
        np.testing.assert_array_equal(f32([m["velocity"] for m in joints]), r.qvel[:, i, 6:])
        np.testing.assert_array_equal(f32([m["effort"] for m in joints]), r.torque[:, i])
        goal = f32([[m["pose"]["position"][a] for a in "xyz"] for _, m in log[f"/robot{i}/goal"]])
        np.testing.assert_array_equal(goal, r.goal[:, i, :3])


def test_mcap_leg_transforms_follow_mujoco_kinematics(played, log):
    """Chaining world -> base -> hip -> thigh -> calf from /tf lands on MuJoCo's calf pose."""
    model = played.env.robot.mj_model
    data = mujoco.MjData(model)
    for k in (0, FRAMES // 2, FRAMES - 1):
        tf = {t["child_frame_id"]: t for t in log["/tf"][k][1]["transforms"]}
        data.qpos[:] = played.rollout.qpos[k, 1]
        mujoco.mj_kinematics(model, data)
        for leg in rb.LEGS:
            pos, quat = np.zeros(3), np.array([1.0, 0, 0, 0])
            for body in ("base", f"{leg}_hip", f"{leg}_thigh", f"{leg}_calf"):
                t = tf[f"robot1/{body}"]
                p = np.array([t["translation"][a] for a in "xyz"])
                q = np.array([t["rotation"][a] for a in "wxyz"])
                rot = np.empty(9)
                mujoco.mju_quat2Mat(rot, quat)
                pos = pos + rot.reshape(3, 3) @ p
                out = np.empty(4)
                mujoco.mju_mulQuat(out, quat, q)
                quat = out
            b = model.body(f"{leg}_calf").id
            np.testing.assert_allclose(pos, data.xpos[b], atol=1e-5)
            np.testing.assert_allclose(np.abs(quat @ data.xquat[b]), 1.0, atol=1e-5)


def test_mcap_rewards_contacts_height_map(played, log):
    r = played.rollout
    for i in range(ROBOTS):
        rewards = [m for _, m in log[f"/robot{i}/reward"]]
        assert set(rewards[0]) == {"timestamp", "total", *r.terms}
        for term, series in r.terms.items():
            np.testing.assert_array_equal(np.float32([m[term] for m in rewards]), series[:, i])
        np.testing.assert_array_equal(np.float32([m["total"] for m in rewards]), r.reward[:, i])
        feet = [[m[leg] for leg in rb.LEGS] for _, m in log[f"/robot{i}/foot_contacts"]]
        np.testing.assert_array_equal(np.array(feet), r.foot_contact[:, i])
        grids = [m for _, m in log[f"/robot{i}/height_map"]]
        assert grids[0]["column_count"] == 21 and grids[0]["cell_size"]["x"] == 0.2
        values = np.stack([np.frombuffer(base64.b64decode(g["data"]), "<f4") for g in grids])
        np.testing.assert_array_equal(values, r.obs[:, i, N_VEC:])
        status = [m for _, m in log[f"/robot{i}/status"]]
        np.testing.assert_array_equal([m["done"] for m in status], r.done[:, i] > 0)


def test_mcap_path_restarts_with_each_episode(played, tmp_path):
    """After an auto-reset (episode step 0) the path holds only the new episode's poses."""
    r = dataclasses.replace(played.rollout, step=played.rollout.step.copy())
    r.step[20:, 0] = np.arange(FRAMES - 20)  # robot 0: a new episode starts at frame 20
    mcap_log.write_mcap(tmp_path / "r.mcap", played.env, r)
    paths = [m["poses"] for _, m in mcap_log.read_mcap(tmp_path / "r.mcap")["/robot0/path"]]
    lengths = [len(p) for p in paths]
    assert lengths[19] == 5 and lengths[20] == 1 and lengths[25] == 2  # every 0.1 s + current
    first = np.float32([paths[-1][0]["position"][a] for a in "xyz"])
    np.testing.assert_array_equal(first, r.qpos[20, 0, :3])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.mcap"]


def test_mcap_terrain_mesh(played, log):
    (_, update), = log["/terrain"]
    (tri,) = update["entities"][0]["triangles"]
    pts = np.array([[p["x"], p["y"], p["z"]] for p in tri["points"]])
    idx = np.array(tri["indices"])
    assert len(idx) % 3 == 0 and idx.max() < len(pts) and len(tri["colors"]) == len(pts)
    env = played.env
    hf = env.terrain.heights()
    assert pts[:, 2].max() == pytest.approx(hf.max(), abs=1e-3)  # the top landing is there
    assert pts[:, 0].max() == pytest.approx((env.atlas_shape[1] - 0.5) * env.resolution)


def test_video_frame_count_size_and_content(played):
    import imageio.v3 as iio

    frames = iio.imread(played.video)
    assert frames.shape == (FRAMES, H, W, 3) and frames.dtype == np.uint8
    assert iio.immeta(played.video)["fps"] == pytest.approx(50.0)
    assert frames.std() > 10  # not a blank image
    # the video shows the rollout: frame k is close to a fresh render of qpos[k] and far from a
    # render of the robot moved 0.5 m
    r, env = played.rollout, played.env
    k = FRAMES - 1
    q = r.qpos[k, 0].copy()
    moved = q.copy()
    moved[0] += 0.5
    own, other = play.render_frames(env.robot.mj_model, np.stack([q, moved]), W, H,
                                    goal=r.goal[k, 0])
    err_own = np.abs(frames[k].astype(float) - own).mean()
    err_other = np.abs(frames[k].astype(float) - other).mean()
    assert err_own < 6.0 and err_other > 2 * err_own


def test_video_subsampled_fps(played, tmp_path):
    import imageio.v3 as iio

    n = play.render_video(played.env, played.rollout, tmp_path / "v25.mp4", 1, W, H, fps=25)
    frames = iio.imread(tmp_path / "v25.mp4")
    assert n == FRAMES // 2 and frames.shape == (FRAMES // 2, H, W, 3)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["v25.mp4"]  # no temp file left


def test_gl_backend_is_offscreen():
    assert play.ensure_gl() in ("egl", "osmesa", "glfw", "default")


def test_no_temp_files_left(played):
    assert sorted(p.name for p in played.dir.iterdir()) == ["r.mcap", "v.mp4"]


@pytest.mark.parametrize(
    "case, extra, message",
    [
        ("missing", [], "checkpoint file not found"),
        ("corrupt", [], "corrupt or unreadable checkpoint"),
        ("ok", ["--family", "zigzag"], "unknown terrain family 'zigzag'"),
        ("ok", ["--level", "9"], "level 9 out of range"),
        ("ok", ["--robots", "0"], "robots must be >= 1"),
        ("ok", ["--video", "x.mp4", "--width", "161"], "video size must be even"),
    ],
)
def test_bad_inputs_one_line_errors(policy_file, tmp_path, capsys, case, extra, message):
    ck = {"missing": tmp_path / "nope.npz", "corrupt": tmp_path / "bad.npz",
          "ok": policy_file}[case]
    if case == "corrupt":
        ck.write_bytes(b"not a checkpoint")
    args = ["play", "--checkpoint", str(ck), "--seconds", "0.1", "--resolution", "0.1"]
    code = cli.main(args + extra)
    err = capsys.readouterr().err.strip().splitlines()
    err = [line for line in err if "warp" not in line]  # mujoco's note about the optional warp
    assert code == 2
    assert len(err) == 1 and err[0].startswith("mjx-stairs play: error:") and message in err[0]


def test_a_policy_trained_with_a_bf16_encoder_loads_in_float32(policy_file, tmp_path):
    """conv_impl 'fused_bf16' is a training setting: the loaded policy computes in float32
    (the same actions as the policy saved with the default conv_impl), and its metadata still
    says what it trained with."""
    cfg = ExperimentConfig()
    cfg = dataclasses.replace(cfg, network=dataclasses.replace(cfg.network,
                                                               conv_impl="fused_bf16"))
    ref = policy_lib.load_policy(policy_file)
    path = tmp_path / "bf16.npz"
    policy_lib.save_policy(path, ref.params, ref.normalizer, 0, cfg,
                           networks.ObsLayout(N_VEC, MAP))
    pol = policy_lib.load_policy(path)
    assert pol.network.conv_impl == "auto" and pol.metadata["network"]["conv_impl"] == "fused_bf16"
    obs = jax.random.normal(jax.random.PRNGKey(2), (4, D))
    np.testing.assert_array_equal(policy_lib.policy_action(pol, obs),
                                  policy_lib.policy_action(ref, obs))


def test_play_on_a_mesh(policy_file, tmp_path, capsys):
    """play --mesh: the rollout runs on the imported staircase (the robots start at --start, the
    goal is --goal, in the atlas frame), and the MCAP names the mesh."""
    import trimesh
    from mcap.reader import make_reader

    floor = trimesh.creation.box((3.0, 2.0, 0.2))
    floor.apply_translation((0.0, 0.0, -0.1))
    floor.export(tmp_path / "floor.stl")
    out = tmp_path / "r.mcap"
    code = cli.main(["play", "--checkpoint", str(policy_file),
                     "--mesh", str(tmp_path / "floor.stl"), "--start", "-0.6,0", "--goal",
                     "0.6,0", "--robots", "1", "--seconds", "0.1", "--resolution", "0.1",
                     "--mcap", str(out)])
    assert code == 0
    assert "floor: 1 robots" in capsys.readouterr().out
    with open(out, "rb") as f:
        meta = {m.name: m.metadata for m in make_reader(f).iter_metadata()}["mjx_stairs"]
    assert meta["staircase"] == "floor"
    log = mcap_log.read_mcap(out)
    assert len(log["/terrain"]) == 1
