"""Several processes through jax.distributed on this machine's CPU: two processes of two host
devices each train exactly as one process with four; a checkpoint of one process resumes in two,
and one of two processes in one process with one device."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import jax
import numpy as np
import pytest

from mjx_stairs.rl import checkpoint, distributed, runner
from tests.mjx_stairs.rl import distributed_run
from tests.mjx_stairs.rl.toy_env import PointReach

ROOT = Path(__file__).resolve().parents[3]
ROBOTS, STEPS, ITERATIONS = 16, 8, 2


def test_settings_from_env():
    assert distributed.settings_from_env({}) is None
    ours = {"MJX_STAIRS_COORDINATOR": "h:1", "MJX_STAIRS_NUM_PROCESSES": "2",
            "MJX_STAIRS_PROCESS_ID": "1", "JAX_PROCESS_ID": "0"}
    assert distributed.settings_from_env(ours) == {"coordinator": "h:1", "num_processes": 2,
                                                   "process_id": 1}
    jax_names = {"JAX_COORDINATOR_ADDRESS": "h:2", "JAX_NUM_PROCESSES": "4",
                 "JAX_PROCESS_ID": "3"}
    assert distributed.settings_from_env(jax_names) == {"coordinator": "h:2",
                                                        "num_processes": 4, "process_id": 3}
    # a coordinator alone: JAX's cluster detection supplies the rest
    assert distributed.settings_from_env({"JAX_COORDINATOR_ADDRESS": "h:3"}) == {
        "coordinator": "h:3"}
    with pytest.raises(ValueError, match="without MJX_STAIRS_COORDINATOR"):
        distributed.settings_from_env({"MJX_STAIRS_PROCESS_ID": "1"})
    with pytest.raises(ValueError, match="MJX_STAIRS_NUM_PROCESSES='two' is not an integer"):
        distributed.settings_from_env({"MJX_STAIRS_COORDINATOR": "h:1",
                                       "MJX_STAIRS_NUM_PROCESSES": "two"})


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("localhost", 0))
        return s.getsockname()[1]


def _start(out: Path, devices: int, *args: str, **variables: str) -> subprocess.Popen:
    out.mkdir(parents=True, exist_ok=True)
    env = {k: v for k, v in os.environ.items() if not k.startswith(("MJX_STAIRS_", "JAX_"))}
    env.update(PYTHONPATH=str(ROOT), JAX_PLATFORMS="cpu",
               XLA_FLAGS=f"{os.environ.get('XLA_FLAGS', '')} "  # the session's (conftest.py)
               f"--xla_force_host_platform_device_count={devices}", **variables)
    log = (out / f"log_{variables.get('MJX_STAIRS_PROCESS_ID', 0)}.txt").open("w")
    return subprocess.Popen([sys.executable, "-m", "tests.mjx_stairs.rl.distributed_run",
                             str(out), *args], cwd=ROOT, env=env, stdout=log,
                            stderr=subprocess.STDOUT)


def _wait(procs: list[subprocess.Popen], root: Path) -> None:
    try:
        codes = [p.wait(timeout=400) for p in procs]
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
    logs = "".join(f.read_text()[-2000:] for f in sorted(root.glob("*/log_*.txt")))
    assert codes == [0] * len(procs), logs


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The same run twice: one process with four devices ("one"), then two processes with two
    devices each through a localhost coordinator ("two"), which also resume from the first
    run's checkpoint after iteration 1 ("two/resumed")."""
    root = tmp_path_factory.mktemp("distributed")
    _wait([_start(root / "one", 4)], root)
    port, start = str(_free_port()), str(_checkpoint_path(root / "one", 1))
    _wait([_start(root / "two", 2, start, MJX_STAIRS_COORDINATOR=f"localhost:{port}",
                  MJX_STAIRS_NUM_PROCESSES="2", MJX_STAIRS_PROCESS_ID=str(i)) for i in (0, 1)],
          root)
    return root


def _facts(out: Path, process: int) -> dict:
    return json.loads((out / f"process_{process}.json").read_text())


def _checkpoint_path(out: Path, iteration: int, run: str = "run") -> Path:
    return checkpoint.checkpoint_path(out / run / "checkpoints", iteration)


