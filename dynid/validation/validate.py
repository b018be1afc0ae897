"""Validation of identified models on held-out data: the engine of ``dynid validate``.

>>> result = validate(load_model("M.json"), load_dataset("V.csv", 6))
>>> result.figures()["rms"]                     # N m per joint, on the measured torque as compared
>>> table = compare([result, validate(load_model("M_ols.json"), data)])

How a prediction is compared
----------------------------
An identified model predicts a dataset as it was identified (:meth:`IdentifiedModel.predict`): the
states are reconstructed and, with parallel filtering, the rigid-body part is filtered like the
torque, trimmed and decimated.  The measured torque is compared after the same treatment (its
``reference``: ``raw``, or e.g. ``filtered and trimmed``); ``--predictions`` writes exactly the two
signals that were compared.

The prediction is split into its layers, so a report can show each of them:

* ``link``: the rigid-body part (base parameters and armature), filtered like the torque;
* ``friction``: layer 2 (or the linear friction identified with the links, filtered likewise);
* ``gmm``: the layer-3 correction.

The noise floor
---------------
What no model can predict, measured on the compared torque (never assumed), exactly as the gap
diagnosis measures it (:func:`dynid.validation.noise.measure_noise`): the spread across periods
when the data repeat a motion (``period`` given, read from the simulator's sidecar
``<data>.truth.json``, or detected from the angles) at least twice; otherwise the white-noise level
of the raw torque's spectrum carried through the filter.

The result (:class:`ValidationResult`, :func:`describe_model`) lives in :mod:`dynid.validation.result`
and the robot description's own model (:func:`nominal_model`, :func:`described_model`) in
:mod:`dynid.validation.baseline`; both are importable from here too.
"""

from __future__ import annotations

import io
import os
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from dynid.data.dataset import Dataset
from dynid.data.files import simulated_on, truth_sidecar
from dynid.data.preparation import Prepared, Preprocessing
from dynid.exceptions import DataError, DataWarning, ModelFileError, ShapeError, UsageError
from dynid.identify.columns import linear_torque
from dynid.identify.model import IdentifiedModel, identify
from dynid.validation.baseline import described_model, nominal_model
from dynid.validation.metrics import NoiseFloor, torque_metrics
from dynid.validation.noise import measure_noise
from dynid.validation.result import ValidationResult, describe_model

__all__ = [
    "COMPARISON",
    "IdentifiedMethod",
    "MethodSpec",
    "ValidationResult",
    "check_same_robot",
    "compare",
    "compare_methods",
    "describe_model",
    "described_model",
    "identify_methods",
    "nominal_model",
    "reference_noise_floor",
    "sidecar_period",
    "validate",
    "write_predictions",
]


# ---------------------------------------------------------------------------- checks
def check_same_robot(model: IdentifiedModel, data: Dataset, *, model_name: str = "the model") -> None:
    """Refuse data recorded on another robot than the model's.

    The joint counts must agree; a simulated dataset's sidecar (``<data>.truth.json``) also names its
    robot, which must be the model's.

    Parameters
    ----------
    model : IdentifiedModel
        The model.
    data : Dataset
        The data.
    model_name : str
        Name of the model in the message (e.g. its file).

    Raises
    ------
    ModelFileError
        Another robot.
    """
    robot = model.robot
    data_name = Path(str(data.meta.get("source", "the data"))).name
    if data.n != robot.n:
        raise ModelFileError(
            f"{model_name} was identified for '{robot.name}' ({robot.n} joints) but {data_name} has {data.n} "
            "joints; validate a model on data recorded on the robot it was identified for."
        )
    name = simulated_on(robot, data)
    if name is not None:
        raise ModelFileError(
            f"{model_name} was identified for '{robot.name}' but {data_name} was simulated on '{name}' "
            f"(its {data_name}.truth.json says so); validate a model on data of the robot it was identified for."
        )


def sidecar_period(data: Dataset) -> float | None:
    """Period (s) of the trajectory a simulated dataset followed, from its sidecar, or None.

    A Fourier trajectory repeats after its duration (a whole number of its periods): enough for the
    spread across repeats.

    Parameters
    ----------
    data : Dataset
        Data read by :func:`dynid.data.files.load_dataset` (its ``meta["source"]`` names the file).
    """
    side = truth_sidecar(data)
    traj = (side or {}).get("trajectory") or {}
    if traj.get("type") == "FourierTrajectory" and traj.get("duration"):
        return float(traj["duration"])
    return None


