"""The `mjx-stairs` command: train, eval, critic-map, input-use, bench, exp1, terrain, play,
export, sim2sim, sim2sim-gaps."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
import typing
from pathlib import Path
from typing import Any

from mjx_stairs.config import ConfigError
from mjx_stairs.rl.checkpoint import CheckpointError
from mjx_stairs.study import scorecard
from mjx_stairs.study.cli_flags import flag_cases, glued_poses, mesh_flags
from mjx_stairs.study.specs import EvalSpec
from mjx_stairs.tools import sim2sim_cli
from mjx_stairs.tools.specs import PlaySpec


def _csv_ints(text: str) -> tuple[int, ...]:
    try:
        return tuple(int(t) for t in text.split(",") if t.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated integers, got {text!r}"
        ) from None


def add_spec_flags(parser: argparse.ArgumentParser, cls: type, exclude: tuple[str, ...] = (),
                   **defaults: Any) -> None:
    """One flag per field of the spec dataclass ``cls`` (all but ``exclude``): the name from
    the field's ``flag`` metadata or its own name, its type, help and default (``defaults``
    overrides; a ``one_based`` field is shown 1-based)."""
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        if f.name in exclude:
            continue
        meta, tp = f.metadata, hints[f.name]
        default = defaults.get(f.name, f.default)
        flag = meta.get("flag", "--" + f.name.replace("_", "-"))
        kw: dict[str, Any] = {"dest": f.name, "help": meta.get("help", ""),
                              "metavar": meta.get("metavar", flag[2:].upper().replace("-", "_"))}
        if typing.get_origin(tp) is typing.Literal:
            kw["metavar"] = None
            kw["choices"] = typing.get_args(tp)
        elif tp == tuple[int, ...]:
            kw["type"] = _csv_ints
        elif tp == tuple[str, ...]:
            kw["nargs"] = "+"
        else:
            kw["type"] = tp
        if meta.get("one_based"):
            default = tuple(v + 1 for v in default) if isinstance(default, tuple) else default + 1
        kw["default"] = list(default) if kw.get("nargs") else default
        kw["help"] += f" (default {default})" if default not in ((), "") else ""
        parser.add_argument(flag, **kw)


def spec_from(cls: type, args: argparse.Namespace, **extra: Any) -> Any:
    """The spec dataclass of the parsed flags (add_spec_flags) and ``extra`` fields."""
    kwargs = {}
    for f in dataclasses.fields(cls):
        if f.name in extra or not hasattr(args, f.name):
            continue
        v = getattr(args, f.name)
        if f.metadata.get("one_based"):
            v = tuple(x - 1 for x in v) if isinstance(v, tuple) else v - 1
        kwargs[f.name] = tuple(v) if isinstance(v, list) else v
    return cls(**kwargs, **extra)


def cmd_train(args: argparse.Namespace) -> int:
    from mjx_stairs.rl import distributed

    distributed.initialize_from_env()  # several processes (MJX_STAIRS_COORDINATOR etc.): first
    from mjx_stairs.rl import runner
    from mjx_stairs.study import experiment

    config, cpu = experiment.load(args.config, args.overrides)
    if cpu and distributed.is_main():
        print(
            f"[mjx-stairs] no GPU: running the CPU preset of {args.config} "
            f"({config.train.num_envs} robots, {config.train.total_iterations} iterations); "
            "the full run needs a GPU",
            flush=True,
        )
    env = experiment.make_env(config)
    result = runner.run(config, env, run_dir=args.run_dir, resume=args.resume)
    if config.publish_dir and distributed.is_main():
        experiment.publish(result.run_dir, config.publish_dir, result.metrics, result.stop_reason)
        print(f"[mjx-stairs] published to {config.publish_dir}", flush=True)
    return 0


def cmd_exp1_report(args: argparse.Namespace) -> int:
    from mjx_stairs.study import exp1

    exp1.report(args.stage2, args.out, args.ablation, spec_from(EvalSpec, args))
    return 0


def cmd_curves(args: argparse.Namespace) -> int:
    from mjx_stairs.study import plots

    runs = {}
    for item in args.run:
        name, sep, path = item.partition("=")
        runs[name if sep else Path(item).name] = path if sep else item
    plots.plot_curves(runs, args.out)  # a missing or broken file: main's one-line error
    print(f"wrote {args.out}")
    return 0


def cmd_input_use(args: argparse.Namespace) -> int:
    from mjx_stairs.rl.policy import load_policy
    from mjx_stairs.study import input_use

    print(input_use.markdown(input_use.input_use(load_policy(args.checkpoint), args.samples)))
    return 0


def cmd_exp1(args: argparse.Namespace) -> int:
    from mjx_stairs.study import exp1

    exp1.run_pipeline(force=args.force, robots=args.robots, overrides=tuple(args.overrides))
    return 0


def cmd_transfer(args: argparse.Namespace) -> int:
    from mjx_stairs.study import transfer

    spec = spec_from(EvalSpec, args)
    if args.config is None:  # the whole experiment: train what is missing, then the matrix
        transfer.run_pipeline(spec, force=args.force)
        return 0
    result = transfer.matrix(transfer.load_models(args.config), spec, args.out,
                             rows=args.rows, columns=args.columns)
    if "cells" in result:  # a part of the matrix: its cells only
        for src, row in result["cells"].items():
            for dst, rec in row.items():
                print(f"{src} on {dst}: " + " / ".join(f"{100 * s:.1f}" for s in rec["success"]),
                      flush=True)
        return 0
    print(transfer.markdown(result), flush=True)
    return 0


def cmd_eval(args: argparse.Namespace) -> int:
    from mjx_stairs.study import evaluate

    spec = spec_from(EvalSpec, args)
    found = flag_cases(args, spec.resolution)
    if found is None:
        evaluate.evaluate(args.checkpoint, args.families, spec, args.out)
        return 0
    from mjx_stairs.study import cases

    cases.evaluate_cases(args.checkpoint, found, spec, args.out, source=args.mesh or args.suite)
    return 0


def cmd_critic_map(args: argparse.Namespace) -> int:
    from mjx_stairs.rl.policy import load_policy
    from mjx_stairs.study import critic_map, plots

    found = flag_cases(args, args.resolution)
    policy = load_policy(args.checkpoint)
    if found is not None:
        m = critic_map.critic_map_of_tile(policy, found[0][1], EvalSpec(
            robots_per_level=1, resolution=args.resolution))
        title = f"critic value, {found[0][0]}"
    else:
        m = critic_map.critic_map(policy, args.family, args.level - 1, args.variant,
                                  resolution=args.resolution)
        title = f"critic value, {args.family} test level {args.level}"
    plots.plot_critic_map(m, args.out, title)
    print(f"wrote {args.out}")
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    from mjx_stairs.atomic import write_text
    from mjx_stairs.study import bench, experiment

    config, _ = experiment.load(args.config, args.overrides, cpu=False)
    default_parts = "physics,train" if args.devices else ",".join(bench.PARTS)
    parts = tuple((args.parts or default_parts).split(","))
    if args.devices:  # scaling rows over the first N devices
        out = bench.run_scaling(config, list(args.devices), per_device=args.per_device,
                                total=args.total, scalings=tuple(args.scaling.split(",")),
                                steps=args.steps, repeats=args.repeats, parts=parts)
    else:
        out = bench.run_bench(config, list(args.robots or (4096, 16384)), steps=args.steps,
                              repeats=args.repeats, parts=parts)
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        write_text(args.out, json.dumps(out, indent=2))
        print(f"wrote {args.out}")
    return 0


def cmd_terrain(args: argparse.Namespace) -> int:
    from terrains.__main__ import main as terrains_main

    return int(terrains_main(args.rest) or 0)


def cmd_play(args: argparse.Namespace) -> int:
    from mjx_stairs.tools import play

    spec = spec_from(PlaySpec, args)
    found = flag_cases(args, spec.resolution)
    try:
        play.play(args.checkpoint, spec, video=args.video, mcap=args.mcap, width=args.width,
                  height=args.height, fps=args.fps, case=None if found is None else found[0])
    except play.RenderError as e:
        print(f"mjx-stairs play: error: {e}", file=sys.stderr)
        return 2
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    from mjx_stairs.tools import export

    return export.export_command(args.checkpoint, args.onnx, check=args.verify,
                                 observation=args.observation, pd=args.pd)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="mjx-stairs", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True)
    _add_train_and_eval(sub)
    _add_studies(sub)
    _add_tools(sub)
    return p


def _add_train_and_eval(sub) -> None:

    t = sub.add_parser("train", help="train from an experiment TOML")
    t.add_argument("config", help="experiments/*.toml")
    t.add_argument("overrides", nargs="*", help="key.sub=value overrides")
    t.add_argument(
        "--resume",
        nargs="?",
        const=True,
        default=False,
        metavar="STATE_FILE",
        help="continue the newest run of this experiment, or from a checkpoint file (e.g. one "
        "carried from another machine)",
    )
    t.add_argument("--run-dir", default=None, help="run directory (default: a new one)")
    t.set_defaults(fn=cmd_train)

    e = sub.add_parser("eval", help="success rate per (checkpoint, family, level)")
    e.add_argument("--checkpoint", nargs="+", required=True, help="policy.npz file(s)")
    e.add_argument("--family", nargs="+", dest="families", default=["u_shaped"],
                   help="stair families")
    add_spec_flags(e, EvalSpec, exclude=("family",))
    mesh_flags(e, suite=True)
    e.add_argument("--out", default=None, help="families: directory for results.json and "
                   "results.md; --mesh / --suite: the JSON file (one record per case)")
    e.set_defaults(fn=cmd_eval)

    c = sub.add_parser("critic-map", help="the critic's value over a tile (paper Fig. 4)")
    c.add_argument("--checkpoint", required=True)
    c.add_argument("--family", default="u_shaped")
    c.add_argument("--level", type=int, default=3, help="1-based test level")
    c.add_argument("--variant", type=int, default=0)
    c.add_argument("--resolution", type=float, default=0.025)
    mesh_flags(c)
    c.add_argument("--out", required=True, help="PNG path")
    c.set_defaults(fn=cmd_critic_map)

    u = sub.add_parser("input-use", help="how much a policy reads each observation term")
    u.add_argument("--checkpoint", required=True)
    u.add_argument("--samples", type=int, default=512)
    u.set_defaults(fn=cmd_input_use)

    b = sub.add_parser("bench", help="physics / env / training throughput")
    b.add_argument("--config", default="experiments/stage2_u.toml")
    b.add_argument("overrides", nargs="*")
    b.add_argument("--robots", type=int, nargs="+", default=None,
                   help="robot counts over all devices (default 4096 16384)")
    b.add_argument("--devices", type=_csv_ints, default=(), metavar="N,N,...",
                   help="scaling rows over the first N devices for each N (e.g. 1,2,4,8), "
                   "weak and strong; --robots is then not used")
    b.add_argument("--per-device", type=int, default=4096, help="weak scaling: robots per device")
    b.add_argument("--total", type=int, default=16384, help="strong scaling: robots in all")
    b.add_argument("--scaling", default="weak,strong", help="weak, strong or both")
    b.add_argument("--steps", type=int, default=24)
    b.add_argument("--repeats", type=int, default=5)
    b.add_argument("--parts", default=None,
                   help="of physics,env,rollout,train (default: all; physics,train with "
                   "--devices)")
    b.add_argument("--out", default=None, help="JSON path")
    b.set_defaults(fn=cmd_bench)


def _add_studies(sub) -> None:
    x = sub.add_parser("exp1-report", help="the paper's EXP1: Fig. 2, stall ablation, Fig. 4")
    x.add_argument("--stage2", required=True, help="stage-2 policy.npz")
    x.add_argument(
        "--ablation", default=None, help="stage-2 policy trained without the stall penalty"
    )
    add_spec_flags(x, EvalSpec, exclude=("family", "schedule", "levels", "env_overrides",
                                         "direction"))
    x.add_argument("--out", required=True, help="output directory")
    x.set_defaults(fn=cmd_exp1_report)

    cv = sub.add_parser("curves", help="training curves (success, level, return) of runs")
    cv.add_argument(
        "run", nargs="+", help="NAME=DIR or DIR: a published run directory or metrics.jsonl"
    )
    cv.add_argument("--out", required=True, help="PNG path")
    cv.set_defaults(fn=cmd_curves)

    p1 = sub.add_parser("exp1", help="main job: stage 1, stage 2, ablation, EXP1 report")
    p1.add_argument("overrides", nargs="*", help="key.sub=value overrides for every stage")
    p1.add_argument("--force", action="store_true", help="retrain stages already published")
    p1.add_argument("--robots", type=int, default=None, help="robots per level in the report")
    p1.set_defaults(fn=cmd_exp1)

    m = sub.add_parser("transfer-matrix", help="every model on every stair family (Tables 1-2)")
    m.add_argument(
        "--config",
        default=None,
        help="TOML with a [models] table (e.g. experiments/transfer_matrix.toml); "
        "without it, train the missing models first",
    )
    m.add_argument("--force", action="store_true", help="retrain models already published")
    add_spec_flags(m, EvalSpec, exclude=("family", "schedule"), levels=(2, 3))
    m.add_argument("--out", default="experiments/results/transfer")
    m.add_argument("--rows", nargs="+", default=(), metavar="MODEL",
                   help="only these models' cells (written to OUT/cells/; a later run without "
                   "--rows/--columns assembles the matrix from them)")
    m.add_argument("--columns", nargs="+", default=(), metavar="FAMILY",
                   help="only the cells on these families")
    m.set_defaults(fn=cmd_transfer)


def _add_tools(sub) -> None:
    tr = sub.add_parser("terrain", help="the terrains CLI (preview, export, import)")
    tr.add_argument("rest", nargs=argparse.REMAINDER)
    tr.set_defaults(fn=cmd_terrain)

    pl = sub.add_parser("play", help="roll out a policy: mp4 video and/or MCAP for Foxglove")
    pl.add_argument("--checkpoint", required=True, help="policy.npz")
    add_spec_flags(pl, PlaySpec)
    mesh_flags(pl)
    pl.add_argument("--video", default=None, help="mp4 path (robot 0, tracking camera)")
    pl.add_argument("--mcap", default=None, help="MCAP path (all robots)")
    pl.add_argument("--width", type=int, default=640)
    pl.add_argument("--height", type=int, default=480)
    pl.add_argument("--fps", type=float, default=50.0, help="video fps (<= 50: subsampled)")
    pl.set_defaults(fn=cmd_play)

    ex = sub.add_parser("export", help="policy -> ONNX (normaliser + CNN + actor) + JSON sidecar")
    ex.add_argument("--checkpoint", required=True, help="policy.npz")
    ex.add_argument("--onnx", required=True, help="output .onnx (sidecar: <path>.json)")
    ex.add_argument(
        "--no-verify", dest="verify", action="store_false", help="skip the onnxruntime vs JAX check"
    )
    ex.add_argument("--observation", nargs="*", default=[], metavar="KEY=VALUE",
                    help="what the robot's perception gives beyond training, listed in the "
                         "sidecar: height_map.occlusion_samples (the wall rule), "
                         "height_map.sensor_height")
    ex.add_argument("--pd", nargs="*", default=[], metavar="KEY=VALUE",
                    help="the robot's PD gains where they differ from training, listed in the "
                         "sidecar: kd (adds to the joints' damping), kd_per_delay (its rise "
                         "per s of the robot's action delay; docs/deploy.md)")
    ex.set_defaults(fn=cmd_export)
    sim2sim_cli.add_parser(sub)
    scorecard.add_parser(sub)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(glued_poses(sys.argv[1:] if argv is None else argv))
    t0 = time.time()
    try:
        code = args.fn(args)
    except (ConfigError, CheckpointError, FileNotFoundError, ValueError) as e:
        print(f"mjx-stairs {args.command}: error: {e}", file=sys.stderr)
        return 2
    if args.command in ("train", "eval", "bench"):
        print(f"[mjx-stairs] {args.command} done in {time.time() - t0:.0f} s", flush=True)
    return code


if __name__ == "__main__":
    sys.exit(main())
