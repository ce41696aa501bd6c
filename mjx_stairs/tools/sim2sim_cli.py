"""The `mjx-stairs sim2sim` command: its flags and what it runs (mjx_stairs.tools.sim2sim, imported
only when the command runs)."""

from __future__ import annotations

import argparse


def _xy(text: str) -> tuple[float, float]:
    try:
        x, y = (float(t) for t in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected X,Y (metres), got {text!r}") from None
    return x, y


def command(args: argparse.Namespace) -> int:
    from mjx_stairs.tools import sim2sim

    if (args.family is None) == (args.mesh is None):
        raise ValueError("give a staircase: --family F --level N, or --mesh FILE --start X,Y "
                         "--goal X,Y")
    if args.family is not None:
        if args.level is None:
            raise ValueError("--family needs --level N (1-based)")
        course = sim2sim.family_course(args.family, args.level, args.schedule, args.direction,
                                       args.variant, args.resolution, args.tile_size)
    else:
        if args.start is None or args.goal is None:
            raise ValueError("--mesh needs --start X,Y and --goal X,Y (mesh frame, metres)")
        course = sim2sim.mesh_course(args.mesh, args.start, args.goal, args.route,
                                     args.resolution)
    options = sim2sim.Options(
        episodes=args.episodes, seed=args.seed, episode_s=args.episode_s,
        latency_ms=args.latency_ms, noise=args.noise, push=args.push,
        push_speed=args.push_speed, push_every_s=args.push_every,
        contact_timeconst=args.contact_timeconst)
    r = sim2sim.run(args.onnx, course, options, robot=args.robot, video=args.video,
                    mcap=args.mcap, out=args.out)
    edges = ", ".join(f"{k} {v:.2f}" for k, v in r["edge_contacts_per_episode"].items())
    print(f"{course.name}: success {100 * r['success']:.1f} %, fell {100 * r['fell']:.1f} % of "
          f"{r['episodes']} episodes; step-edge contacts per episode: {edges} "
          f"({r['wall_s']:.0f} s)", flush=True)
    for path in (args.out, args.video, args.mcap):
        if path:
            print(f"wrote {path}", flush=True)
    return 0


def add_parser(sub) -> None:
    """The sim2sim subcommand of `mjx-stairs`."""
    s = sub.add_parser("sim2sim", help="an exported ONNX policy in MuJoCo itself (full "
                       "collision geometry, box stairs, observation from the sidecar alone)")
    s.add_argument("--onnx", required=True, help="policy.onnx (its sidecar: <path>.json)")
    s.add_argument("--family", default=None, help="stair family (or --mesh)")
    s.add_argument("--level", type=int, default=None, help="1-based level of the schedule")
    s.add_argument("--schedule", default="test", choices=("train", "test", "extended"))
    s.add_argument("--direction", default="up", choices=("up", "down"))
    s.add_argument("--variant", default=None, help="the family's variant (default its first)")
    s.add_argument("--mesh", default=None, help="a staircase mesh (OBJ/STL/GLB/PLY, metres)")
    s.add_argument("--start", type=_xy, default=None, metavar="X,Y", help="start (mesh frame)")
    s.add_argument("--goal", type=_xy, default=None, metavar="X,Y", help="goal (mesh frame)")
    s.add_argument("--route", type=_xy, nargs="+", default=None, metavar="X,Y",
                   help="route points from start to goal (default: the importer's route)")
    s.add_argument("--episodes", type=int, default=1)
    s.add_argument("--seed", type=int, default=0, help="seed of the starts, noise and pushes")
    s.add_argument("--episode-s", type=float, default=20.0, help="episode length (s)")
    s.add_argument("--latency-ms", type=float, default=0.0, help="action latency (ms)")
    s.add_argument("--noise", action="store_true", help="the training observation noise")
    s.add_argument("--push", action="store_true", help="planar velocity kicks to the base")
    s.add_argument("--push-speed", type=float, default=0.5, help="kick (m/s)")
    s.add_argument("--push-every", type=float, default=4.0, help="seconds between kicks")
    s.add_argument("--contact-timeconst", type=float, default=0.0, metavar="S",
                   help="every geom's contact solref time constant, robot and stairs (0: the "
                   "MJCF's, MuJoCo's default 0.02 s); the sidecar's training.contact_timeconst_s "
                   "says what the policy trained with")
    s.add_argument("--robot", default=None, help="a Go2 MJCF with Unitree's joint names and "
                   "torque motors (default: ours, mjx_stairs/sim/assets/go2_full.xml)")
    s.add_argument("--resolution", type=float, default=0.025, help="stair grid (m)")
    s.add_argument("--tile-size", type=float, default=10.0, help="family tile side (m)")
    s.add_argument("--video", default=None, help="mp4 of the first episode")
    s.add_argument("--mcap", default=None, help="MCAP of the first episode")
    s.add_argument("--out", default=None, help="results JSON")
    s.set_defaults(fn=command)

    g = sub.add_parser("sim2sim-gaps", help="a policy's MJX evaluation beside its sim2sim cells "
                       "in MuJoCo itself, per paper cell and code case, with the gaps")
    g.add_argument("--policy", required=True, help="the policy path the sim2sim cells name")
    g.add_argument("--sim2sim", required=True, help="a folder searched for */cells/*.json")
    g.add_argument("--mjx", nargs="*", default=[], help="`mjx-stairs eval` folders "
                   "(results.json): one per direction and evaluation seed")
    g.add_argument("--mjx-code", nargs="*", default=[], help="`code` suite JSON files")
    g.add_argument("--robot-sha", default=None, help="only cells run on this robot file "
                   "(its SHA-256, or a prefix of it)")
    g.add_argument("--latency-ms", type=float, default=0.0)
    g.add_argument("--contact-timeconst", type=float, default=0.01)
    g.add_argument("--out", default=None, help="write the table here (markdown) too")
    g.set_defaults(fn=gaps_command)


def gaps_command(args: argparse.Namespace) -> int:
    from mjx_stairs import atomic
    from mjx_stairs.tools import sim2sim_gaps

    cells = sim2sim_gaps.gather(args.policy, args.sim2sim, args.mjx, args.mjx_code,
                                args.robot_sha, args.latency_ms, args.contact_timeconst)
    text = sim2sim_gaps.markdown(cells, args.sim2sim, f"`{args.policy}`: MJX and MuJoCo itself "
                                 f"(latency {args.latency_ms:g} ms, contact "
                                 f"{args.contact_timeconst:g} s)")
    print(text, end="")
    if args.out:
        atomic.write_text(args.out, text)
        print(f"wrote {args.out}")
    return 0
