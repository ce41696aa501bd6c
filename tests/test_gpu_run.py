"""experiments/gpu/run.sh, the GPU host's step runner: valid bash, and its header names every step
its case statement runs (issue 20: the one-off session scripts became named steps)."""

import re
import shutil
import subprocess
from pathlib import Path

import pytest

RUN = Path(__file__).resolve().parents[1] / "experiments" / "gpu" / "run.sh"


@pytest.mark.skipif(shutil.which("bash") is None, reason="no bash")
def test_run_sh_parses():
    subprocess.run(["bash", "-n", str(RUN)], check=True)


def test_header_names_every_step():
    text = RUN.read_text()
    header = " ".join(line[1:] for line in text.split("set -uo pipefail")[0].splitlines()
                      if line.startswith("#"))
    body = text.split("run_step() {")[1]
    steps = set()
    for pattern in re.findall(r"^    ([a-z0-9|-]+)\)", body, flags=re.M):
        steps.update(pattern.split("|"))
    assert {"fidelity", "ground-truth", "sim2sim", "transfer-eval", "rq1-eval"} <= steps
    missing = sorted(s for s in steps if not re.search(rf"(?<![\w-]){re.escape(s)}(?![\w-])",
                                                       header))
    assert not missing, f"steps missing from run.sh's header: {missing}"


@pytest.mark.skipif(shutil.which("bash") is None, reason="no bash")
def test_gpu_groups_run_their_steps_pinned_with_their_variables(tmp_path):
    """gpuN:... arguments run in the background, each on its own GPU with its own variables,
    and the script waits for them before it ends."""
    env = {"PATH": "/usr/bin:/bin", "SKIP_INSTALL": "1", "OUT": str(tmp_path),
           "HOME": str(tmp_path)}
    run = subprocess.run(["bash", str(RUN), "60", "gpu0:SEED=7,gpus", "gpu1:gpus,no-such-step",
                          "gpu2+3:gpus"],
                         env=env, capture_output=True, text=True, timeout=120, cwd=RUN.parents[2])
    logs = {n: (tmp_path / "logs" / f"gpu{n}.log").read_text() for n in (0, 1, "2+3")}
    assert "CUDA_VISIBLE_DEVICES=2,3 SEED=unset" in logs["2+3"], logs["2+3"]  # two GPUs
    assert "CUDA_VISIBLE_DEVICES=0 SEED=7" in logs[0], logs[0]
    assert "CUDA_VISIBLE_DEVICES=1 SEED=unset" in logs[1], logs[1]
    assert "unknown step no-such-step" in logs[1]
    assert "gpuN: group" not in logs[1]
    assert "== gpu0: gpus done" in logs[0] and "== gpu1: gpus done" in logs[1]
    assert "== gpu1.log:" in run.stdout  # waited for, and its log shown


