"""Links as physical bodies: standard parameters from a body's mass, centre of mass and inertia, and the
checks that every link of a loaded description is a body and that every joint moves one."""

from __future__ import annotations

import warnings

import numpy as np

from dynid.exceptions import RobotModelError, RobotModelWarning
from dynid.symbolic.robot_model import RobotModel

__all__ = ["INERTIA_TOLERANCE", "check_inertias", "check_simulable", "standard_from_com"]

INERTIA_TOLERANCE = 0.01
"""Largest violation of the triangle inequality a loaded description may have, as a fraction of the trace
of the link's inertia: beyond it the description is refused, below it (rounded inertias of published
URDFs) :func:`check_inertias` warns."""


def _numbers(values) -> str:
    """A short list of numbers for a message: ``[0.05, 0.06, 0.2]`` (6 significant digits)."""
    return "[" + ", ".join(f"{float(v) + 0.0:.6g}" for v in np.ravel(values)) + "]"


def _principal_moments(v: np.ndarray) -> np.ndarray:
    """Principal moments (kg m^2) about the centre of mass of a link from its 10 standard parameters."""
    m = float(v[0])
    c = v[1:4] / m if m > 0 else np.zeros(3)
    inertia = np.array([[v[4], v[5], v[7]], [v[5], v[6], v[8]], [v[7], v[8], v[9]]], dtype=float)
    skew = np.array([[0.0, -c[2], c[1]], [c[2], 0.0, -c[0]], [-c[1], c[0], 0.0]])
    return np.linalg.eigvalsh(inertia + m * skew @ skew)


def check_inertias(model: RobotModel) -> RobotModel:
    """Check that every link of a loaded description is a physical body.

    The rule, the same for URDF files, modified-DH tables and built-in robots: a mass is positive, or
    zero with zero first moment (an empty link); the inertia about the centre of mass is positive
    semi-definite (a point mass or a thin rod, idealised, is accepted); each principal moment is at most
    the sum of the other two (the triangle inequality).  A violation of the triangle inequality by at most
    :data:`INERTIA_TOLERANCE` of the trace (published URDFs round their inertias) gives a warning; anything
    else is refused.  Identified or perturbed parameters (:meth:`RobotModel.with_params`) are not checked.

    Parameters
    ----------
    model : RobotModel
        A model as loaded.

    Returns
    -------
    RobotModel
        ``model``, so that calls chain.

    Raises
    ------
    RobotModelError
        Negative mass, first moment without mass, inertia not positive semi-definite, or the triangle
        inequality violated beyond the tolerance.

    Warns
    -----
    RobotModelWarning
        The triangle inequality violated within the tolerance.
    """
    for j, v in enumerate(np.asarray(model.params, dtype=float).reshape(-1, 10), start=1):
        where = f"the link of joint {j} ('{model.joints[j - 1].name}') of the robot '{model.name}'"
        if not v[0] >= 0:
            raise RobotModelError(
                f"{where} has mass {v[0]:g} kg; a mass must be positive (or zero for an empty link): fix it."
            )
        if v[0] == 0 and np.any(v[1:4] != 0):
            raise RobotModelError(
                f"{where} has zero mass but first moment {_numbers(v[1:4])} kg m; a body "
                "needs a positive mass (or zero mass and zero first moment): fix its mass."
            )
        moments = _principal_moments(v)
        trace = float(moments.sum())
        scale = max(float(np.abs(moments).max()), 1e-300)
        if moments.min() < -1e-9 * scale:
            raise RobotModelError(
                f"{where} has principal moments of inertia {_numbers(moments)} kg m^2 about its "
                "centre of mass; an inertia has none negative (it is positive semi-definite): fix Ixx..Iyz."
            )
        excess = moments - (trace - moments)
        k = int(np.argmax(excess))
        if excess[k] <= 1e-9 * scale:
            continue
        others = np.delete(moments, k)
        said = (
            f"{where} has principal moments of inertia {_numbers(moments)} kg m^2 about its centre "
            f"of mass, and {moments[k]:.6g} exceeds the sum of the other two ({others.sum():.6g})"
        )
        if excess[k] > INERTIA_TOLERANCE * trace:
            raise RobotModelError(
                f"{said}, which no body can have (the triangle inequality); fix Ixx, Iyy, Izz so that each is "
                "at most the sum of the other two."
            )
        warnings.warn(
            f"{said} by {excess[k] / trace:.2%} of the trace, within the {INERTIA_TOLERANCE:.0%} allowed for "
            "rounded inertias; used as given.",
            RobotModelWarning,
            stacklevel=3,
        )
    return model


def check_simulable(model: RobotModel) -> RobotModel:
    """Check that every joint moves something, so that the robot can be simulated.

    A joint carries nothing when every link from it to the tip (its subtree) has zero mass and zero
    inertia and the joint has no armature: its row of the mass matrix is zero, its torque is zero whatever
    the motion, and a simulated controller cannot track it.  Such a description is fine for designing an
    excitation and for identification (they use the regressor only), so only the simulator refuses it.

    Parameters
    ----------
    model : RobotModel
        The robot to simulate.

    Returns
    -------
    RobotModel
        ``model``, so that calls chain.

    Raises
    ------
    RobotModelError
        When a joint carries nothing; the message names the first.
    """
    params = np.asarray(model.params, dtype=float).reshape(-1, 10)
    empty = [not np.any(params[j]) for j in range(model.n)]
    carries = [False] * model.n
    for j in reversed(range(model.n)):
        carries[j] = carries[j] or not empty[j] or model.armature[j] != 0
        parent = model.joints[j].parent - 1
        if parent >= 0 and carries[j]:
            carries[parent] = True
    if all(carries):
        return model
    j = carries.index(False)
    raise RobotModelError(
        f"joint {j + 1} ('{model.joints[j].name}') of the robot '{model.name}' carries no mass, inertia or "
        "armature, so its torque is zero whatever the motion and it cannot be simulated; give its link "
        "(or a link beyond it) a mass and inertia, or the joint an armature."
    )


def standard_from_com(mass: float, com: np.ndarray, inertia_com: np.ndarray) -> np.ndarray:
    """Standard parameters (Pinocchio's order) of a body given its mass, centre of mass and inertia.

    Parameters
    ----------
    mass : float
        Mass (kg).
    com : ndarray, shape (3,)
        Centre of mass in the link frame (m).
    inertia_com : ndarray, shape (3, 3)
        Inertia about the centre of mass, link-frame axes (kg m^2).

    Returns
    -------
    ndarray, shape (10,)
        ``[m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`` with the inertia about the link frame origin.
    """
    c = np.asarray(com, dtype=float)
    skew = np.array([[0.0, -c[2], c[1]], [c[2], 0.0, -c[0]], [-c[1], c[0], 0.0]])
    with np.errstate(over="ignore", invalid="ignore"):  # absurd sizes give inf, refused by RobotModel
        inertia = np.asarray(inertia_com, dtype=float) - mass * skew @ skew
        first = mass * c
    return np.array(
        [
            mass,
            *first,
            inertia[0, 0],
            inertia[0, 1],
            inertia[1, 1],
            inertia[0, 2],
            inertia[1, 2],
            inertia[2, 2],
        ]
    )
