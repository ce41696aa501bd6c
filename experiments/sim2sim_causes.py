"""Issue 25: what makes a policy fail in sim2sim where MJX says it climbs, one change at a time.

    JAX_PLATFORMS=cpu PYTHONPATH=. python experiments/sim2sim_causes.py OUT \
        --onnx experiments/results/generalist/policy.onnx --cells up6,up5 \
        --variants full,euler_explicit,no_head --episodes 50 --workers 2

Each variant is one edit of the sim2sim robot (mjx_stairs/sim/assets/go2_full.xml: full collision
geometry, the Go2 description's joint damping 2, armature 0.01, friction loss 0.2, implicitfast,
MuJoCo's default solver), written to OUT/robots/<variant>.xml and passed to `mjx-stairs sim2sim`
as `--robot`; or the training MJCF (assets/go2.xml: collision spheres only, semi-implicit Euler
with the damping explicit, one Newton iteration) with one edit. Every variant of a cell walks the
same starts (sim2sim's own, seed 0), so two variants are compared episode by episode. One JSON
per (variant, cell) under OUT/<variant>/ (skipped when there: a killed run resumes), then
OUT/table.md: success, falls and step-edge touches per variant and cell, and each variant's
paired change against `full` (starts gained minus lost).

Cells: up6 / down4 ... = U-shaped test level, direction (the family with --family). A variant
name with the suffix _d01 is that variant at joint damping 0.1 (e.g. gt_robot_head_d01); --base
names the variant that the paired changes are counted against (default full).
"""

from __future__ import annotations

import argparse
import json
import os
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import mujoco
import numpy as np

from mjx_stairs.sim.geoms import add_calf_chains, add_head, collide_like
from mjx_stairs.sim.robot import ASSET, JOINT_NAMES, LEGS

ASSETS = ASSET.parent


def _joints(spec: mujoco.MjSpec, **fields) -> None:
    for name in JOINT_NAMES:
        j = spec.joint(name)
        for k, v in fields.items():
            setattr(j, k, [v, 0.0, 0.0] if k == "damping" else v)


def _integrator(spec: mujoco.MjSpec, name: str, eulerdamp: bool = True) -> None:
    spec.option.integrator = getattr(mujoco.mjtIntegrator, f"mjINT_{name.upper()}")
    flag = int(mujoco.mjtDisableBit.mjDSBL_EULERDAMP)
    spec.option.disableflags = (spec.option.disableflags | flag if not eulerdamp
                                else spec.option.disableflags & ~flag)


def _drop_geoms(spec: mujoco.MjSpec, names) -> None:
    for name in names:
        spec.delete(spec.geom(name))


def _default_solver(spec: mujoco.MjSpec) -> None:
    spec.option.iterations, spec.option.ls_iterations = 100, 50


def _add_like(spec: mujoco.MjSpec, body: str, like: str, name: str, **fields) -> None:
    """A massless geom `name` on `body`, colliding as geom `like` does."""
    geom = spec.body(body).add_geom(name=name, density=0.0, **fields)
    collide_like(geom, spec.geom(like))


def _on_calf(spec: mujoco.MjSpec, leg: str, name: str, **fields) -> None:
    """A massless geom `name` on the leg's calf body, colliding as its capsule does."""
    _add_like(spec, f"{leg}_calf", f"{leg}_calf_col", name, **fields)


def _as_full(spec: mujoco.MjSpec) -> None:
    """go2.xml given the sim2sim robot's joints, integrator and solver (go2_full.xml's)."""
    _joints(spec, damping=2.0, frictionloss=0.2)
    _integrator(spec, "implicitfast")
    _default_solver(spec)


def _training_calves(spec: mujoco.MjSpec, parts=("knee", "shin"), chain: bool = True,
                     drop: bool = True) -> None:
    """go2_full.xml's calf capsules replaced by go2.xml's knee and mid-shin spheres and the calf
    chain (sim.geoms), colliding as the capsules did; all named *_calf_*, so that sim2sim counts
    their step-edge touches as calf touches, as the capsules' are. Or some of that: `parts` of
    go2.xml's spheres, the `chain` or not, the capsules dropped or not."""
    train = mujoco.MjSpec.from_file(str(ASSET))
    for leg in LEGS:
        for part in parts:
            src = train.geom(f"{leg}_{part}")
            _on_calf(spec, leg, f"{leg}_calf_{part}", type=src.type, size=src.size, pos=src.pos)
    if chain:
        add_calf_chains(spec, LEGS, "{leg}_calf_col")
    if drop:
        _drop_geoms(spec, CALVES)