# ---------------------------------------------------------------------------- noise floor
def reference_noise_floor(prep: Prepared, *, period: float | None = None) -> NoiseFloor:
    """Noise floor of the torque as compared: the gap diagnosis' measurement, never an error.

    The same figure as :func:`dynid.validation.noise.measure_noise` (spread across periods, the
    period given or detected from the angles; else the raw spectrum through the filter's noise gain),
    so a validation and a diagnosis of the same data agree.  Data whose floor cannot be measured (no
    repeated period and too few samples for the spectrum) get NaN with the reason, not an error: the
    prediction error is still worth reporting.

    Parameters
    ----------
    prep : Prepared
        The prepared data (:meth:`IdentifiedModel.prepare`).
    period : float, optional
        Period (s) of the motion, if known.

    Returns
    -------
    NoiseFloor
    """
    try:
        return measure_noise(prep, period=period)
    except DataError as err:
        return NoiseFloor(std=np.full(prep.tau.shape[1], np.nan), method="unmeasured", detail=str(err))


# ---------------------------------------------------------------------------- validation
def _parts(model: IdentifiedModel, prep: Prepared, data: Dataset) -> tuple[NDArray[np.float64], ...]:
    """Rigid body, friction and GMM parts of the model's prediction of ``data`` (kept rows)."""
    cols, rows = model.columns, prep.rows
    layer1_friction = model.friction is not None and model.friction_source == "layer1"
    if hasattr(model, "predict_parts"):
        # The model's own split, so the parts always add up to model.predict(data); its "link" part
        # holds the friction identified with the links, taken out here for the friction figure.
        parts = model.predict_parts(data, prep=prep)
        link, fric, gmm = parts["link"], parts["friction"], parts["gmm"]
        if layer1_friction:
            lf = prep.filter(
                linear_torque(cols, model.params, prep.q, prep.dq, prep.ddq, mask=cols.friction_mask)
            )
            link, fric = link - lf[rows], fric + lf[rows]
        return link, fric, gmm
    link = prep.filter(linear_torque(cols, model.params, prep.q, prep.dq, prep.ddq, mask=cols.link_mask))[
        rows
    ]
    q_k, dq_k = prep.q[rows], prep.dq[rows]
    if model.friction is None:
        fric = np.zeros_like(link)
    elif layer1_friction:
        full = linear_torque(cols, model.params, prep.q, prep.dq, prep.ddq, mask=cols.friction_mask)
        fric = prep.filter(full)[rows]
    else:
        fric = model.friction.predict(dq_k)
    gmm = np.zeros_like(link) if model.gmr is None else model.gmr.predict(np.hstack([q_k, dq_k]))
    return link, fric, gmm


FAR_OFF_R2 = -1.0
"""Below this R^2 on a joint, validation says in one sentence that the model misses what drives it.

R^2 < -1: the error's variance is more than twice the torque's own, around its mean.  Measured: a torque
of the other sign (-3.4), two wrist joints swapped (-28 on one of them), the TX40 recording's joint 5
without its coupled wrist declared (-5.4); every joint of the Panda, TX40 and LWR4+ held-out parts
otherwise at -0.36 or above (the LWR4+'s joint 6, whose torque is near its noise)."""


def _warn_far_off(r2: NDArray[np.float64], name: str) -> None:
    far = np.flatnonzero(np.asarray(r2) < FAR_OFF_R2)
    if far.size == 0:
        return
    worst = far[np.argmin(np.asarray(r2)[far])]
    warnings.warn(
        f"{name} predicts joint(s) {', '.join(str(j + 1) for j in far)} worse than their mean torque would, by far "
        f"(joint {worst + 1}: R^2 {r2[worst]:.3g}): it misses what drives them there; check that the data were "
        "recorded on this robot, in its joint order, with torques of its sign and unit, or look for an effect the "
        "model lacks (a coupled transmission, ...: dynid diagnose names it)",
        DataWarning,
        stacklevel=3,
    )


