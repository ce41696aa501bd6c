"""`mjx-stairs bench --devices`: weak and strong scaling rows, each part split over the devices
it names (two forced host devices here), and the efficiencies computed from the rows."""

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from mjx_stairs import cli
from mjx_stairs.study import bench

ROOT = Path(__file__).resolve().parents[3]
TINY = ["terrain.resolution=0.05", "terrain.variants_per_family=1", "terrain.levels=[0]"]

SCRIPT = textwrap.dedent("""
    import json
    import jax
    from mjx_stairs.study import bench, experiment
    assert len(jax.devices()) == 2, jax.devices()
    config, _ = experiment.load("experiments/stage2_u.toml", {tiny!r}, cpu=False)
    out = bench.run_scaling(config, [2], per_device=2, total=4, parts=("physics",), steps=2,
                            repeats=1)
    print("RESULT " + json.dumps(out))
""")


def test_scaling_rows_run_on_the_devices_they_name():
    """Two devices, weak (2 per device) and strong (4 in all): one row measured once (an MJX
    compile takes ~20-45 s on this CPU), its physics split over both devices."""
    env = dict(os.environ, PYTHONPATH=str(ROOT), JAX_PLATFORMS="cpu",
               XLA_FLAGS=os.environ.get("XLA_FLAGS", "")  # the session's (conftest.py)
               + " --xla_force_host_platform_device_count=2")
    proc = subprocess.run([sys.executable, "-c", SCRIPT.format(tiny=TINY)], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=400)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    out = json.loads(proc.stdout.split("RESULT ", 1)[1])
    rows = [(r["scaling"], r["devices"], r["robots"]) for r in out["results"]]
    assert rows == [("weak", 2, 4), ("strong", 2, 4)]
    weak, strong = out["results"]
    assert weak["physics"] == strong["physics"]  # measured once
    assert weak["physics"]["devices_used"] == 2  # physics-only split over both devices
    assert weak["physics"]["steps_per_s"] > 0
    assert (out["per_device"], out["total"], out["devices"]) == (2, 4, 2)
    assert [(s["scaling"], s["physics_efficiency"]) for s in out["scaling"]] == [
        ("weak", None), ("strong", None)]  # no one-device row to compare with


def _row(scaling, devices, robots, train, physics, compile_s=40.0):
    return {"scaling": scaling, "devices": devices, "robots": robots,
            "train": {"steps_per_s": train, "compile_s": compile_s},
            "physics": {"steps_per_s": physics}}


def test_efficiency_is_rate_over_n_times_one_device():
    rows = [_row("weak", 1, 4096, 400.0, 1000.0), _row("strong", 1, 16384, 500.0, 1200.0),
            _row("weak", 2, 8192, 720.0, 2000.0, 55.0), _row("strong", 2, 16384, 800.0, 2400.0),
            _row("strong", 4, 16384, 1000.0, 4000.0)]
    got = {(s["scaling"], s["devices"]): s for s in bench.efficiency(rows)}
    assert got[("weak", 2)]["train_efficiency"] == pytest.approx(0.9)
    assert got[("weak", 2)]["physics_efficiency"] == pytest.approx(1.0)
    assert got[("weak", 2)]["train_compile_s"] == 55.0
    assert got[("strong", 2)]["train_efficiency"] == pytest.approx(0.8)
    assert got[("strong", 4)]["train_efficiency"] == pytest.approx(0.5)
    assert bench.efficiency(rows[2:3])[0]["train_efficiency"] is None  # no one-device row


def test_bench_devices_errors_are_one_line(capsys):
    assert cli.main(["bench", "--devices", "1,2", *TINY]) == 2  # one CPU device here
    err = capsys.readouterr().err
    assert "--devices [1, 2], but 1 devices are visible" in err
    assert len(err.strip().splitlines()) == 1
    assert cli.main(["bench", "--devices", "1", "--scaling", "wide", *TINY]) == 2
    assert "scalings ['wide']" in capsys.readouterr().err