def _checkpoint(out: Path, iteration: int, run: str = "run") -> tuple[dict, dict]:
    return checkpoint.load(_checkpoint_path(out, iteration, run))


def _assert_close(a: dict, b: dict, rtol: float, atol: float) -> None:
    assert sorted(a) == sorted(b)
    for k in a:
        np.testing.assert_allclose(np.asarray(a[k], np.float64), np.asarray(b[k], np.float64),
                                   rtol=rtol, atol=atol, err_msg=k)


def test_two_processes_train_as_one_with_four_devices(runs):
    one, p0, p1 = _facts(runs / "one", 0), _facts(runs / "two", 0), _facts(runs / "two", 1)
    assert (one["process_count"], one["devices"], one["mesh_devices"]) == (1, 4, 4)
    for i, p in enumerate((p0, p1)):
        assert (p["process_index"], p["process_count"]) == (i, 2)
        assert (p["devices"], p["local_devices"], p["mesh_devices"]) == (4, 2, 4)
        # MJX's default device is process 0's: the robot model must lie on each one's own
        assert p["robot_model_addressable"]
    assert p0["records"] == p1["records"]  # both processes see the same global metrics
    assert [r["iteration"] for r in p0["records"]] == [1, 2]
    for a, b in zip(one["records"], p0["records"], strict=True):
        _assert_close(a, b, rtol=1e-5, atol=1e-6)
    # process 0 alone wrote the run directory; only it logged
    lines = (runs / "two" / "run" / "metrics.jsonl").read_text().splitlines()
    assert [json.loads(x)["iteration"] for x in lines] == [1, 2]
    # the checkpoints hold the global arrays: every robot, the whole normaliser count
    (s1, meta1), (s2, meta2) = _checkpoint(runs / "one", 2), _checkpoint(runs / "two", 2)
    assert meta1["processes"] == 1 and meta2["processes"] == 2
    assert s2[".ep_return"].shape == (ROBOTS,)
    for stream in ("state", "privileged_state"):
        count = s2[f".normalizer['{stream}'].count"]
        assert count == ROBOTS * STEPS * ITERATIONS  # over all robots of both processes
    _assert_close(s1, s2, rtol=1e-5, atol=1e-6)  # params, Adam, normaliser, env state, rng


def test_a_two_process_checkpoint_resumes_in_one_process(runs, tmp_path):
    """Resumed from iteration 1 of the two-process run on this process's one device, the
    second iteration reproduces the two-process one (up to the order of float sums)."""
    assert len(jax.devices()) == 1
    cfg = distributed_run.config(tmp_path)
    start = _checkpoint_path(runs / "two", 1)
    resumed = runner.run(cfg, PointReach(map_shape=(5, 5)), run_dir=tmp_path / "run",
                         resume=start)
    assert int(resumed.state.iteration) == ITERATIONS and resumed.stop_reason == "total_iterations"
    mine, _ = _checkpoint(tmp_path, 2)
    theirs, _ = _checkpoint(runs / "two", 2)
    _assert_close(mine, theirs, rtol=1e-3, atol=1e-4)
    record = json.loads((tmp_path / "run" / "metrics.jsonl").read_text().splitlines()[-1])
    two = _facts(runs / "two", 0)["records"][-1]
    _assert_close({k: record[k] for k in two}, two, rtol=1e-3, atol=1e-4)


def test_a_one_process_checkpoint_resumes_in_two_processes(runs):
    """Each of the two processes builds its devices' part of the global state from the file
    (put_global); the second iteration then matches the one-process run's."""
    p0, p1 = _facts(runs / "two", 0), _facts(runs / "two", 1)
    assert p0["resumed_records"] == p1["resumed_records"]
    assert [r["iteration"] for r in p0["resumed_records"]] == [2]
    _assert_close(p0["resumed_records"][0], _facts(runs / "one", 0)["records"][1], rtol=1e-5,
                  atol=1e-6)
    resumed, meta = _checkpoint(runs / "two", 2, "resumed")
    assert meta["processes"] == 2
    _assert_close(resumed, _checkpoint(runs / "one", 2)[0], rtol=1e-5, atol=1e-6)
