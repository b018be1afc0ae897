"""A reference model taken from the robot description: the baseline an identified model should beat.

:func:`nominal_model` keeps the description's rigid body (link parameters and armature) and fits only a
friction model to the data; :func:`described_model` is the shared shape of every model whose rigid body
is read rather than estimated (also :func:`dynid.simmodel.nominal.description_model`'s).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynid.data.dataset import Dataset
from dynid.data.preparation import Prepared, Preprocessing, prepare
from dynid.identify.columns import column_set, linear_torque
from dynid.identify.friction import FrictionLayer
from dynid.identify.model import IdentifiedModel

__all__ = ["described_model", "nominal_model"]


def nominal_model(
    robot,
    data: Dataset,
    *,
    preprocessing: Preprocessing | None = None,
    friction: str = "linear",
) -> IdentifiedModel:
    """The robot's own (URDF) parameters with a friction model fitted to the data: a baseline.

    The rigid-body part comes unchanged from the robot description (its link parameters and armature);
    only the friction is fitted, to ``tau - tau_link`` on ``data``, as layer 2 would.  An identified
    model should predict held-out data better than this.

    Parameters
    ----------
    robot : RobotModel
        The robot, with the parameters of its description.
    data : Dataset
        Data to fit the friction on (the identification data, not the held-out ones).
    preprocessing : Preprocessing, optional
        As for the identified models it is compared with.
    friction : str
        Friction model (default ``linear``: Coulomb, viscous and offset per joint).

    Returns
    -------
    IdentifiedModel
        With ``method="urdf"`` and a zero covariance (nothing of the rigid body was estimated).
    """
    cols = column_set(robot, friction=False, armature=True)
    n = robot.n
    phi = np.concatenate(
        [np.asarray(robot.params, float), np.asarray(robot.armature, float), np.zeros(3 * n)]
    )
    x = cols.P @ phi
    prep = prepare(data, preprocessing, n_joints=n)
    rows = prep.rows
    link = prep.filter(linear_torque(cols, x, prep.q, prep.dq, prep.ddq))[rows]
    resid = prep.tau_reference - link
    layer = FrictionLayer(model=friction).fit(prep.dq[rows], resid)
    after = resid - layer.predict(prep.dq[rows])

    def rms(r: NDArray[np.float64]) -> list[float]:
        return [float(v) for v in np.sqrt(np.mean(r**2, axis=0))]

    return described_model(
        robot,
        cols,
        x,
        prep,
        layer,
        method="urdf",
        friction_source="layer2",
        rms_layers={"link": rms(resid), "friction": rms(after), "gmm": rms(after)},
        notes=["rigid body from the robot description"],
        n_samples=len(rows),
    )


def described_model(
    robot,
    cols,
    x: NDArray[np.float64],
    prep: Prepared,
    friction: FrictionLayer,
    *,
    method: str,
    friction_source: str,
    rms_layers: dict[str, list[float]],
    notes: list[str],
    n_samples: int | None = None,
    layers_filtered: bool = False,
) -> IdentifiedModel:
    """A model whose rigid body comes from a robot description: nothing of it estimated.

    The shared shape of :func:`nominal_model` (URDF bodies, friction fitted) and
    :func:`dynid.simmodel.nominal.description_model` (a simulator's file, friction as it states it): a
    zero covariance, no mixture, no condition number.

    Parameters
    ----------
    robot : RobotModel
        The robot.
    cols : ColumnSet
        The model's columns.
    x : ndarray, shape (p,)
        Its parameters in those columns.
    prep : Prepared
        The data it was prepared on (its settings and reference are recorded).
    friction : FrictionLayer
        The friction layer.
    method : str
        What the model is (``"urdf"``, ``"nominal"``).
    friction_source : {"layer1", "layer2"}
        Where the friction comes from (see :class:`IdentifiedModel`).
    rms_layers : dict
        Training RMS (N m) after ``link``, ``friction`` and ``gmm``, per joint (NaN where not measured).
    notes : list of str
        Notes for the summary.
    n_samples : int, optional
        Samples the friction was fitted on.
    layers_filtered : bool
        As for :class:`IdentifiedModel`.
    """
    n = robot.n
    info: dict[str, Any] = {"notes": list(notes), "reference": prep.reference}
    if n_samples is not None:
        info = {"n_samples": int(n_samples), **info}
    return IdentifiedModel(
        robot=robot,
        columns=cols,
        params=x,
        cov=np.zeros((cols.p, cols.p)),
        method=method,
        preprocessing=dict(prep.settings),
        friction=friction,
        friction_source=friction_source,
        gmr=None,
        cond=float("nan"),
        rms=np.asarray(rms_layers["friction"], dtype=np.float64).reshape(n),
        rms_layers=rms_layers,
        info=info,
        layers_filtered=layers_filtered,
    )
