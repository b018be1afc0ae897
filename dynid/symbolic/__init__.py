"""Robot models, Pinocchio's dynamics on CasADi symbols, base parameters and C export."""

from __future__ import annotations

from dynid.symbolic.robot import BUILTIN_ROBOTS, PARAM_NAMES, RobotModel, load_robot

__all__ = [
    "BUILTIN_ROBOTS",
    "PARAM_NAMES",
    "BaseParameters",
    "RobotFunctions",
    "RobotModel",
    "base_parameters",
    "load_robot",
    "robot_functions",
]


def __getattr__(name: str):
    # CasADi-dependent parts are imported on first use (the command line starts faster).
    if name in ("RobotFunctions", "robot_functions"):
        from dynid.symbolic import functions

        return getattr(functions, name)
    if name in ("BaseParameters", "base_parameters"):
        from dynid.symbolic import base

        return getattr(base, name)
    raise AttributeError(f"module 'dynid.symbolic' has no attribute {name!r}")