STRAIGHT_CALF = ((0.0, 0.0, 0.0), (-0.002, 0.0, -0.19), 0.013)
"""(from, to, radius) in the calf frame of go2_full.xml's calf until 2026-11-29: one capsule on
the knee-foot axis (since then two along the link's bow, sim.geoms.CALF_SHAPE)."""


def _dense_calves(spec: mujoco.MjSpec, n: int = 15, parts=()) -> None:
    """Each calf replaced by `n` spheres of the straight capsule's radius along its axis
    (STRAIGHT_CALF), spaced less than a radius apart: that capsule's shape as spheres (with
    go2.xml's `parts`, e.g. its mid-shin sphere, r 0.018 and 4 mm ahead of the axis, named
    *_calf_*)."""
    _training_calves(spec, parts, chain=False, drop=False)
    a, b, r = (np.asarray(v) for v in STRAIGHT_CALF)
    for leg in LEGS:
        for i, t in enumerate(np.linspace(0.0, 1.0, n)):
            _on_calf(spec, leg, f"{leg}_calf_dense{i}", type=mujoco.mjtGeom.mjGEOM_SPHERE,
                     size=[float(r), 0.0, 0.0], pos=(a + t * (b - a)).tolist())
    _drop_geoms(spec, CALVES)


def _straight_calves(spec: mujoco.MjSpec) -> None:
    """Each calf's two capsules replaced by the one straight capsule of STRAIGHT_CALF."""
    a, b, r = STRAIGHT_CALF
    for leg in LEGS:
        _on_calf(spec, leg, f"{leg}_calf_straight", type=mujoco.mjtGeom.mjGEOM_CAPSULE,
                 size=[r, 0.0, 0.0], fromto=[*a, *b])
    _drop_geoms(spec, CALVES)


def _training_trunk(spec: mujoco.MjSpec) -> None:
    """go2_full.xml's trunk box and head replaced by training's trunk group: go2.xml's four
    corner spheres and the head sphere of robot.head_collision (sim.geoms.HEAD), colliding as
    the box did."""
    train = mujoco.MjSpec.from_file(str(ASSET))
    for corner in ("fl", "fr", "rl", "rr"):
        src = train.geom(f"trunk_{corner}")
        _add_like(spec, "base", "trunk", f"trunk_{corner}", type=src.type, size=src.size,
                  pos=src.pos)
    add_head(spec)
    _drop_geoms(spec, ("trunk", *HEAD))


