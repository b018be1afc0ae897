"""Robot models: built-in names, URDF files and modified-DH tables.

Every description is reduced to one canonical kinematic tree (:class:`RobotModel`): a list of
single-DOF joints with their placement in the parent joint frame, the standard inertial parameters of
the body each joint carries, the armature (rotor inertia) and the tool frame.  The numeric Pinocchio
model and the symbolic CasADi functions are both built from that one tree, so they cannot disagree.

Standard parameters are Pinocchio's: per joint ``[m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]``
with ``m c`` the first moment and the inertia about the joint frame origin, in the joint frame (SI).

The pieces are modules of their own: the canonical tree (:mod:`dynid.symbolic.robot_model`), URDF and
MJCF files (:mod:`dynid.symbolic.urdf`), modified-DH tables (:mod:`dynid.symbolic.mdh`), coupled
transmissions (:mod:`dynid.symbolic.transmission`) and the checks that every link is a physical body
(:mod:`dynid.symbolic.inertia`).  This module dispatches on the description and re-exports their public
names.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from dynid.exceptions import RobotModelError
from dynid.symbolic.inertia import INERTIA_TOLERANCE, check_inertias, check_simulable, standard_from_com
from dynid.symbolic.mdh import load_mdh, mdh_placement
from dynid.symbolic.robot_model import DEFAULT_DDQ_MAX, PARAM_NAMES, Joint, RobotModel
from dynid.symbolic.transmission import load_transmission
from dynid.symbolic.urdf import CONTINUOUS_RANGE, SNAP_M, SNAP_RAD, load_mjcf, load_urdf, pin_model_from_urdf

__all__ = [
    "BUILTIN_ROBOTS",
    "CONTINUOUS_RANGE",
    "DEFAULT_DDQ_MAX",
    "INERTIA_TOLERANCE",
    "PARAM_NAMES",
    "SNAP_M",
    "SNAP_RAD",
    "Joint",
    "RobotModel",
    "check_inertias",
    "check_simulable",
    "example_robot_data_dir",
    "load_robot",
    "load_transmission",
    "mdh_placement",
    "pin_model_from_urdf",
    "standard_from_com",
]

# Built-in robots: URDF inside the installed example-robot-data package, joints to lock, tool frame,
# acceleration limits (rad/s^2).  Panda: Franka's datasheet limits; UR: none published, the default.
BUILTIN_ROBOTS: dict[str, dict] = {
    "ur5": {
        "urdf": "ur_description/urdf/ur5_robot.urdf",
        "lock": (),
        "tool": "tool0",
        "ddq_max": None,
    },
    "ur10": {
        "urdf": "ur_description/urdf/ur10_robot.urdf",
        "lock": (),
        "tool": "tool0",
        "ddq_max": None,
    },
    "panda": {
        "urdf": "panda_description/urdf/panda.urdf",
        "lock": ("panda_finger_joint1", "panda_finger_joint2"),
        "tool": "panda_hand_tcp",
        "ddq_max": (15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0),
    },
}


def _site_roots() -> list[Path]:
    return [Path(p) for p in sys.path if p]


def example_robot_data_dir() -> Path:
    """Folder ``robots/`` of the installed example-robot-data package."""
    for root in _site_roots():
        candidate = root / "cmeel.prefix" / "share" / "example-robot-data" / "robots"
        if candidate.is_dir():
            return candidate
    raise RobotModelError(
        "the built-in robots need the package example-robot-data, which was not found on sys.path; "
        "install it with 'pip install example-robot-data'."
    )


# ---------------------------------------------------------------------------- entry point
def load_robot(
    robot: str | Path | RobotModel,
    *,
    q_min=None,
    q_max=None,
    dq_max=None,
    ddq_max=None,
    tool: str | None = None,
    transmission: str | os.PathLike[str] | None = None,
) -> RobotModel:
    """Load a robot from a built-in name, a URDF path or a modified-DH TOML table.

    Parameters
    ----------
    robot : str or Path or RobotModel
        ``"ur5"``, ``"ur10"``, ``"panda"`` (7-DOF arm, hand rigidly attached, fingers locked), a
        ``.urdf`` path, or a ``.toml`` modified-DH table.  A RobotModel is returned as is (with the
        limit overrides applied).  A MuJoCo ``.xml`` (MJCF) is read by Pinocchio's MJCF parser.
    q_min, q_max, dq_max, ddq_max : float or sequence of float, optional
        Override the model's joint limits (one value for all joints, or one per joint).
    tool : str, optional
        Name of the URDF frame used as the tool frame (default: the robot's flange / last frame); a name
        the model does not have is refused, listing its frames.
    transmission : str or path-like, optional
        A TOML file with a ``[transmission]`` table (:func:`load_transmission`): the coupled
        transmission beside a URDF (a table robot may declare it in its own file).

    Raises
    ------
    RobotModelError
        Unknown name, missing or malformed file, unsupported or mimic joint, missing or short table column,
        unknown tool frame, a link that is not a physical body (:func:`check_inertias`).

    Warns
    -----
    RobotModelWarning
        A link's inertia violates the triangle inequality within :data:`INERTIA_TOLERANCE`.
    """
    if isinstance(robot, RobotModel):
        model = robot
    else:
        text = str(robot)
        path = Path(text).expanduser()
        key = text.lower()
        if key in BUILTIN_ROBOTS and not path.exists():
            info = BUILTIN_ROBOTS[key]
            urdf = example_robot_data_dir() / info["urdf"]
            model = check_inertias(
                load_urdf(
                    urdf,
                    name=key,
                    source=key,
                    lock=info["lock"],
                    tool=tool or info["tool"],
                    ddq_max=info["ddq_max"],
                )
            )
        elif path.suffix.lower() == ".urdf":
            model = check_inertias(load_urdf(path, name=path.stem, source=str(path), tool=tool))
        elif path.suffix.lower() in (".xml", ".mjcf"):
            model = check_inertias(load_mjcf(path, name=path.stem, source=str(path), tool=tool))
        elif path.suffix.lower() == ".toml":
            model = check_inertias(load_mdh(path, name=path.stem))
            if tool is not None and tool != model.tool_name:
                raise RobotModelError(
                    f"the table '{path}' has one tool frame, '{model.tool_name}', not '{tool}'; leave out "
                    "--tool, or name the frame in the table's [tool] section (name = ...)."
                )
        elif path.is_dir():
            found = sorted(
                str(f) for pattern in ("*.urdf", "*/*.urdf", "*.toml", "*.xml") for f in path.glob(pattern)
            )[:3]
            inside = f" (in it: {', '.join(found)})" if found else ""
            raise RobotModelError(
                f"--robot '{text}' is a folder{inside}; give the robot's description file itself (a .urdf, a "
                f"MuJoCo .xml or a modified-DH .toml) or a built-in name ({', '.join(BUILTIN_ROBOTS)})."
            )
        else:
            raise RobotModelError(
                f"unknown robot '{text}'; give a built-in name ({', '.join(BUILTIN_ROBOTS)}), a .urdf file, a "
                "MuJoCo .xml (MJCF) or a modified-DH .toml table."
            )
    if any(v is not None for v in (q_min, q_max, dq_max, ddq_max)):
        model = model.with_limits(q_min=q_min, q_max=q_max, dq_max=dq_max, ddq_max=ddq_max)
    if transmission is not None:
        model = model.with_transmission(load_transmission(transmission, model.n))
    return model
