"""A simulator description corrected from data: what separates its nominal model from the robot, and a fix.

:func:`correct_description` re-identifies, on training data, what a URDF or MJCF can carry (the link
bodies, the armature for MJCF, a viscous ``damping`` and a Coulomb ``frictionloss`` per joint, plus a
torque offset that no format carries), with the robot loaded from the description itself, so that the
physically consistent fit (:func:`dynid.identify.model.identify` with its default physical fit) pulls the
directions the data cannot see toward the file's own bodies (:mod:`dynid.simmodel.parameters`).  A URDF
has no armature field, so for a URDF the fit runs without armature columns: the link bodies take what
they can of it, instead of fitting an armature the file would then drop.

On held-out data it scores, on the same prepared states and the same reference torque as
``dynid validate --model FILE`` does,

* the file as it stands (the nominal model, :func:`dynid.simmodel.nominal.description_model`),
* the file with one group of its values corrected at a time (link bodies, armature, friction): which
  group separates the file from the robot, each alone (the groups interact, so the closures do not
  add up),
* the corrected file (every group),

and, with ``out``, writes the corrected description into a copy of the file through
:func:`dynid.simmodel.export.export_model` (reload-checked before it is kept; what the format cannot
carry is listed in its comment).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynid.data.dataset import Dataset
from dynid.identify.columns import column_set, linear_torque
from dynid.simmodel.nominal import description_friction, description_model, is_description

__all__ = ["GROUPS", "Correction", "correct_description", "description_format"]

GROUPS = ("link bodies", "armature", "friction")
"""The groups of a description's values that a correction changes, one at a time in the breakdown."""


def description_format(path: str | os.PathLike[str]) -> str:
    """``"urdf"`` or ``"mjcf"``: the format of a simulator description, from its suffix."""
    return "urdf" if Path(path).suffix.lower() == ".urdf" else "mjcf"