HEAD = ("trunk_head_upper", "trunk_head_lower")
CALVES = tuple(f"{leg}_calf_col{s}" for leg in LEGS for s in ("", "_lower"))
THIGHS = tuple(f"{leg}_thigh_col" for leg in LEGS)
HIPS = tuple(f"{leg}_hip_col" for leg in LEGS)
VARIANTS = {  # name: (base MJCF, edit, what it changes)
    "full": ("go2_full.xml", lambda s: None, "the sim2sim robot as it is (since 2026-11-29 its "
             "calves bowed as the link, sim.geoms.CALF_SHAPE; before, `full_straight`)"),
    "damping01": ("go2_full.xml", lambda s: _joints(s, damping=0.1),
                  "joint damping 0.1 (training's MJCF)"),
    "no_frictionloss": ("go2_full.xml", lambda s: _joints(s, frictionloss=0.0),
                        "no joint friction loss (training has none)"),
    "euler": ("go2_full.xml", lambda s: _integrator(s, "euler"),
              "semi-implicit Euler, damping implicit (eulerdamp on)"),
    "euler_explicit": ("go2_full.xml", lambda s: _integrator(s, "euler", eulerdamp=False),
                       "semi-implicit Euler, damping explicit (training's integrator)"),
    "no_head": ("go2_full.xml", lambda s: _drop_geoms(s, HEAD),
                "no head geoms (training's trunk spheres do not reach the head)"),
    "spheres": ("go2.xml", _as_full, "training's collision spheres, everything else as `full`"),
    "spheres_head": ("go2.xml", lambda s: (_as_full(s), add_head(s)),
                     "`spheres` with the head sphere of robot.head_collision (training's robot "
                     "since 2026-11-27)"),
    "calf_chain": ("go2.xml", lambda s: (_as_full(s), add_calf_chains(s, LEGS)),
                   "`spheres` with the calf chains of robot.calf_collision (sim.geoms)"),
    "no_calf": ("go2_full.xml", lambda s: _drop_geoms(s, CALVES),
                "no calf capsules (the calves touch nothing; the feet still do)"),
    "full_calf_chain": ("go2_full.xml", _training_calves,
                        "each calf capsule replaced by training's calf with robot.calf_collision "
                        "(knee and mid-shin spheres of go2.xml and the chain)"),
    "full_knee": ("go2_full.xml", lambda s: _training_calves(s, ("knee",), False, False),
                  "go2.xml's knee sphere (r 0.025) added to each calf, the capsules kept"),
    "full_dense": ("go2_full.xml", _dense_calves,
                   "each calf replaced by 15 spheres along the straight capsule's axis"),
    "full_dense_shin": ("go2_full.xml", lambda s: _dense_calves(s, parts=("shin",)),
                        "`full_dense` with go2.xml's mid-shin sphere (r 0.018) on each calf"),
    "full_straight": ("go2_full.xml", _straight_calves,
                      "each calf as one straight capsule on the knee-foot axis (go2_full.xml's "
                      "calf until 2026-11-29)"),
    "full_sphere_trunk": ("go2_full.xml", _training_trunk,
                          "the trunk box and head replaced by training's trunk spheres (four "
                          "corners and the head sphere of robot.head_collision)"),
    "no_thigh": ("go2_full.xml", lambda s: _drop_geoms(s, THIGHS),
                 "no thigh capsules (training's robot has no thigh geoms)"),
    "no_hip": ("go2_full.xml", lambda s: _drop_geoms(s, HIPS),
               "no hip cylinders (training's robot has no hip geoms)"),
    "full_training_body": ("go2_full.xml", lambda s: (
        _training_trunk(s), _drop_geoms(s, THIGHS), _training_calves(s)),
        "training's trunk spheres, no thighs, training's calves with the chain: `calf_chain`'s "
        "collision but for the hip cylinders kept"),
    "gt_robot": ("go2.xml", lambda s: (_joints(s, damping=2.0), _integrator(s, "euler"),
                                       _default_solver(s)),
                 "the ground truth's robot (training's MJCF: spheres, no friction loss), damping 2 "
                 "implicit, the solver converged"),
    "gt_robot_head": ("go2.xml", lambda s: (_joints(s, damping=2.0), _integrator(s, "euler"),
                                            _default_solver(s), add_head(s)),
                      "`gt_robot` with the head sphere of robot.head_collision: training's and "
                      "the MJX evaluation's robot since 2026-11-27"),
    "gt_robot_explicit": ("go2.xml", lambda s: (_joints(s, damping=2.0), _default_solver(s)),
                          "the same with the damping explicit (training's integrator)"),
}


D01 = "_d01"
"""A variant name's suffix: the variant with every joint's damping then set to 0.1, the
evaluation physics' (the MJCF's) damping, e.g. `gt_robot_head_d01`."""


def lookup(variant: str) -> tuple[str, object, str]:
    """VARIANTS[variant], or for `<known>_d01` that variant at joint damping 0.1."""
    if variant in VARIANTS:
        return VARIANTS[variant]
    if variant.endswith(D01) and variant[:-len(D01)] in VARIANTS:
        base, edit, what = VARIANTS[variant[:-len(D01)]]
        return base, lambda s: (edit(s), _joints(s, damping=0.1)), f"{what}; joint damping 0.1"
    raise SystemExit(f"unknown variant {variant!r}; known: {', '.join(VARIANTS)} (each also "
                     f"with the suffix {D01}: joint damping 0.1)")


def write_robot(variant: str, folder: Path) -> Path:
    """OUT/robots/<variant>.xml: the variant's MJCF."""
    base, edit, _ = lookup(variant)
    spec = mujoco.MjSpec.from_file(str(ASSETS / base))
    edit(spec)
    spec.compile()  # fails here, not in a worker
    path = folder / "robots" / f"{variant}.xml"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(spec.to_xml())
    return path


def parse_cell(cell: str) -> tuple[str, int]:
    for d in ("up", "down"):
        if cell.startswith(d) and cell[len(d):].isdigit():
            return d, int(cell[len(d):])
    raise SystemExit(f"cell {cell!r}: expected up<level> or down<level>, e.g. up6")


def code_case(cell: str):
    """The `code` suite's case `cell` (its name without the suite's prefix, e.g.
    commercial_straight_up)."""
    from terrains.suites import find_case

    try:
        return find_case("code", f"code_{cell}")
    except ValueError as e:
        raise SystemExit(f"cell {cell!r}: {e}") from None


