"""A simulator's own description (URDF or MuJoCo MJCF) as the model under test, with no identification.

:func:`description_model` reads the file as the simulator would: the rigid body from its links, the
armature from the MJCF's joints (URDF has none), viscous friction from ``damping`` and Coulomb friction
from ``friction`` (URDF ``<dynamics>``) or ``frictionloss`` (MJCF), all as Pinocchio's parsers read
them (``model.armature``, ``model.damping``, ``model.friction``).  The result is an
:class:`dynid.identify.model.IdentifiedModel` with method ``"nominal"`` and a zero covariance, so
``validate`` (and everything that takes a model) scores the simulator's model on real data as it
scores an identified one.  The Coulomb term is ``frictionloss * sign(dq)``: MuJoCo's frictionloss is a
constraint whose force is that level while the joint slides.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from dynid.data.dataset import Dataset
from dynid.data.preparation import Preprocessing, prepare
from dynid.exceptions import UsageError
from dynid.identify.columns import column_set
from dynid.identify.friction import FrictionLayer
from dynid.identify.model import IdentifiedModel
from dynid.validation.validate import described_model

__all__ = ["DESCRIPTION_SUFFIXES", "description_friction", "description_model", "is_description"]

DESCRIPTION_SUFFIXES = (".urdf", ".xml", ".mjcf")


def is_description(path: str | os.PathLike[str]) -> bool:
    """Whether a ``--model`` argument names a simulator description rather than a dynid model file."""
    return Path(path).suffix.lower() in DESCRIPTION_SUFFIXES


def description_friction(path: str | os.PathLike[str], joint_names) -> tuple[np.ndarray, np.ndarray]:
    """Viscous (N m s/rad) and Coulomb (N m) friction per joint of a URDF or MJCF, as Pinocchio reads them.

    Parameters
    ----------
    path : str or path-like
        The description.
    joint_names : sequence of str
        The joints, in the model's order.
    """
    import pinocchio as pin

    path = Path(path)
    build = pin.buildModelFromUrdf if path.suffix.lower() == ".urdf" else pin.buildModelFromMJCF
    pm = build(str(path))
    damping, coulomb = np.zeros(len(joint_names)), np.zeros(len(joint_names))
    for i, name in enumerate(joint_names):
        v = pm.joints[pm.getJointId(name)].idx_v
        damping[i] = float(pm.damping[v])
        coulomb[i] = float(pm.friction[v])
    return damping, coulomb


def description_model(
    path: str | os.PathLike[str], data: Dataset, *, preprocessing: Preprocessing | None = None
) -> IdentifiedModel:
    """The nominal model of a simulator description (see the module docstring).

    Parameters
    ----------
    path : str or path-like
        A URDF (``.urdf``) or a MuJoCo MJCF (``.xml``).
    data : Dataset
        The data it will be scored on: only their preprocessing settings are resolved on them (the
        filter cut-off chosen from the data); nothing is fitted.
    preprocessing : Preprocessing, optional
        Filtering and differentiation (default :class:`Preprocessing`).

    Returns
    -------
    IdentifiedModel
        ``method="nominal"``, zero covariance, linear friction from the file.
    """
    from dynid.symbolic.robot import load_robot

    path = Path(path)
    if not is_description(path):
        raise UsageError(
            f"'{path}' is not a simulator description; give a .urdf or a MuJoCo .xml (or a dynid model .json)"
        )
    robot = load_robot(path)
    n = robot.n
    damping, coulomb = description_friction(path, robot.joint_names)
    cols = column_set(robot, friction=True, armature=True)
    phi = np.concatenate([robot.params, robot.armature, coulomb, damping, np.zeros(n)])
    x = cols.P @ phi
    prep = prepare(data, preprocessing, n_joints=n)
    friction = FrictionLayer.from_dict(
        {
            "model": "linear",
            "joints": [{"fc": float(coulomb[j]), "fv": float(damping[j]), "fo": 0.0} for j in range(n)],
        }
    )
    nan = [float("nan")] * n
    return described_model(
        robot,
        cols,
        x,
        prep,
        friction,
        method="nominal",
        friction_source="layer1",
        rms_layers={"link": nan, "friction": nan, "gmm": nan},
        notes=[
            f"the simulator's own model from {path.name}: rigid body, armature, damping and Coulomb "
            "friction as the file states them; nothing identified"
        ],
        layers_filtered=True,
    )
