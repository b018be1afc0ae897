"""Bodies in frames: a payload's frame on a robot, its ten inertial parameters moved between frames.

The ten standard parameters of a body, Pinocchio's order: ``[m, m cx, m cy, m cz, Ixx, Ixy, Iyy, Ixz,
Iyz, Izz]`` (kg, kg m, kg m^2 about the frame's origin).  A payload is written in a frame F of the robot
(its tool frame, or one of its description's frames by name); :func:`frame_transform` moves it to the
frame of the joint that carries it, where the regressor's columns of that link apply.  Used by the
payload identification (:mod:`dynid.identify.payload`) and the payload motion's design
(:mod:`dynid.optim.payload_motion`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from dynid.exceptions import UsageError

__all__ = ["PayloadFrame", "body_figures", "frame_transform", "inertia_matrix", "payload_frame", "point_mass", "six"]


@dataclass(frozen=True)
class PayloadFrame:
    """The frame a payload is written in, placed on the body that carries it.

    Attributes
    ----------
    name : str
        Frame name (the tool frame's, or the one given).
    link : int
        The body carrying it: index of its joint, from 0.
    rotation : ndarray, shape (3, 3)
        F's axes in that joint's frame.
    translation : ndarray, shape (3,)
        F's origin in that joint's frame (m).
    """

    name: str
    link: int
    rotation: NDArray[np.float64]
    translation: NDArray[np.float64]


def payload_frame(robot, frame: str | None = None) -> PayloadFrame:
    """The frame F of a robot: its tool frame, or a frame of its description by name.

    Parameters
    ----------
    robot : RobotModel
    frame : str, optional
        A frame name of the robot's URDF (or built-in robot); default the tool frame.

    Raises
    ------
    UsageError
        A frame the description does not have, or one on the fixed base.
    """
    from dynid.exceptions import RobotModelError
    from dynid.symbolic.robot import load_robot

    source = robot
    if frame is not None and frame != robot.tool_name:
        try:
            source = load_robot(robot.source, tool=frame)
        except RobotModelError as exc:
            raise UsageError(f"--frame {frame}: {exc}") from None
        if source.n != robot.n or source.joint_names != robot.joint_names:
            raise UsageError(
                f"--frame {frame}: the description {robot.source} now has other joints than the model; "
                "give the model's own robot description"
            )
    parent = int(source.tool_parent)
    if not 1 <= parent <= robot.n:
        raise UsageError(
            f"the frame '{source.tool_name}' is on the fixed base, which carries no payload the joints "
            "feel; give --frame a frame on a moving link (the tool flange)"
        )
    return PayloadFrame(
        name=str(source.tool_name),
        link=parent - 1,
        rotation=np.asarray(source.tool_rotation, dtype=np.float64),
        translation=np.asarray(source.tool_translation, dtype=np.float64),
    )


def inertia_matrix(v: NDArray[np.float64]) -> NDArray[np.float64]:
    """The 3 x 3 inertia of the last six standard parameters ``[Ixx, Ixy, Iyy, Ixz, Iyz, Izz]``."""
    return np.array([[v[0], v[1], v[3]], [v[1], v[2], v[4]], [v[3], v[4], v[5]]])


def six(inertia: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.array(
        [inertia[0, 0], inertia[0, 1], inertia[1, 1], inertia[0, 2], inertia[1, 2], inertia[2, 2]]
    )


def _moved(v: NDArray[np.float64], R: NDArray[np.float64], p: NDArray[np.float64]) -> NDArray[np.float64]:
    """Standard parameters about F's origin in F's axes -> about the link frame's origin and axes."""
    m, h = v[0], R @ v[1:4]
    inertia = R @ inertia_matrix(v[4:]) @ R.T + m * (p @ p * np.eye(3) - np.outer(p, p))
    inertia += 2.0 * (p @ h) * np.eye(3) - np.outer(p, h) - np.outer(h, p)
    return np.concatenate([[m], m * p + h, six(inertia)])


def frame_transform(frame: PayloadFrame) -> NDArray[np.float64]:
    """The 10 x 10 matrix ``T`` with ``params_link = T @ params_F`` (the map is linear).

    Parameters
    ----------
    frame : PayloadFrame
    """
    eye = np.eye(10)
    return np.stack([_moved(e, frame.rotation, frame.translation) for e in eye], axis=1)


def body_figures(v: NDArray[np.float64]) -> NDArray[np.float64]:
    """``[m, cx, cy, cz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]``: mass, centre of mass and inertia about it."""
    m = v[0]
    c = v[1:4] / m if abs(m) > 1e-12 else np.zeros(3)
    inertia = inertia_matrix(v[4:]) - m * (c @ c * np.eye(3) - np.outer(c, c))
    return np.concatenate([[m], c, six(inertia)])


def point_mass(v: NDArray[np.float64]) -> NDArray[np.float64]:
    """The point mass at the centre of mass of ``v`` (its inertia about the com zero)."""
    m = v[0]
    c = v[1:4] / m if abs(m) > 1e-12 else np.zeros(3)
    return np.concatenate([[m], m * c, six(m * (c @ c * np.eye(3) - np.outer(c, c)))])