def _python_call(tmp_path, step: str, variables: dict, marker: str) -> str:
    """run.sh's STEP with VARIABLES, python3 a stand-in that records its arguments: the one
    recorded call containing MARKER."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    calls = tmp_path / "calls.txt"
    (bin_dir / "python3").write_text(f'#!/bin/sh\necho "$@" >> {calls}\n')
    (bin_dir / "python3").chmod(0o755)
    env = {"PATH": f"{bin_dir}:/usr/bin:/bin", "SKIP_INSTALL": "1", "OUT": str(tmp_path / "out"),
           "HOME": str(tmp_path), **variables}
    subprocess.run(["bash", str(RUN), "200", step], env=env, capture_output=True,
                   text=True, timeout=60, cwd=RUN.parents[2], check=True)
    (call,) = [c for c in calls.read_text().splitlines() if marker in c]
    return call


@pytest.mark.skipif(shutil.which("bash") is None, reason="no bash")
@pytest.mark.parametrize("variables, expected", [
    ({"CODE_POLICIES": "a+b=x.npz", "CODE_MESH": "c"},
     "--steps suite,mesh --policies a,b=x.npz --mesh-policies c"),
    ({"CODE_POLICIES": "a"}, "--steps suite --policies a"),
    ({"CODE_MESH": "c+d"}, "--steps mesh --mesh-policies c,d"),
    ({"CODE_POLICIES": "a", "CODE_ENV": "k=1+j=2"}, "--policies a --env k=1 j=2"),
])
def test_code_suite_step_runs_every_step_asked_for(tmp_path, variables, expected):
    """code-suite passes one --steps for both CODE_POLICIES and CODE_MESH (two --steps flags
    ran the last one only, 2026-11-27), and CODE_ENV's overrides as one --env. python3 is a
    stand-in that records its arguments."""
    call = _python_call(tmp_path, "code-suite", variables, "code_suite.py")
    assert call.endswith(expected), call


@pytest.mark.skipif(shutil.which("bash") is None, reason="no bash")
@pytest.mark.parametrize("variables, expected", [
    ({"FIDELITY_OPTIONS": "evaluation_stiff", "FIDELITY_CELLS": "5+6+17"},
     "--options evaluation_stiff --cells 5,6,17"),
    ({}, "--options evaluation --cells "),  # unset: every cell (run.sh runs under set -u)
])
def test_fidelity_step_passes_its_cells(tmp_path, variables, expected):
    """fidelity passes FIDELITY_CELLS as fidelity.py's comma list (a gpuN: token cannot hold a
    comma; 2026-11-28 the a+b form reached fidelity.py unconverted). python3 records its
    arguments."""
    call = _python_call(tmp_path, "fidelity", variables, "fidelity.py mjx")
    assert call.endswith(expected), call


@pytest.mark.skipif(shutil.which("bash") is None, reason="no bash")
def test_wait_policy_waits_for_a_run_published_in_this_command(tmp_path):
    """A group's wait-policy step returns once another group's run is published
    (/tmp/policies/NAME.npz written after the command started), and gives up near the deadline
    when none comes; a file from before the command does not count."""
    import os
    import time
    import uuid

    env = {"PATH": "/usr/bin:/bin", "SKIP_INSTALL": "1", "OUT": str(tmp_path / "out"),
           "HOME": str(tmp_path)}
    name = f"test_wait_{uuid.uuid4().hex[:8]}"
    f = Path("/tmp/policies") / f"{name}.npz"
    f.parent.mkdir(exist_ok=True)
    try:
        f.write_bytes(b"old")
        os.utime(f, (time.time() - 3600, time.time() - 3600))  # an earlier command's
        run = subprocess.Popen(["bash", str(RUN), "120", f"gpu0:WAIT_POLICY={name},wait-policy"],
                               env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                               text=True, cwd=RUN.parents[2])
        time.sleep(8)
        assert run.poll() is None  # the old file did not count
        f.write_bytes(b"new")
        run.communicate(timeout=60)
        log = (tmp_path / "out" / "logs" / "gpu0.log").read_text()
        assert f"{f} is in" in log, log
        late = subprocess.run(["bash", str(RUN), "64", "gpu0:WAIT_POLICY=no_such_run,wait-policy"],
                              env=env, capture_output=True, text=True, timeout=60,
                              cwd=RUN.parents[2])
        assert late.returncode == 0
        assert "no new /tmp/policies/no_such_run.npz in time" in (
            tmp_path / "out" / "logs" / "gpu0.log").read_text()
    finally:
        f.unlink(missing_ok=True)


@pytest.mark.skipif(shutil.which("bash") is None, reason="no bash")
def test_a_failed_training_is_reported_and_the_next_steps_run(tmp_path):
    """A training that exits non-zero (a config error, a diverged update) is said in one line,
    nothing is copied from it, and the command goes on. python3 is a stand-in whose `-m
    mjx_stairs train` fails."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    (bin_dir / "python3").write_text(
        '#!/bin/sh\ncase "$*" in *"mjx_stairs train"*) echo "mjx-stairs train: error: '
        'training diverged" >&2; exit 2;; esac\nexit 0\n')
    (bin_dir / "python3").chmod(0o755)
    env = {"PATH": f"{bin_dir}:/usr/bin:/bin", "SKIP_INSTALL": "1", "OUT": str(tmp_path / "out"),
           "HOME": str(tmp_path)}
    run = subprocess.run(["bash", str(RUN), "200", "stage1", "gpus"], env=env,
                         capture_output=True, text=True, timeout=60, cwd=RUN.parents[2])
    assert "training diverged" in run.stdout
    assert "== stage1: train failed (2); nothing published, no state copied" in run.stdout
    assert "cp:" not in run.stdout + run.stderr and "Traceback" not in run.stdout
    assert "== gpus done" in run.stdout


