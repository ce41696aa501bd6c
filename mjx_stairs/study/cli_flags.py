"""The command-line flags that name a staircase other than a family's (--mesh, --start, --goal,
--route, --suite), shared by `mjx-stairs eval`, `critic-map` and `play`."""

from __future__ import annotations

import argparse


def mesh_flags(parser: argparse.ArgumentParser, suite: bool = False) -> None:
    """--mesh FILE --start --goal [--route] (and --suite): a staircase other than a family's."""
    parser.add_argument("--mesh", default=None, help="a staircase mesh (STL, OBJ, PLY; metres, "
                        "z up) in place of a family")
    parser.add_argument("--start", default=None, metavar="X,Y[,YAW]",
                        help="with --mesh: the spawn, mesh frame (m, rad)")
    parser.add_argument("--goal", default=None, metavar="X,Y[,YAW]",
                        help="with --mesh: the goal, mesh frame")
    parser.add_argument("--route", default=None, metavar="FILE.csv",
                        help="with --mesh: the route the waypoint follows, x,y per line, mesh "
                        "frame (default: the importer's path, kept in the middle)")
    if suite:
        parser.add_argument("--suite", default=None, metavar="DIR|NAME",
                            help="a folder of cases (NAME.json beside its mesh) or a fixed "
                            "suite: code, paper (every case up and down)")


def flag_cases(args: argparse.Namespace, resolution: float) -> list | None:
    """The cases that --mesh or --suite name (study.cases.from_flags), None for neither."""
    from mjx_stairs.study import cases

    return cases.from_flags(args.mesh, args.start, args.goal, args.route,
                            getattr(args, "suite", None), resolution)


def glued_poses(argv: list[str]) -> list[str]:
    """"--start -1,2" -> "--start=-1,2": argparse takes a value starting with '-' for a flag."""
    out: list[str] = []
    for a in argv:
        if out and out[-1] in ("--start", "--goal") and a[:1] == "-" and a[1:2] in "0123456789.":
            out[-1] += "=" + a
        else:
            out.append(a)
    return out