@dataclass
class Correction:
    """What separates a description's nominal model from the robot, and the corrected values.

    Attributes
    ----------
    format : str
        ``urdf`` or ``mjcf``.
    nominal : dict
        The file's values per joint: ``mass`` (kg, the body each joint carries), ``armature``
        (kg m^2), ``damping`` (N m s/rad), ``frictionloss`` (N m).
    corrected : dict
        The same, corrected.
    rms_nominal, rms_corrected : ndarray, shape (n,)
        Held-out torque RMS of the file as it stands and of the corrected file (N m).
    groups : list of dict
        ``{"group", "rms", "closure"}``: the held-out RMS with that group alone corrected, and the share of
        the gap it closes.
    closure : ndarray, shape (n,)
        Share of the gap closed per joint by the corrected file: ``(mse_nominal - mse_corrected) /
        (mse_nominal - floor^2)`` (NaN where the nominal model is within 5 % of the floor's variance).
    closure_overall : float
        The same over all joints (sums of the per-joint mean squares in noise variances).
    floor : ndarray, shape (n,)
        The noise floor the gap is measured to (N m; zeros when none was given).
    export : ExportResult or None
        The file written (``out`` given).
    not_carried : list of dict
        What the corrected values leave out (offsets, armature for URDF, ...), from the parameters.
    reference : str
        The torque the errors are taken against.
    cutoff_hz : float
        The filter cut-off of the comparison (the training data's, as the diagnosis uses).
    rms_validate : dict
        ``nominal`` and ``corrected`` held-out RMS per joint as ``dynid validate --model FILE`` computes it
        (its cut-off chosen on the held-out data, ``cutoff_hz``).
    pull : dict
        ``reference_weight`` of the pull toward the file's bodies and how far (``mahalanobis``, standard
        deviations) the bodies moved from the identified parameters.
    """

    format: str
    nominal: dict[str, list[float]]
    corrected: dict[str, list[float]]
    rms_nominal: NDArray[np.float64]
    rms_corrected: NDArray[np.float64]
    groups: list[dict[str, Any]]
    closure: NDArray[np.float64]
    closure_overall: float
    floor: NDArray[np.float64]
    export: Any = None
    not_carried: list[dict[str, Any]] = field(default_factory=list)
    reference: str = ""
    cutoff_hz: float = float("nan")
    rms_validate: dict[str, Any] = field(default_factory=dict)
    pull: dict[str, float] = field(default_factory=dict)

    def finding(self) -> str:
        """One sentence: the group that closes most of the gap alone, and what the corrected file closes."""
        groups = [g for g in self.groups if g["applies"]]
        best = max(groups, key=lambda g: g["closure"] if np.isfinite(g["closure"]) else -np.inf)
        # round before printing, so that a closure of -0.001 reads 0 %, not -0 %
        rest = ", ".join(f"{g['group']} {_percent(g['closure'])}" for g in groups if g is not best)
        return (
            f"What separates the file from the robot: its {best['group']} (corrected alone, they close "
            f"{_percent(best['closure'])} of the held-out gap{'; ' + rest if rest else ''}); every group corrected "
            f"closes {_percent(self.closure_overall)} (mean RMS {np.mean(self.rms_nominal):.4g} -> "
            f"{np.mean(self.rms_corrected):.4g} N m)."
        )

    def figures(self) -> dict[str, Any]:
        """JSON-ready figures."""
        return {
            "format": self.format,
            "nominal": self.nominal,
            "corrected": self.corrected,
            "rms_nominal": self.rms_nominal.tolist(),
            "rms_corrected": self.rms_corrected.tolist(),
            "floor": self.floor.tolist(),
            "groups": [{**g, "rms": list(g["rms"])} for g in self.groups],
            "closure": [None if not np.isfinite(c) else float(c) for c in self.closure],
            "closure_overall": self.closure_overall,
            "closure_definition": "(mse_nominal - mse) / (mse_nominal - noise floor^2), on the held-out data",
            "not_carried": self.not_carried,
            "reference": self.reference,
            "out": None if self.export is None else str(self.export.path),
            "checks": None if self.export is None else self.export.checks,
            "cutoff_hz": self.cutoff_hz,
            "rms_validate": self.rms_validate,
            "pull": self.pull,
        }


def _percent(share: float) -> str:
    """A share as a whole percentage ("-" when undefined: no gap over the floor)."""
    return f"{round(100 * share) + 0:d} %" if np.isfinite(share) else "-"


def _values(standard, armature, damping, loss, n) -> dict[str, list[float]]:
    return {
        "mass": [float(standard[10 * j]) for j in range(n)],
        "armature": [float(v) for v in armature],
        "damping": [float(v) for v in damping],
        "frictionloss": [float(v) for v in loss],
    }


