"""Options shared by several subcommands."""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Any

from dynid.exceptions import RobotModelError, UsageError

__all__ = ["add_json_argument", "add_robot_arguments", "robot_from_args", "write_figures"]


def add_robot_arguments(parser: argparse.ArgumentParser, *, default: str | None = None) -> None:
    """``--robot`` and the joint-limit overrides."""
    parser.add_argument(
        "--robot",
        default=default,
        required=default is None,
        help="built-in name (ur5, ur10, panda), a URDF file or a modified-DH .toml table"
        + (f" (default {default})" if default else ""),
    )
    for name, unit in (("q-min", "rad"), ("q-max", "rad"), ("dq-max", "rad/s"), ("ddq-max", "rad/s^2")):
        parser.add_argument(
            f"--{name}",
            metavar="V[,V...]",
            help=f"override the model's {name.replace('-', ' ')} limit ({unit}): one value for all joints or one per joint",
        )
    parser.add_argument("--tool", help="URDF frame used as the tool frame (default: the robot's flange)")


def add_json_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", metavar="FILE", help="also write the figures as JSON to FILE")


def write_figures(path: str | os.PathLike[str] | None, figures: Any) -> None:
    """Write a command's figures to ``--json FILE`` (strict JSON, atomically), if a file was given.

    Parameters
    ----------
    path : str, path-like or None
        The ``--json`` file; None writes nothing.
    figures : Any
        The figures; non-finite numbers are written as ``null``.

    Raises
    ------
    UsageError
        If the folder of ``path`` does not exist.
    """
    if path is None:
        return
    from dynid._io import write_json

    path = Path(path)
    if not path.parent.is_dir():
        raise UsageError(f"the folder '{path.parent}' does not exist; create it or write elsewhere.")
    write_json(path, figures)


def _floats(option: str, text: str | None):
    if text is None:
        return None
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise RobotModelError(
            f"--{option} is '{text}'; give numbers separated by commas, e.g. --{option} 2.0 or --{option} 1,1,2,2,3,3."
        ) from None
    return values[0] if len(values) == 1 else values


def robot_from_args(args: argparse.Namespace):
    """Load the robot named by ``--robot`` with the limit overrides applied."""
    from dynid.symbolic.robot import load_robot

    return load_robot(
        args.robot,
        q_min=_floats("q-min", args.q_min),
        q_max=_floats("q-max", args.q_max),
        dq_max=_floats("dq-max", args.dq_max),
        ddq_max=_floats("ddq-max", args.ddq_max),
        tool=args.tool,
    )
