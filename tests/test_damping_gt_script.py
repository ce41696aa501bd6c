"""experiments/damping_gt.py's configs: damping, its integration, a fixed action delay and MJX's
Newton iterations, and the grid of docs/deploy.md."""

import importlib.util
from pathlib import Path

import pytest

from mjx_stairs.env.config import env_config_from

EVAL = "robot.physics=evaluation"

ROOT = Path(__file__).resolve().parents[1]
spec = importlib.util.spec_from_file_location("damping_gt", ROOT / "experiments/damping_gt.py")
damping_gt = importlib.util.module_from_spec(spec)
spec.loader.exec_module(damping_gt)


def test_a_config_names_damping_integration_and_delay():
    assert damping_gt.overrides("d2") == ("robot.joint_damping=2.0",
                                          "robot.implicit_damping=false")
    assert damping_gt.overrides("d0.5i_l15") == ("robot.joint_damping=0.5",
                                                 "robot.implicit_damping=true",
                                                 "robot.action_delay_s=0.015")
    # applied after the evaluation physics (eval_env), whose 8 Newton iterations implicit damping
    # needs (sim.robot.IMPLICIT_MIN_ITERATIONS)
    robot = env_config_from(None, (EVAL, *damping_gt.overrides("d0.5i_l15"))).robot
    assert (robot.joint_damping, robot.implicit_damping) == (0.5, True)
    assert robot.action_delay_s == pytest.approx(0.015)
    # _n<iterations>: MJX's Newton iterations, after the delay or alone
    n30 = env_config_from(None, (EVAL, *damping_gt.overrides("d2i_l20_n30"))).robot
    assert (n30.solver_iterations, n30.joint_damping, n30.action_delay_s) == (30, 2.0, 0.02)
    assert env_config_from(None, (EVAL, *damping_gt.overrides("d2i"))).robot.solver_iterations == 8
    # _c<contacts>: the columns collider's contacts a sphere, no env override
    assert damping_gt.parse("d2i_c3") == (damping_gt.overrides("d2i"), 3)
    assert damping_gt.parse("d2i_l20")[1] is None


def test_the_grid_is_damping_by_delay_and_every_cell_is_a_valid_env():
    assert len(damping_gt.GRID) == len(set(damping_gt.GRID)) == 20
    assert damping_gt.GRID[0] == "d0.1i" and damping_gt.GRID[-1] == "d2i_l20"
    delays = {env_config_from(None, (EVAL, *damping_gt.overrides(c))).robot.action_delay_s
              for c in damping_gt.GRID}
    assert sorted(round(d, 3) for d in delays) == [0.0, 0.005, 0.01, 0.015, 0.02]


@pytest.mark.parametrize("bad", ["x2", "d", "dfoo", "d2i_l", "d2i_lx", "d2i_n", "d2i_n2.5",
                                 "d2i_q3", "d2i_c1", "d2i_c"])
def test_a_bad_config_is_a_one_line_error(bad):
    with pytest.raises(SystemExit, match=f"config '{bad}': expected") as e:
        damping_gt.overrides(bad)
    assert "\n" not in str(e.value)


def test_n_gives_the_ground_truth_mjx_budget_and_nothing_else_changes_its_solver():
    from mjx_stairs.sim import box_world as bw

    assert damping_gt.gt_solver("d2i") == bw.DEFAULT_SOLVER
    assert damping_gt.gt_solver("d2i_l20_c3") == bw.DEFAULT_SOLVER
    s = damping_gt.gt_solver("d2i_n8")
    assert (s.iterations, s.ls_iterations) == (8, 10)
    assert s.tolerance == bw.DEFAULT_SOLVER.tolerance
