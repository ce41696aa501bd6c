"""experiments/damping_climb_probe.py (issue 25): sim2sim's robot at another joint damping, and
one recorded episode's joint and motor facts."""

import json
import sys
from pathlib import Path

import mujoco
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "experiments"))
import damping_climb_probe as probe  # noqa: E402

from mjx_stairs.sim.robot import JOINT_NAMES  # noqa: E402


def test_the_robot_copy_has_the_damping_on_every_leg_joint(tmp_path):
    model = mujoco.MjModel.from_xml_path(str(probe.robot_with_damping(0.5, tmp_path)))
    ours = mujoco.MjModel.from_xml_path(str(probe.sw.OUR_ROBOT))
    for name in JOINT_NAMES:
        dof = model.joint(name).dofadr[0]
        assert model.dof_damping[dof] == 0.5 and ours.dof_damping[dof] == 2.0
    np.testing.assert_array_equal(model.body_mass, ours.body_mass)


def test_a_short_probe_writes_each_damping_and_its_facts(tmp_path):
    onnx = ROOT / "experiments/results/generalist_d2/policy.onnx"
    probe.main([str(tmp_path), "--onnx", str(onnx), "--dampings", "0.1,2", "--episodes", "1",
                "--episode-s", "0.3"])
    rows = (tmp_path / "code_commercial_straight_up.md").read_text().splitlines()
    assert [r.split("|")[1].strip() for r in rows[2:]] == ["0.1", "2"]
    for d in ("0.1", "2"):
        r = json.loads((tmp_path / f"code_commercial_straight_up_d{d}.json").read_text())
        assert r["damping"] == float(d) and len(r["records"]) == 1
        m = r["means"]
        assert m["success"] == 0.0  # 0.3 s is too short to climb a flight
        for k in ("still", "action_at_clip", "thigh_torque_at_limit", "calf_torque_at_limit"):
            assert 0.0 <= m[k] <= 1.0
        assert m["calf_joint_speed_rad_s"] > 0.0  # the legs moved
