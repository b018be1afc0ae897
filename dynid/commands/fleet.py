"""``dynid fleet``: identify every recording of a fleet on Dask, test for drift, write the table and report."""

from __future__ import annotations

import argparse
import importlib.util
import os

from dynid._extras import install_hint
from dynid.commands.common import (
    add_degrees_argument,
    add_json_argument,
    add_robot_arguments,
    check_outputs,
    output,
    robot_file,
    robot_from_args,
    write_figures,
)
from dynid.identify.registry import FRICTION_MODELS, method_names

__all__ = ["HELP", "add_arguments", "run"]

HELP = "identify every recording of many robots on a Dask cluster, test their parameters for drift, write a report"


def _gmm(text: str) -> str | int:
    if text in ("off", "auto"):
        return text
    if not text.isdigit() or int(text) < 1:
        raise argparse.ArgumentTypeError(f"--gmm is '{text}'; give off, auto or a number of components (1 or more)")
    return int(text)


def _cutoff(text: str) -> float | str | None:
    if text in ("auto", "none"):
        return None if text == "none" else "auto"
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--cutoff is '{text}'; give a frequency in Hz, auto or none") from None


def _fraction(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--holdout is '{text}'; give a fraction such as 0.2") from None
    if not 0.0 <= value < 0.9:
        raise argparse.ArgumentTypeError(f"--holdout is {value}; give a fraction in [0, 0.9), such as 0.2")
    return value


def _alpha(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not 0.0 < value < 1.0:
        raise argparse.ArgumentTypeError(f"--alpha is '{text}'; give an error rate between 0 and 1, such as 0.05")
    return value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_robot_arguments(parser)
    parser.add_argument(
        "--data",
        required=True,
        metavar="GLOB",
        help="recordings: a quoted glob pattern ('recordings/**/*.csv'; .csv, .npz, .mcap files and rosbag2 "
        "folders); without --manifest each is <robot>/<ISO date or index>.<ext>",
    )
    parser.add_argument(
        "--manifest", metavar="FLEET.csv", help="CSV with the columns path, robot, time: one row per recording"
    )
    parser.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="a running Dask scheduler (tcp://HOST:8786, or a scheduler file .json); default a local cluster",
    )
    parser.add_argument(
        "--workers", default=2, type=int, metavar="N", help="workers of the local cluster (default 2)"
    )
    parser.add_argument(
        "--serial", action="store_true", help="identify in this process, one recording after another (no Dask)"
    )
    add_degrees_argument(parser)
    parser.add_argument(
        "--topic", metavar="NAME", help="the JointState topic of ROS 2 recordings that hold several"
    )
    parser.add_argument(
        "--method", default="irls", choices=method_names(),
        help="layer-1 method (default irls: one pipeline for every recording, so that their parameters compare)",
    )
    parser.add_argument(
        "--friction", default="seed", choices=FRICTION_MODELS.names(),
        help="friction model (default seed, the paper's)",
    )
    parser.add_argument(
        "--gmm", default="auto", type=_gmm, metavar="{off,auto,K}", help="layer-3 correction (default auto)"
    )
    parser.add_argument(
        "--cutoff", default="auto", type=_cutoff, metavar="HZ", help="low-pass cut-off (default auto, as identify)"
    )
    parser.add_argument(
        "--holdout", default=0.2, type=_fraction, metavar="F",
        help="fraction of each recording, at its end, held out for the error (default 0.2; 0: none)",
    )
    parser.add_argument(
        "--diagnose", action="store_true", help="diagnose each recording's model on its held-out part (slow)"
    )
    parser.add_argument(
        "--alpha", default=0.05, type=_alpha, metavar="A",
        help="family-wise error rate of the drift tests over robots x parameters (default 0.05, Holm)",
    )
    parser.add_argument(
        "--out", required=True, metavar="DIR",
        help="folder to write: new, empty, or an earlier fleet run (replaced); fleet.parquet, fleet.csv, drift.csv, report.html, summary.json",
    )
    add_json_argument(parser)


def run(args: argparse.Namespace) -> int:
    from dynid.exceptions import UsageError
    from dynid.fleet.core import FleetSettings, identify_fleet
    from dynid.fleet.recordings import find_recordings

    if args.workers < 1:
        raise UsageError(f"--workers is {args.workers}; give at least 1 worker.")
    if args.serial and args.scheduler:
        raise UsageError("--serial and --scheduler exclude each other; give one of them.")
    # The table is written through pyarrow, and the cluster needs distributed: say so before any work.
    for module, needed in (("pyarrow", True), ("distributed", not args.serial)):
        if needed and importlib.util.find_spec(module) is None:
            raise UsageError(
                f"dynid fleet needs the package {module}, which is not installed; install it with "
                f"{install_hint('fleet')}."
            )
    recordings = find_recordings(args.data, args.manifest, out=args.out)
    check_outputs(
        [output("out", args.out, folder=True, replace=True, marker="summary.json"), output("json", args.json, (".json",))],
        {"data": [r.path for r in recordings], "manifest": args.manifest, "robot": robot_file(args)},
    )
    settings = FleetSettings(
        method=args.method, friction=args.friction, gmm=args.gmm, cutoff=args.cutoff, holdout=args.holdout,
        diagnose=args.diagnose, degrees=args.degrees, topic=args.topic,
    )
    robot = robot_from_args(args)
    print(
        f"{len(recordings)} recordings of {len({r.robot for r in recordings})} robots; identifying on "
        + ("this process" if args.serial else args.scheduler or f"a local cluster of {args.workers} workers")
    )
    result = identify_fleet(
        robot, recordings, scheduler=args.scheduler, workers=args.workers, serial=args.serial, settings=settings,
        alpha=args.alpha,
    )
    result.write(args.out)
    print(result.summary())
    print(f"wrote {os.path.join(args.out, '')}: fleet.parquet, fleet.csv, drift.csv, report.html, summary.json")
    write_figures(args.json, result.figures())
    return 0
