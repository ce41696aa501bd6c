"""experiments/sim2sim_causes.py's cells: a family's test levels (up<level>/down<level>) or the
`code` suite's cases by name, a bad one refused before anything runs."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
spec = importlib.util.spec_from_file_location("sim2sim_causes",
                                              ROOT / "experiments/sim2sim_causes.py")
causes = importlib.util.module_from_spec(spec)
spec.loader.exec_module(causes)


def test_family_cells_are_direction_and_level():
    assert causes.parse_cell("up6") == ("up", 6)
    assert causes.parse_cell("down1") == ("down", 1)
    for bad in ("up", "sideways3", "up6b"):
        with pytest.raises(SystemExit, match=bad):
            causes.check_cell("u_shaped", bad)


def test_code_cells_are_the_suites_cases():
    case = causes.code_case("commercial_straight_up")
    assert (case.name, case.direction) == ("code_commercial_straight_up", "up")
    assert case.staircase.riser == pytest.approx(0.178)
    causes.check_cell("code", "residential_winder_left_down")
    with pytest.raises(SystemExit, match="commercial_ramp_up"):
        causes.check_cell("code", "commercial_ramp_up")
    with pytest.raises(SystemExit, match="up6"):  # a family cell is not a code case
        causes.check_cell("code", "up6")


def test_every_robot_variant_compiles_and_changes_collision_alone(tmp_path):
    """Each variant's MJCF loads in MuJoCo; the calf variants (one edit of go2_full.xml's calves)
    put the geoms they name on each calf, colliding with the capsule's friction."""
    import mujoco

    from mjx_stairs.sim.geoms import CALF_CHAIN_LEN

    full = mujoco.MjModel.from_xml_path(str(causes.write_robot("full", tmp_path)))
    calf = [v for v in causes.VARIANTS if v.startswith("full") or v == "no_calf"]
    assert {"full_straight", "full_dense", "full_calf_chain"} <= set(calf)
    for variant in causes.VARIANTS:
        model = mujoco.MjModel.from_xml_path(str(causes.write_robot(variant, tmp_path)))
        if variant not in calf:
            continue
        body = model.body("FL_calf").id
        geoms = [g for g in range(model.ngeom) if model.geom_bodyid[g] == body
                 and model.geom_contype[g] and "foot" not in model.geom(g).name.lower()]
        assert len(geoms) == {"no_calf": 0, "full_knee": 3, "full_straight": 1, "full_dense": 15,
                              "full_dense_shin": 16, "full_calf_chain": 2 + CALF_CHAIN_LEN,
                              "full": 2}.get(variant, len(geoms)), variant
        for g in geoms:
            assert model.geom_friction[g].tolist() == full.geom_friction[
                full.geom("FL_calf_col").id].tolist()


def test_trunk_and_thigh_variants_change_only_those_geoms(tmp_path):
    """`full_sphere_trunk` swaps the trunk box and head for training's trunk spheres (go2.xml's
    corners, robot.head_collision's head), `no_thigh` drops the thigh capsules, `no_hip` the hip
    cylinders; masses, inertias and every other colliding geom stay as in `full`;
    `full_training_body` is all of training's collision but the hips kept."""
    import mujoco

    def colliding(model):
        return {model.geom(g).name for g in range(model.ngeom) if model.geom_contype[g]}

    full = mujoco.MjModel.from_xml_path(str(causes.write_robot("full", tmp_path)))
    trunk = mujoco.MjModel.from_xml_path(str(causes.write_robot("full_sphere_trunk", tmp_path)))
    thigh = mujoco.MjModel.from_xml_path(str(causes.write_robot("no_thigh", tmp_path)))
    for m in (trunk, thigh):
        assert np.allclose(m.body_mass, full.body_mass)
        assert np.allclose(m.body_inertia, full.body_inertia)
    spheres = {f"trunk_{c}" for c in ("fl", "fr", "rl", "rr", "head")}
    assert colliding(trunk) == colliding(full) - {"trunk", *causes.HEAD} | spheres
    assert all(trunk.geom_type[trunk.geom(n).id] == mujoco.mjtGeom.mjGEOM_SPHERE for n in spheres)
    assert colliding(thigh) == colliding(full) - {f"{leg}_thigh_col" for leg in causes.LEGS}
    hips = {f"{leg}_hip_col" for leg in causes.LEGS}
    no_hip = mujoco.MjModel.from_xml_path(str(causes.write_robot("no_hip", tmp_path)))
    assert colliding(no_hip) == colliding(full) - hips
    body = colliding(mujoco.MjModel.from_xml_path(
        str(causes.write_robot("full_training_body", tmp_path))))
    assert hips | spheres <= body and not body & {"trunk", "FL_thigh_col", "FL_calf_col"}
    with_head = mujoco.MjModel.from_xml_path(str(causes.write_robot("spheres_head", tmp_path)))
    assert colliding(with_head) == colliding(mujoco.MjModel.from_xml_path(
        str(causes.write_robot("spheres", tmp_path)))) | {"trunk_head"}


def test_d01_suffix_is_the_variant_at_damping_01_and_nothing_else(tmp_path):
    """`<variant>_d01` is that variant with every joint's damping 0.1 (the evaluation physics'),
    its geoms, integrator and friction loss unchanged; `gt_robot_head` is `gt_robot` with the
    head sphere; an unknown name or suffix is refused with the known names."""
    import mujoco

    def load(v):
        return mujoco.MjModel.from_xml_path(str(causes.write_robot(v, tmp_path)))

    for variant in ("full", "gt_robot_head", "spheres_head"):
        plain, d01 = load(variant), load(variant + causes.D01)
        assert np.allclose(d01.dof_damping[6:], 0.1) and not np.allclose(plain.dof_damping[6:], 0.1)
        assert plain.ngeom == d01.ngeom and plain.opt.integrator == d01.opt.integrator
        assert np.array_equal(plain.dof_frictionloss, d01.dof_frictionloss)
    gt, head = load("gt_robot"), load("gt_robot_head")
    assert head.ngeom == gt.ngeom + 1
    assert head.geom("trunk_head").type == mujoco.mjtGeom.mjGEOM_SPHERE
    for bad in ("full_d02", "nothing_d01"):
        with pytest.raises(SystemExit, match=bad):
            causes.lookup(bad)