def validate(
    model: IdentifiedModel,
    data: Dataset,
    *,
    period: float | None = None,
    label: str | None = None,
    info: dict[str, Any] | None = None,
) -> ValidationResult:
    """Predict held-out data with a model and measure the error against the noise floor.

    Parameters
    ----------
    model : IdentifiedModel
        The identified model (:func:`dynid.identify.model.load_model`).
    data : Dataset
        Held-out data of the same robot (not the identification data).
    period : float, optional
        Period (s) of a repeating motion, for the noise floor; default from the simulator's sidecar of
        the data file, else the spectrum is used.
    label : str, optional
        Name of the model in tables (default: its description).
    info : dict, optional
        Extra facts kept with the result (e.g. ``{"model_file": "M.json"}``).

    Returns
    -------
    ValidationResult

    Raises
    ------
    ModelFileError
        Data of another robot.
    DataError
        Data the model's preprocessing cannot use (too short for its filter, ...).
    """
    if not isinstance(model, IdentifiedModel):
        raise UsageError(
            f"model is a {type(model).__name__}; give an IdentifiedModel (identify(...) or load_model(path))."
        )
    if not isinstance(data, Dataset):
        raise UsageError(f"data is a {type(data).__name__}; give a Dataset (load_dataset(path)).")
    check_same_robot(model, data, model_name=(info or {}).get("model_file", "the model"))
    prep = model.prepare(data)
    if prep.m < 2:
        raise DataError(
            f"the data keep {prep.m} sample(s) after the model's preprocessing; validate on a longer recording."
        )
    link, fric, gmm = _parts(model, prep, data)
    tau = prep.tau_reference
    pred = link + fric + gmm
    metrics = torque_metrics(tau, pred)
    _warn_far_off(metrics["r2"], (info or {}).get("model_file") or label or "the model")
    if period is None:
        period = sidecar_period(data)
    source = data.meta.get("source")
    return ValidationResult(
        label=label or describe_model(model),
        model=model,
        t=prep.t[prep.rows],
        q=prep.q[prep.rows],
        dq=prep.dq[prep.rows],
        tau=tau,
        tau_pred=pred,
        tau_link=link,
        tau_friction=fric,
        tau_gmm=gmm,
        metrics=metrics,
        metrics_before_gmm=torque_metrics(tau, link + fric),
        noise=reference_noise_floor(prep, period=period),
        reference=prep.reference,
        data=Path(str(source)).name if source else str(data.meta.get("recording", "held-out data")),
        info=dict(info or {}),
    )


def compare(results: Sequence[ValidationResult]) -> list[dict[str, Any]]:
    """One row per model validated on the same data: the table of ``--compare``.

    Parameters
    ----------
    results : sequence of ValidationResult
        Results on one dataset (same samples and reference).

    Returns
    -------
    list of dict
        :meth:`ValidationResult.summary` of each, in order.

    Raises
    ------
    ShapeError
        Results on different samples: the models were identified with different preprocessing, so
        their errors are not on the same torque.
    """
    if not results:
        return []
    first = results[0]
    for other in results[1:]:
        if other.tau.shape != first.tau.shape or not np.allclose(other.tau, first.tau, rtol=1e-9, atol=1e-9):
            raise ShapeError(
                f"'{other.label}' is compared on another torque than '{first.label}' (different filtering, "
                "trimming or decimation); identify the models with the same preprocessing to compare them."
            )
    return [r.summary() for r in results]


# ---------------------------------------------------------------------------- files
def write_predictions(result: ValidationResult, path: str | os.PathLike[str]) -> Path:
    """Write ``t, tau_1..tau_n, tau_pred_1..tau_pred_n`` (the compared signals) as CSV, atomically.

    Parameters
    ----------
    result : ValidationResult
        The validation.
    path : str or path-like
        CSV file in an existing folder.

    Returns
    -------
    Path
    """
    from dynid._io import write_text

    n = result.n
    header = ["t", *(f"tau_{j + 1}" for j in range(n)), *(f"tau_pred_{j + 1}" for j in range(n))]
    buf = io.StringIO()
    np.savetxt(
        buf,
        np.column_stack([result.t, result.tau, result.tau_pred]),
        delimiter=",",
        header=",".join(header),
        comments="",
        fmt="%.10g",
    )
    path = Path(path)
    write_text(path, buf.getvalue())
    return path


# ---------------------------------------------------------------------------- a reference model
# ---------------------------------------------------------------------------- methods side by side
class MethodSpec(NamedTuple):
    """One model of a comparison: its label and how :func:`dynid.identify.model.identify` makes it.

    Parameters
    ----------
    label : str
        Name in tables and legends.
    method : str
        Layer-1 method (``ols``, ``wls``, ``gls``, ``irls``, ``consistent``).
    friction : str
        Friction model (``none``, ``linear``, ``seed``, ``stribeck``, ``sigmoid``).
    gmm : str or int
        Layer 3: ``off``, ``auto`` or a number of components.
    reference_weight : float
        Consistent method: pull toward the URDF bodies.
    """

    label: str
    method: str
    friction: str
    gmm: str | int
    reference_weight: float = 0.0