@pytest.mark.skipif(shutil.which("bash") is None, reason="no bash")
def test_a_training_step_run_again_resumes_from_what_it_kept(tmp_path):
    """On a warm machine the same training step in the next command resumes from the state the
    first one kept, and its curve holds both commands' rows; FRESH=1 starts over. python3 is a
    stand-in trainer that writes a state, a policy and one metrics row per call."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    (bin_dir / "python3").write_text(
        '#!/bin/sh\ncase "$*" in *"mjx_stairs train"*)\n'
        '  echo "ARGS $*"\n'
        '  pub=$(echo "$*" | sed -n "s/.*publish_dir=\\([^ ]*\\).*/\\1/p")\n'
        '  n=$(ls -d "$RUNS"/stage1__* 2>/dev/null | wc -l)\n'
        '  mkdir -p "$pub" "$RUNS/stage1__$n/checkpoints"\n'
        '  echo "state $n" > "$RUNS/stage1__$n/checkpoints/state_1.npz"\n'
        '  echo policy > "$pub/policy.npz"\n'
        '  echo "{\\"row\\": $n}" > "$pub/metrics.jsonl";;\nesac\nexit 0\n')
    (bin_dir / "python3").chmod(0o755)
    env = {"PATH": f"{bin_dir}:/usr/bin:/bin", "SKIP_INSTALL": "1", "HOME": str(tmp_path),
           "RUNS": str(tmp_path / "runs"), "KEEP": str(tmp_path / "keep")}

    def command(i, **extra):
        out = tmp_path / f"out{i}"
        run = subprocess.run(["bash", str(RUN), "200", "stage1"], env={**env, **extra,
                             "OUT": str(out)}, capture_output=True, text=True, timeout=60,
                             cwd=RUN.parents[2])
        return run.stdout, out / "stage1"

    first, out1 = command(1)
    assert "--resume" not in first
    assert (tmp_path / "keep" / "stage1" / "state.npz").read_text() == "state 0\n"
    second, out2 = command(2)
    assert f"--resume {tmp_path}/keep/stage1/state.npz" in second
    assert (out2 / "metrics.jsonl").read_text().split() == ['{"row":', '0}', '{"row":', '1}']
    assert (tmp_path / "keep" / "stage1" / "state.npz").read_text() == "state 1\n"
    third, _ = command(3, FRESH="1")
    assert "--resume" not in third


@pytest.mark.skipif(shutil.which("bash") is None, reason="no bash")
@pytest.mark.parametrize("variables, gpu_call", [
    ({}, "--mjx --mjx-column robot="),  # the two default MJX columns on the GPU first
    ({"S2S_MJX": "0"}, None),  # MuJoCo only: the GPU is left to the trainings
    ({"S2S_MJX": "0", "S2S_ARGS": "--mjx-column+wall=k=1"}, "--mjx-column wall=k=1"),
])
def test_sim2sim_policy_runs_mjx_only_when_a_column_is_asked_and_resumes_a_folder(
        tmp_path, variables, gpu_call):
    """sim2sim-policy: the --mjx-only GPU call runs when an MJX column is asked for (S2S_MJX=0
    drops the two default ones), the CPU run in the background always, and S2S_FROM's cells and
    columns are where that run looks for what is done (its out folder, brought back in $OUT).
    python3 is a stand-in that records its arguments."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    calls = tmp_path / "calls.txt"
    (bin_dir / "python3").write_text(f'#!/bin/sh\necho "$@" >> {calls}\n')
    (bin_dir / "python3").chmod(0o755)
    earlier = tmp_path / "earlier"
    (earlier / "cells").mkdir(parents=True)
    (earlier / "cells" / "code_x.json").write_text("{}")
    (earlier / "mjx_wall_code.json").write_text("{}")
    env = {"PATH": f"{bin_dir}:/usr/bin:/bin", "SKIP_INSTALL": "1", "OUT": str(tmp_path / "out"),
           "HOME": str(tmp_path), "S2S_POLICY": "p", "S2S_CELLS": "code",
           "S2S_FROM": str(earlier), **variables}
    subprocess.run(["bash", str(RUN), "200", "sim2sim-policy"], env=env, capture_output=True,
                   text=True, timeout=60, cwd=RUN.parents[2], check=True)
    lines = calls.read_text().splitlines()
    mjx_only = [c for c in lines if "--mjx-only" in c]
    (cpu,) = [c for c in lines if "sim2sim_table.py" in c and "--mjx-only" not in c]
    assert "--cells code" in cpu and "--workers 14" in cpu
    if gpu_call is None:
        assert not mjx_only and "--mjx" not in cpu, lines
    else:
        assert len(mjx_only) == 1 and gpu_call in mjx_only[0], lines
    out = tmp_path / "out" / "sim2sim" / "p_up"
    assert (out / "cells" / "code_x.json").exists() and (out / "mjx_wall_code.json").exists()


@pytest.mark.skipif(shutil.which("bash") is None, reason="no bash")
def test_a_variable_token_outside_a_group_says_where_it_belongs(tmp_path):
    """KEY=VALUE,step outside a gpuN: group is not a step: run.sh stops before any GPU work and
    says to put it in a group (a device call lost to this on 2026-12-01)."""
    env = {"PATH": "/usr/bin:/bin", "SKIP_INSTALL": "1", "OUT": str(tmp_path),
           "HOME": str(tmp_path)}
    run = subprocess.run(["bash", str(RUN), "60", "SEED=7,gpus"], env=env, capture_output=True,
                         text=True, timeout=120, cwd=RUN.parents[2])
    assert run.returncode == 2
    assert "unknown step SEED=7,gpus" in run.stdout
    assert "gpu0:SEED=7,gpus" in run.stdout
