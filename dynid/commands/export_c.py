"""``dynid export-c``: C source, header, shared library, example and loader of a robot's regressors."""

from __future__ import annotations

import argparse

from dynid.commands.common import add_robot_arguments, check_outputs, output, robot_file, robot_from_args

__all__ = ["HELP", "add_arguments", "run"]

HELP = "export a robot's regressors as C source, header, compiled library and example"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_robot_arguments(parser)
    parser.add_argument("--out", required=True, metavar="DIR", help="folder to write: new, empty, or an earlier export (replaced); a folder holding other files is refused")
    parser.add_argument(
        "--functions",
        default=None,
        metavar="NAME[,NAME...]",
        help="functions to export (default: base_regressor, regressor, rnea, friction_columns, gravity, fk)",
    )


def run(args: argparse.Namespace) -> int:
    from dynid.symbolic.export import DEFAULT_EXPORT, export_c

    check_outputs([output("out", args.out, folder=True, replace=True, marker="manifest.json")], {"robot": robot_file(args)})
    robot = robot_from_args(args)
    functions = (
        DEFAULT_EXPORT if args.functions is None else tuple(f.strip() for f in args.functions.split(","))
    )
    result = export_c(robot, args.out, functions=functions)
    print(
        f"wrote {result.folder}/: {result.source.name}, {result.header.name}, {result.batch_source.name}, "
        f"{result.library.name}, example.c + Makefile, manifest.json, dynid_loader.py"
    )
    print(f"  build the example: make -C {result.folder} && {result.folder}/example")
    print(f"  from Python: CompiledLibrary('{result.folder}').base_regressor(q, dq, ddq)  (dynid_loader.py)")
    return 0