COMPARISON: tuple[MethodSpec, ...] = (
    MethodSpec("full", "consistent", "seed", "auto"),
    MethodSpec("OLS", "ols", "linear", "off"),
    MethodSpec("IRLS", "irls", "linear", "off"),
)
"""The paper's comparison: the full method first (physically consistent links with IRLS weighting,
the paper's friction model, the GMM layer), then OLS and IRLS with linear friction identified with
the links."""


@dataclass(frozen=True, eq=False)
class IdentifiedMethod:
    """A model identified by one of several methods (:func:`identify_methods`).

    Attributes
    ----------
    label : str
        Its name in tables (``full``, ``OLS``, ...).
    model : IdentifiedModel
        The model.
    seconds : float
        Identification time (s).
    warnings : list of str
        Warnings raised while identifying (e.g. IPOPT stopped at its iteration limit).
    """

    label: str
    model: IdentifiedModel
    seconds: float
    warnings: list[str]


def identify_methods(
    robot,
    train: Dataset,
    *,
    methods: Sequence[MethodSpec | tuple] = COMPARISON,
    preprocessing: Preprocessing | None = None,
    random_state: int = 0,
    progress: Callable[[str], None] | None = None,
) -> list[IdentifiedMethod]:
    """Identify a robot by several methods on the same data (the same preprocessing for all).

    Parameters
    ----------
    robot : RobotModel
        The robot that recorded the data.
    train : Dataset
        Identification data.
    methods : sequence of MethodSpec
        The models to identify (default :data:`COMPARISON`); plain tuples
        ``(label, method, friction, gmm[, reference_weight])`` work too.
    preprocessing : Preprocessing, optional
        Filtering and decimation, the same for every model.
    random_state : int
        Seed of the GMM layer's EM.
    progress : callable, optional
        Receives a line per model (with its time) and one per warning.

    Returns
    -------
    list of IdentifiedMethod
    """
    out = []
    for spec in methods:
        spec = MethodSpec(*spec)
        label = spec.label
        start = time.perf_counter()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            model = identify(
                robot,
                train,
                method=spec.method,
                friction=spec.friction,
                gmm=spec.gmm,
                preprocessing=preprocessing,
                reference_weight=spec.reference_weight,
                random_state=random_state,
            )
        seconds = time.perf_counter() - start
        notes = list(dict.fromkeys(str(w.message) for w in caught))
        if progress is not None:
            progress(f"{label}: {describe_model(model)}, {seconds:.1f} s")
            for note in notes:
                progress(f"  note: {note}")
        out.append(IdentifiedMethod(label=label, model=model, seconds=seconds, warnings=notes))
    return out


def compare_methods(
    robot,
    train: Dataset,
    heldout: Dataset,
    *,
    methods: Sequence[MethodSpec | tuple] = COMPARISON,
    preprocessing: Preprocessing | None = None,
    baseline: bool = False,
    period: float | None = None,
    random_state: int = 0,
    progress: Callable[[str], None] | None = None,
) -> list[ValidationResult]:
    """Identify a robot by several methods on the same data and validate each on held-out data.

    Parameters
    ----------
    robot : RobotModel
        The robot that recorded the data.
    train : Dataset
        Identification data.
    heldout : Dataset
        Held-out data (another run, or the later part of one).
    methods : sequence of MethodSpec
        The models to identify (default :data:`COMPARISON`); the first is the one a report shows in
        detail.
    preprocessing : Preprocessing, optional
        The same for every model, so that their errors are on the same torque.
    baseline : bool
        Also validate the robot description's own parameters with linear friction fitted on ``train``
        (:func:`nominal_model`), labelled ``URDF``, last.
    period : float, optional
        Period (s) of the held-out motion, for the noise floor.
    random_state : int
        Seed of the GMM layer's EM.
    progress : callable, optional
        Receives a line per model identified (with its time and any warning).

    Returns
    -------
    list of ValidationResult
        One per model, in order; ``info`` holds ``seconds`` (identification time) and ``warnings``.
    """
    fitted = identify_methods(
        robot,
        train,
        methods=methods,
        preprocessing=preprocessing,
        random_state=random_state,
        progress=progress,
    )
    if baseline:
        start = time.perf_counter()
        model = nominal_model(robot, train, preprocessing=preprocessing)
        seconds = time.perf_counter() - start
        if progress is not None:
            progress(f"URDF: the robot description's parameters with linear friction fitted, {seconds:.1f} s")
        fitted.append(IdentifiedMethod(label="URDF", model=model, seconds=seconds, warnings=[]))
    results = [
        validate(
            f.model,
            heldout,
            period=period,
            label=f.label,
            info={"seconds": f.seconds, "warnings": f.warnings},
        )
        for f in fitted
    ]
    compare(results)
    return results