def check_cell(family: str, cell: str) -> None:
    """A bad cell name fails before anything runs."""
    code_case(cell) if family == "code" else parse_cell(cell)


def _job(args) -> str:
    onnx, family, cell, robot, out, episodes, latency, episode_s, timeconst = args
    from mjx_stairs.tools import sim2sim

    if family == "code":
        course = sim2sim.tile_course(code_case(cell).tile(), f"code_{cell}")
    else:
        direction, level = parse_cell(cell)
        course = sim2sim.family_course(family, level, "test", direction)
    r = sim2sim.run(onnx, course, sim2sim.Options(episodes=episodes, latency_ms=latency,
                                                  episode_s=episode_s,
                                                  contact_timeconst=timeconst),
                    robot=robot, out=out)
    return f"{out}: {100 * r['success']:.1f} % success, {100 * r['fell']:.1f} % falls, " \
           f"{r['wall_s']:.0f} s"


def table(folder: Path, variants: list[str], cells: list[str], base: str = "full") -> str:
    def load(v, c):
        p = folder / v / f"{c}.json"
        return json.loads(p.read_text()) if p.is_file() else None

    head = "| variant | what changes | " + " | ".join(cells) + " |"
    rows = [head, "|" + "---|" * (2 + len(cells))]
    for v in variants:
        row = []
        for c in cells:
            d, ref = load(v, c), load(base, c)
            if d is None:
                row.append("")
                continue
            s = f"{100 * d['success']:.0f} ({100 * d['fell']:.0f})"
            if ref is not None and v != base and len(ref["records"]) == len(d["records"]):
                a = np.array([r["success"] for r in ref["records"]])
                b = np.array([r["success"] for r in d["records"]])
                s += f" +{int((b & ~a).sum())}/-{int((a & ~b).sum())}"
            e = d["edge_contacts_per_episode"]
            s += f"; trunk {e['trunk']:.1f}, calf {e['calf']:.1f}"
            row.append(s)
        rows.append(f"| {v} | {lookup(v)[2]} | " + " | ".join(row) + " |")
    return "\n".join(rows) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--onnx", required=True)
    ap.add_argument("--family", default="u_shaped",
                    help="a family (cells up<level>/down<level> of its test levels), or code "
                         "(cells: the code suite's case names, e.g. commercial_straight_up)")
    ap.add_argument("--cells", default="up6")
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--episodes", type=int, default=50)
    ap.add_argument("--latency-ms", type=float, default=0.0)
    ap.add_argument("--episode-s", type=float, default=20.0, help="30 as the code suite's")
    ap.add_argument("--contact-timeconst", type=float, default=0.0,
                    help="every geom's contact solref time constant (s; 0: the MJCF's own), "
                         "0.01 as the evaluation physics since 2026-11-28")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--base", default="full",
                    help="the variant that the others' paired changes are counted against")
    a = ap.parse_args()
    variants, cells = a.variants.split(","), a.cells.split(",")
    for v in (*variants, a.base):
        lookup(v)
    if a.base not in variants:
        raise SystemExit(f"--base {a.base!r} is not one of --variants")
    for c in cells:
        check_cell(a.family, c)
    jobs = []
    for v in variants:
        robot = write_robot(v, a.out)
        (a.out / v).mkdir(parents=True, exist_ok=True)
        for c in cells:
            out = a.out / v / f"{c}.json"
            if not out.is_file():
                jobs.append((a.onnx, a.family, c, str(robot), str(out), a.episodes, a.latency_ms,
                             a.episode_s, a.contact_timeconst))
    with ProcessPoolExecutor(a.workers) as pool:
        for line in pool.map(_job, jobs):
            print(line, flush=True)
    text = table(a.out, variants, cells, a.base)
    where = "the code suite" if a.family == "code" else f"{a.family} test levels"
    contact = f"{a.contact_timeconst:g} s" if a.contact_timeconst else "the MJCF's"
    note = (f"\nsuccess % (falls %) of {a.episodes} episodes per cell ({a.episode_s:g} s), "
            f"{where}, sim2sim's starts (seed 0), latency {a.latency_ms:g} ms, contact time "
            f"constant {contact}; +gained/-lost: "
            f"starts that succeed with the variant and not with `{a.base}`, and the reverse; "
            f"trunk, calf: step-edge touches per episode. Policy: {a.onnx}.\n")
    (a.out / "table.md").write_text(text + note)
    print(text + note)


if __name__ == "__main__":
    main()
