"""``dynid convert``: a recording as it comes (its own columns and units, or a named real recording) into dynid's dataset."""

from __future__ import annotations

import argparse
from pathlib import Path

from dynid.commands.common import add_json_argument, check_outputs, output, write_figures
from dynid.exceptions import UsageError

__all__ = ["HELP", "add_arguments", "run"]

HELP = (
    "turn a recording as it comes (its own column names and units, or a named real recording) into a dataset"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    source = parser.add_argument_group("source (one of)")
    source.add_argument(
        "--data", metavar="RAW.csv", help="a table with a header (commas, semicolons, tabs or spaces)"
    )
    source.add_argument(
        "--recording",
        metavar="NAME",
        help="a real recording read by its adapter: panda_gaz2019, tx40, kuka_lwr4_flobaroid (from ../shared/data, "
        "or --root)",
    )
    source.add_argument("--root", metavar="DIR", help="folder holding the named recordings")
    source.add_argument(
        "--run",
        type=int,
        metavar="N",
        help="the run of a recording that holds several (kuka_lwr4_flobaroid: 1, 2 or 3; default 1)",
    )
    columns = parser.add_argument_group("columns of --data (names, or one pattern with *)")
    columns.add_argument("--time", default="t", metavar="COL", help="time column (default t)")
    columns.add_argument(
        "--q", metavar="COLS", help="joint angles, joint 1 first: 'pos_1,pos_2,...' or 'pos_*'"
    )
    columns.add_argument("--tau", metavar="COLS", help="joint torques, joint 1 first ('effort_*')")
    columns.add_argument("--dq", metavar="COLS", help="joint velocities, if logged")
    columns.add_argument("--ddq", metavar="COLS", help="joint accelerations, if logged")
    units = parser.add_argument_group("units of --data")
    units.add_argument(
        "--time-unit", default="s", choices=("s", "ms", "us", "ns"), help="unit of the time column"
    )
    units.add_argument("--degrees", action="store_true", help="angles (and their derivatives) in degrees")
    units.add_argument(
        "--torque-scale",
        metavar="K[,K...]",
        help="factor to N m, one or one per joint (0.001 for mN m; torque constant x gear ratio for motor current)",
    )
    parser.add_argument("--robot", help="check the data against this robot (joint count, torque magnitude)")
    parser.add_argument(
        "--out", required=True, metavar="D.csv", help="the dataset to write (.csv, or .npz to keep runs)"
    )
    add_json_argument(parser)


def run(args: argparse.Namespace) -> int:
    from dynid.data.files import check_torque_scale, save_dataset

    if (args.data is None) == (args.recording is None):
        raise UsageError("give --data RAW.csv (with --q and --tau) or --recording NAME, one of them")
    if args.run is not None and args.recording is None:
        raise UsageError("--run picks a run of a named recording; give --recording NAME with it")
    check_outputs(
        [output("out", args.out, (".csv", ".npz")), output("json", args.json, (".json",))],
        {"data": args.data},
    )
    if args.recording is not None:
        from dynid._progress import stage
        from dynid.data.adapters import ADAPTERS, load_recording

        with stage(f"reading the recording {args.recording}"):
            ds = load_recording(args.recording, args.root, run=args.run)
        runs = ADAPTERS[args.recording].runs
        source = f"the recording {args.recording}" + (f", run {args.run or 1} of {runs}" if runs > 1 else "")
    else:
        if args.q is None or args.tau is None:
            raise UsageError(
                "--data needs --q and --tau: the columns of the joint angles and torques (e.g. 'pos_*')"
            )
        from dynid._progress import stage
        from dynid.data.convert import convert_table

        with stage(f"reading {args.data}"):
            ds = convert_table(
                args.data,
                time=args.time,
                q=args.q,
                tau=args.tau,
                dq=args.dq,
                ddq=args.ddq,
                time_unit=args.time_unit,
                degrees=args.degrees,
                torque_scale=args.torque_scale,
            )
        source = str(args.data)
    if args.robot is not None:
        from dynid.symbolic.robot import load_robot

        robot = load_robot(args.robot)
        if robot.n != ds.n:
            raise UsageError(
                f"{source} has {ds.n} joints and the robot '{robot.name}' {robot.n}; give its own robot"
            )
        ds = check_torque_scale(ds, robot, source=source)
    out = Path(args.out)
    save_dataset(ds, out)
    rate = (ds.m - 1) / ds.duration if ds.duration > 0 else float("nan")
    signals = ", ".join(k for k in ("dq", "ddq") if getattr(ds, k, None) is not None)
    print(
        f"{source}: {ds.m} samples of {ds.n} joints over {ds.duration:.4g} s ({rate:.4g} Hz)"
        + (f", with {signals}" if signals else "")
    )
    for key, cols in ds.meta.get("columns", {}).items():
        print(f"  {key}: {', '.join(cols) if isinstance(cols, list) else cols}")
    done = [
        *([f"t {args.time_unit} -> s"] if getattr(args, "time_unit", "s") != "s" else []),
        *(["angles deg -> rad"] if getattr(args, "degrees", False) else []),
        *([f"torques x {args.torque_scale} -> N m"] if getattr(args, "torque_scale", None) else []),
    ]
    if done and getattr(args, "recording", None) is None:  # a named recording's adapter does its own
        print(f"  converted: {'; '.join(done)}")
    print(f"wrote {out}")
    write_figures(
        args.json,
        {
            "out": str(out),
            "samples": ds.m,
            "joints": ds.n,
            "duration_s": ds.duration,
            "columns": ds.meta.get("columns"),
        },
    )
    return 0