def correct_description(
    path: str | os.PathLike[str],
    train: Dataset,
    heldout: Dataset,
    *,
    out: str | os.PathLike[str] | None = None,
    floor: NDArray[np.float64] | None = None,
) -> Correction:
    """Re-identify what a description carries, score it against the file on held-out data, write it.

    Parameters
    ----------
    path : str or path-like
        The description (``.urdf`` or MuJoCo ``.xml``).
    train : Dataset
        Training data of the robot (the corrections are fitted on them).
    heldout : Dataset
        Held-out data of the robot (the corrections are scored on them).
    out : str or path-like, optional
        Where to write the corrected description (same format as ``path``); nothing is written without.
    floor : ndarray, shape (n,), optional
        Noise floor of the held-out torque (N m): the gap is measured down to it (default zero).

    Returns
    -------
    Correction

    Raises
    ------
    UsageError
        Not a description.
    IdentificationError
        The written file failed its reload check (nothing is written).
    """
    from dynid.exceptions import UsageError

    path = Path(path)
    if not is_description(path):
        raise UsageError(f"'{path}' is not a simulator description; give a .urdf or a MuJoCo .xml")
    fmt = description_format(path)
    # the nominal model seen through the training data's preprocessing, as the diagnosis sees it
    nominal = description_model(path, train)
    robot = nominal.robot
    n = robot.n
    fit = _fit_and_write(path, fmt, robot, train, heldout, out)
    values = _group_values(path, robot, fit.params, fmt)
    prep = nominal.prepare(heldout)
    # what 'dynid validate --model FILE --data heldout' reports: the cut-off chosen on the held-out data
    prep_own = description_model(path, heldout).prepare(heldout)
    plain = column_set(robot.with_transmission(None), friction=True, armature=True)
    fl = np.zeros(n) if floor is None else np.asarray(floor, dtype=float)
    rms_nom = _heldout_rms(plain, values.file, prep)
    rms_cor = _heldout_rms(plain, values.fixed, prep)
    groups = _group_breakdown(plain, prep, values, fmt, rms_nom, fl)
    per, total = _closure(rms_cor, rms_nom, fl)
    params = fit.params
    return Correction(
        format=fmt,
        nominal=_values(robot.params, robot.armature, values.damping, values.loss, n),
        corrected=_values(params.standard, values.armature, params.damping, params.frictionloss, n),
        rms_nominal=rms_nom,
        rms_corrected=rms_cor,
        groups=groups,
        closure=per,
        closure_overall=total,
        floor=fl,
        export=fit.export,
        not_carried=fit.not_carried,
        reference=str(prep.reference),
        cutoff_hz=float(prep.settings.get("cutoff_hz") or float("nan")),
        rms_validate={
            "cutoff_hz": float(prep_own.settings.get("cutoff_hz") or float("nan")),
            "nominal": _heldout_rms(plain, values.file, prep_own).tolist(),
            "corrected": _heldout_rms(plain, values.fixed, prep_own).tolist(),
        },
        pull={
            "reference_weight": fit.weight,
            "mahalanobis": float(params.projection.get("mahalanobis", 0.0)),
        },
    )


@dataclass(frozen=True)
class _Fit:
    """The corrected simulator parameters, the pull's weight, the file written (or None) and what it leaves out."""

    params: Any
    weight: float
    export: Any
    not_carried: list[dict[str, Any]]


def _fit_and_write(path: Path, fmt: str, robot, train: Dataset, heldout: Dataset, out) -> _Fit:
    """Fit what the format carries on ``train``, pull it toward the file's bodies, and write it to ``out`` if given."""
    model = _consistent_fit(robot, train, fmt)
    weight, params = _pulled(model, robot)
    export = None
    if out is not None:
        from dynid.simmodel.export import export_model

        export = export_model(
            model,
            fmt,
            out,
            template=path,
            model_name=f"{path.name} corrected on data",
            reference_weight=weight,
            heldout=heldout,
        )
        params = export.params
    not_carried = params.not_carried if export is None else export.not_carried
    return _Fit(params=params, weight=weight, export=export, not_carried=not_carried)


def _consistent_fit(robot, train: Dataset, fmt: str):
    """The physically consistent fit of what the format carries, without its own standard set."""
    from dynid.identify.model import identify

    # no drive gain: the corrected description carries the bodies, and a gain it cannot carry would leave
    # them fitted to a torque the file does not predict
    model = identify(robot, train, friction="linear", gmm="off", armature=fmt == "mjcf", drive_gains=False)
    # The consistent fit's own standard set leaves what the data cannot see wherever its solver ended (the
    # Panda's first link at 2800 kg); the closest consistent set pulled toward the file's bodies replaces it.
    info = {k: v for k, v in model.info.items() if k != "consistency"}
    return replace(model, info=info)


@dataclass(frozen=True)
class _GroupValues:
    """Each group's values as the file holds them and corrected, and the file's and corrected extras."""

    file: dict[str, Any]
    fixed: dict[str, Any]
    damping: NDArray[np.float64]
    loss: NDArray[np.float64]
    armature: NDArray[np.float64]


