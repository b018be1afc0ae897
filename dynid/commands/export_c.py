"""``dynid export-c``: C source, header, shared library, example and loader of a robot's regressors, or of an
identified model's torque prediction (``--model``), reload-checked."""

from __future__ import annotations

import argparse

from dynid.commands.common import add_robot_arguments, check_outputs, output, robot_file, robot_from_args

__all__ = ["HELP", "add_arguments", "run"]

HELP = (
    "export a robot's regressors (--robot) or an identified model's torque prediction (--model) as C source, "
    "header, compiled library and example"
)

_ROBOT_ONLY = ("q_min", "q_max", "dq_max", "ddq_max", "tool")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_robot_arguments(parser, required=False)
    parser.add_argument(
        "--model",
        metavar="M.json",
        help="model file written by 'dynid identify': export its torque prediction (predict) and regressor "
        "(model_regressor) instead of a robot's functions; checked against the model before it is written",
    )
    parser.add_argument(
        "--out",
        required=True,
        metavar="DIR",
        help="folder to write: new, empty, or an earlier export (replaced); a folder holding other files is refused",
    )
    parser.add_argument(
        "--functions",
        default=None,
        metavar="NAME[,NAME...]",
        help="functions to export (default: base_regressor, regressor, rnea, friction_columns, gravity, fk; "
        "with --model: the robot functions to add after predict and model_regressor, none by default)",
    )


def run(args: argparse.Namespace) -> int:
    from dynid.exceptions import UsageError

    if (args.robot is None) == (args.model is None):
        raise UsageError(
            "give --robot R (a robot's regressors) or --model M.json (an identified model's torque prediction)"
            + (", not both" if args.model is not None else "")
        )
    if args.model is not None:
        given = [f"--{name.replace('_', '-')}" for name in _ROBOT_ONLY if getattr(args, name) is not None]
        if given:
            raise UsageError(
                f"{', '.join(given)} {'apply' if len(given) > 1 else 'applies'} to --robot; a model carries the "
                f"robot it was identified for: leave {'them' if len(given) > 1 else 'it'} out"
            )
        return _run_model(args)
    from dynid.symbolic.export import DEFAULT_EXPORT, export_c

    check_outputs(
        [output("out", args.out, folder=True, replace=True, marker="manifest.json")],
        {"robot": robot_file(args)},
    )
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


def _run_model(args: argparse.Namespace) -> int:
    from pathlib import Path

    from dynid._progress import say

    check_outputs(
        [output("out", args.out, folder=True, replace=True, marker="manifest.json")], {"model": args.model}
    )
    from dynid.identify.export_c import export_model_c
    from dynid.identify.model import load_model

    model = load_model(args.model)
    functions = (
        () if args.functions is None else tuple(f.strip() for f in args.functions.split(",") if f.strip())
    )
    say("writing the model's prediction as C and reloading the library to check it")
    result = export_model_c(model, args.out, functions=functions, model_file=Path(args.model).name)
    e = result.export
    check = result.check
    print(
        f"wrote {e.folder}/: {e.source.name}, {e.header.name}, {e.batch_source.name}, {e.library.name}, "
        "example.c + Makefile, manifest.json, dynid_loader.py"
    )
    print(f"  predict(q, dq, ddq) -> tau carries: {'; '.join(result.carried)}")
    print(
        f"  reload check passed: the library's prediction is the model's to {check['relative_error']:.2g} (relative; "
        f"tolerance {check['tolerance']:.0e}) on {check['states']} random states within the limits"
    )
    if result.not_carried:
        print("  not carried (the C torque leaves them out; listed in manifest.json too):")
        for item in result.not_carried:
            joints = ",".join(str(j) for j in item["joints"])
            print(f"    {item['what']} (joints {joints or '-'}): {item['why']}")
    else:
        print("  not carried: nothing (the C prediction is the whole model)")
    print(f"  build the example: make -C {e.folder} && {e.folder}/example")
    print(f"  from Python: CompiledLibrary('{e.folder}').predict(q, dq, ddq)  (dynid_loader.py)")
    return 0
