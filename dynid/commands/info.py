"""``dynid info``: a robot's joints, limits and base parameters."""

from __future__ import annotations

import argparse

from dynid.commands.common import (
    add_json_argument,
    add_robot_arguments,
    check_outputs,
    output,
    robot_file,
    robot_from_args,
    write_figures,
)

__all__ = ["HELP", "add_arguments", "run"]

HELP = "show a robot's joints, limits and base parameters"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_robot_arguments(parser)
    add_json_argument(parser)


def run(args: argparse.Namespace) -> int:
    from dynid.symbolic.base import base_parameters
    from dynid.symbolic.functions import robot_functions

    check_outputs([output("json", args.json, (".json",))], {"robot": robot_file(args)})
    robot = robot_from_args(args)
    base = base_parameters(robot_functions(robot))
    print(
        f"{robot.name}: {robot.n} joints, {base.n_base} base parameters ({int(base.gravity_related.sum())} "
        f"gravity-related), source {robot.source}"
    )
    print(f"{'joint':>5} {'name':<22} {'type':<4} {'q_min':>8} {'q_max':>8} {'dq_max':>7} {'ddq_max':>7}")
    for j, joint in enumerate(robot.joints):
        print(
            f"{j + 1:>5} {joint.name:<22} {joint.kind:<4} {robot.q_min[j]:>8.3f} {robot.q_max[j]:>8.3f} "
            f"{robot.dq_max[j]:>7.3f} {robot.ddq_max[j]:>7.2f}"
        )
    print("base parameters (g: gravity-related):")
    for k, row in enumerate(base.table()):
        print(f"{k + 1:>4} {'g' if row['gravity_related'] else ' '} {row['name']:<8} = {row['expression']}")
    write_figures(
        args.json,
        {
            "robot": robot.name,
            "n": robot.n,
            "joint_names": list(robot.joint_names),
            "limits": {
                "q_min": robot.q_min,
                "q_max": robot.q_max,
                "dq_max": robot.dq_max,
                "ddq_max": robot.ddq_max,
            },
            "n_base": base.n_base,
            "base_parameters": base.table(),
        },
    )
    return 0