def _group_values(path: Path, robot, params, fmt: str) -> _GroupValues:
    """The file's values and the corrected ones per group (no armature corrected for a URDF)."""
    armature = params.armature if fmt == "mjcf" else np.zeros(robot.n)
    damping0, loss0 = description_friction(path, robot.joint_names)
    file_values = {
        "link bodies": np.asarray(robot.params, dtype=float),
        "armature": np.asarray(robot.armature, dtype=float),
        "friction": (loss0, damping0),
    }
    fixed = {
        "link bodies": params.standard,
        "armature": armature,
        "friction": (params.frictionloss, params.damping),
    }
    return _GroupValues(file=file_values, fixed=fixed, damping=damping0, loss=loss0, armature=armature)


def _heldout_rms(plain, values: dict[str, Any], prep) -> NDArray[np.float64]:
    """Torque RMS per joint of the model with these group values against the prepared reference torque."""
    loss, damp = values["friction"]
    phi = np.concatenate([values["link bodies"], values["armature"], loss, damp, np.zeros(plain.n)])
    tau = linear_torque(plain, plain.P @ phi, prep.q, prep.dq, prep.ddq)
    return np.sqrt(np.mean((prep.tau_reference - prep.filter(tau)[prep.rows]) ** 2, axis=0))


def _closure(
    r: NDArray[np.float64], rms_nom: NDArray[np.float64], fl: NDArray[np.float64]
) -> tuple[NDArray[np.float64], float]:
    """Share of the nominal model's gap to the floor that RMS ``r`` closes: per joint and over all joints."""
    gap = rms_nom**2 - fl**2
    with np.errstate(divide="ignore", invalid="ignore"):
        per = np.where(gap > 0.05 * np.maximum(fl**2, 1e-300), (rms_nom**2 - r**2) / gap, np.nan)
    scale = 1.0 / np.maximum(fl, 1e-12) ** 2 if np.all(fl > 0) else 1.0 / np.maximum(rms_nom, 1e-12) ** 2
    den = float(np.sum(np.maximum(rms_nom**2 - fl**2, 0.0) * scale))
    total = float(np.sum((rms_nom**2 - r**2) * scale)) / den if den > 0 else float("nan")
    return per, total


def _group_breakdown(
    plain, prep, values: _GroupValues, fmt: str, rms_nom: NDArray[np.float64], fl: NDArray[np.float64]
) -> list[dict[str, Any]]:
    """The held-out RMS and overall closure with each group alone corrected, in :data:`GROUPS` order."""
    groups = []
    for g in GROUPS:
        mixed = dict(values.file)
        mixed[g] = values.fixed[g]
        r = _heldout_rms(plain, mixed, prep)
        applies = not (g == "armature" and fmt == "urdf")
        groups.append(
            {"group": g, "rms": r.tolist(), "closure": _closure(r, rms_nom, fl)[1], "applies": applies}
        )
    return groups


_PULLS = (1e-2, 1e-3, 1e-4, 0.0)
"""Weights of the pull toward the file's bodies, tried strongest first (see :func:`_pulled`)."""


def _pulled(model, robot):
    """The strongest pull toward the file's bodies that moves the fit by at most one standard deviation.

    The data hold some combinations of the standard parameters only loosely; within the fit's own
    uncertainty (Mahalanobis distance <= 1 from the identified parameters) the file's values are kept, so
    a body changes where the data support the change.  Returns ``(weight, SimParameters)``.
    """
    from dynid.simmodel.parameters import simulator_parameters

    for weight in _PULLS:
        params = simulator_parameters(model, robot, reference_weight=weight)
        if weight == 0.0 or params.projection.get("mahalanobis", 0.0) <= 1.0:
            return weight, params
    raise AssertionError("unreachable: the last weight is 0")
