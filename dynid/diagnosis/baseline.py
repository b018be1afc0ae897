"""The diagnosis' data and baseline: both datasets prepared as the model's were, the baseline refitted.

Stages, in the order :func:`dynid.diagnosis.core.diagnose` runs them:

1. :func:`model_structure`: the robot, the model's columns, its preprocessing and friction shape
   (the data of another robot are refused); :func:`check_training_length`.
2. :func:`sample`: one dataset prepared (the same filter on the torque and on every regressor column:
   parallel filtering), thinned, with its baseline columns at full rate and filtered (:class:`Sample`).
3. :func:`refit_baseline`: the base parameters and the model's own extra columns (armature, linear
   friction, the shape of its friction layer) identified again on the training data by weighted least
   squares, reweighted by the residual level per joint until the weights settle (:class:`Baseline`).
4. :func:`side`: a sample with the refit's torque, from which the candidates' columns are built
   (:class:`Side`, whose :class:`~dynid.diagnosis.candidates.FeatureSource` is complete when made).
5. :func:`heldout_baseline` and :func:`excess_over_floor`: the refit's held-out error, the model's as
   given, and whether the excess over the noise floor is significant.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynid.data.dataset import Dataset
from dynid.data.preparation import Prepared, Preprocessing, prepare
from dynid.diagnosis import stats as st
from dynid.diagnosis.candidates import Candidate, FeatureSource, candidate_columns
from dynid.diagnosis.fitting import WeightedFit, losses, mse, predict
from dynid.diagnosis.settings import DiagnosisSettings
from dynid.exceptions import DataError, IdentificationError, ShapeError, UsageError
from dynid.identify.columns import ColumnSet, column_set, compiled_base_regressor

__all__ = [
    "Baseline",
    "HeldOutBaseline",
    "ModelStructure",
    "Sample",
    "Side",
    "StateNoise",
    "check_training_length",
    "crossfit_residual",
    "excess_over_floor",
    "heldout_baseline",
    "model_structure",
    "refit_baseline",
    "sample",
    "side",
    "state_estimation_variance",
    "state_noise",
]

_STATE_FACTOR = 2.0  # state filter cut-off over the parallel filter's in the refit
_WEIGHT_PASSES = 6  # reweighting passes of the baseline refit, at most
_MIN_TRAIN_SECONDS = 2.0
FOLDS = 5  # contiguous held-out stretches of the cross-fitted baseline and candidates
_CAP = 20.0  # block means of the excess test above the level are capped here (noise variances)

FrictionShape = Callable[[NDArray[np.float64]], NDArray[np.float64]]


# ---------------------------------------------------------------------------- the model's structure
@dataclass(frozen=True, eq=False)
class ModelStructure:
    """What the baseline refit keeps of the model: its robot, columns, preprocessing and friction shape.

    Attributes
    ----------
    robot : RobotModel
    columns : ColumnSet
        Base parameters and the model's extra columns.
    preprocessing : dict
        The model's preprocessing settings (states filtered at twice the cut-off where the model filters
        them at the parallel filter's).
    friction_shape : callable or None
        ``f(dq) -> (M, n)``: the shape of the model's friction layer, one column per joint.
    """

    robot: Any
    columns: ColumnSet
    preprocessing: dict[str, Any]
    friction_shape: FrictionShape | None


def model_structure(model, robot, train: Dataset, heldout: Dataset) -> ModelStructure:
    """The structure the baseline is refitted with, after checking both datasets against the robot.

    Raises
    ------
    UsageError
        Neither a model nor a robot.
    DataError
        Data that are not a Dataset.
    ShapeError
        Data of another robot (joint count).
    """
    if model is None and robot is None:
        raise UsageError("diagnose needs the identified model or, without one, robot=...; give either.")
    robot = model.robot if model is not None else robot
    for label, ds in (("training", train), ("held-out", heldout)):
        if not isinstance(ds, Dataset):
            raise DataError(
                f"the {label} data are a {type(ds).__name__}; give a Dataset (load_dataset(path) or Dataset(t, q, tau))."
            )
        if ds.n != robot.n:
            raise ShapeError(
                f"the {label} data have {ds.n} joints; the model's robot '{robot.name}' has {robot.n}: give data "
                "recorded on that robot."
            )
    if model is not None:
        cols = model.columns
        if cols.n_effect:
            # the baseline refits the model's own columns; its effect terms are candidates like any other
            cols = column_set(robot, friction=cols.friction, armature=cols.armature)
        settings = dict(model.preprocessing)
        shape = None
        if model.friction is not None and model.friction_source == "layer2":
            fr = model.friction

            def shape(dq, fr=fr):
                return fr.predict(dq)
    else:
        cols = column_set(robot, friction=True, armature=False)
        settings = Preprocessing().resolve(train)
        shape = None
    cutoff = settings.get("cutoff_hz")
    if cutoff is not None and settings.get("parallel") and settings.get("state_cutoff_hz") == cutoff:
        # The states are low-passed before differentiation and the regressor again in parallel with the
        # torque: at one cut-off the inertial columns are filtered twice where the torque is filtered once,
        # which leaves a residual at every sharp feature (reversals).  The refit differentiates states
        # filtered at twice the cut-off, so that the parallel filter sets the band alone.
        fs = 1.0 / train.dt
        settings = {**settings, "state_cutoff_hz": float(min(_STATE_FACTOR * cutoff, 0.4 * fs))}
    return ModelStructure(robot=robot, columns=cols, preprocessing=settings, friction_shape=shape)


def check_training_length(structure: ModelStructure, train: Dataset) -> None:
    """Refuse training data too short to refit the baseline with a candidate and tune its hyper-parameters.

    Raises
    ------
    IdentificationError
        Too few samples for the baseline and a candidate.
    """
    cols, settings = structure.columns, structure.preprocessing
    n = cols.n
    k = cols.p + (n if structure.friction_shape is not None else 0) + 8  # baseline + the largest candidate
    trim = float(settings.get("trim_s") or 0.0)
    usable = max(train.duration - 2 * trim, 0.0)
    samples = int(usable / train.dt) // max(int(settings.get("decimate") or 1), 1)
    need = max(_MIN_TRAIN_SECONDS, 10.0 * k / n * train.dt * max(int(settings.get("decimate") or 1), 1))
    if usable < need or samples * n < 10 * k:
        raise IdentificationError(
            f"the training data give {usable:.2g} s ({samples} samples) after trimming, too few to refit the "
            f"{cols.p} model parameters with a candidate effect and tune it; give at least {need + 2 * trim:.2g} s "
            "(in practice several periods of an exciting trajectory)."
        )


def _structure_columns(structure: ModelStructure, q, dq, ddq) -> NDArray[np.float64]:
    """Full-rate baseline columns (M, n, k0) at the states given: base regressor, the model's extras, its
    friction shape."""
    cols, friction_shape = structure.columns, structure.friction_shape
    robot = cols.robot
    M, n = q.shape
    nb = cols.n_base
    extras = len(cols.extras)
    k0 = nb + extras + (n if friction_shape is not None else 0)
    X = np.zeros((M, n, k0))
    chunk = 16384
    for a in range(0, M, chunk):
        s = slice(a, min(a + chunk, M))
        X[s, :, :nb] = compiled_base_regressor(robot, q[s], dq[s], ddq[s])
    if extras:
        E = cols.extra_columns(dq, ddq)
        # a coupled motor's columns reach several joints (its weights); the others their own joint
        X[:, :, nb : nb + extras] = E[:, None, :] * cols.extra_weights[None, :, :]
    if friction_shape is not None:
        F = friction_shape(dq)
        for j in range(n):
            X[:, j, nb + extras + j] = F[:, j]
    return X


def _torque_function(structure: ModelStructure, x: NDArray[np.float64]):
    """``f(q, dq, ddq) -> (M, n)``: the baseline torque with coefficients x at any states (full rate)."""

    def torque_at(q, dq, ddq):
        return np.einsum("mnk,k->mn", _structure_columns(structure, q, dq, ddq), x)

    return torque_at


# ---------------------------------------------------------------------------- one dataset
@dataclass(frozen=True, eq=False)
class Sample:
    """One dataset prepared for the diagnosis, before the baseline refit.

    Attributes
    ----------
    prep : Prepared
        The data as the model sees them (full rate).
    rows : ndarray of int, shape (m,)
        Rows used (thinned evenly to at most ``max_samples``).
    y : ndarray, shape (m, n)
        Filtered torque at those rows (N m).
    X0 : ndarray, shape (m, n, k0)
        Filtered baseline columns at those rows.
    X_full : ndarray, shape (M, n, k0)
        Unfiltered baseline columns at full rate (the refit's torque is built from them).
    moving : ndarray, shape (m, n)
        1 where a joint moves faster than ``stick_fraction`` of its top speed, else 0.
    """

    prep: Prepared
    rows: NDArray[np.intp]
    y: NDArray[np.float64]
    X0: NDArray[np.float64]
    X_full: NDArray[np.float64]
    moving: NDArray[np.float64]


def sample(structure: ModelStructure, ds: Dataset, settings: DiagnosisSettings) -> Sample:
    """Prepare one dataset as the model's data were, thin it, and build its baseline columns."""
    prep = prepare(ds, Preprocessing.from_settings(structure.preprocessing), n_joints=structure.robot.n)
    stride = max(1, math.ceil(len(prep.rows) / settings.max_samples))
    rows = prep.rows[::stride]
    X_full = _structure_columns(structure, prep.q, prep.dq, prep.ddq)
    X0 = prep.filter(X_full)[rows]
    y = prep.filter(prep.tau)[rows]
    # Coulomb friction is ill-defined near zero speed: sticking there is left to the gap map, not to the
    # attribution.
    dq = prep.dq[rows]
    top = np.max(np.abs(dq), axis=0)
    moving = (np.abs(dq) >= settings.stick_fraction * np.maximum(top, 1e-12)).astype(float)
    return Sample(prep=prep, rows=rows, y=y, X0=X0, X_full=X_full, moving=moving)


@dataclass(frozen=True, eq=False)
class Side:
    """One dataset with the baseline refit's torque: what candidates are built from and scored on.

    Attributes
    ----------
    prep, rows, y, X0, moving
        As in :class:`Sample`.
    src : FeatureSource
        Full-rate states and the refit's torque (full and links' share, and at other states).
    """

    prep: Prepared
    rows: NDArray[np.intp]
    y: NDArray[np.float64]
    X0: NDArray[np.float64]
    moving: NDArray[np.float64]
    src: FeatureSource

    def filt(self, A: NDArray[np.float64]) -> NDArray[np.float64]:
        """Filter full-rate columns (M, ...) like the torque and keep the rows used."""
        return self.prep.filter(A)[self.rows]

    def columns(self, cand: Candidate) -> NDArray[np.float64]:
        """A candidate's columns (m, n, c), filtered like the torque, at the rows used."""
        return self.filt(candidate_columns(self.src, cand))

    @property
    def t(self) -> NDArray[np.float64]:
        """Time (s) of the rows used."""
        return self.prep.t[self.rows]


def side(s: Sample, structure: ModelStructure, x: NDArray[np.float64]) -> Side:
    """A sample with the refit's torque at full rate (unfiltered): what the candidates' load, delay and
    elasticity columns use; for the transmission, the links' share (the base columns, which come first;
    armature and friction act on the motor side)."""
    nb = structure.columns.n_base
    x_link = np.concatenate([x[:nb], np.zeros(len(x) - nb)])
    prep = s.prep
    src = FeatureSource(
        t=prep.t,
        q=prep.q,
        dq=prep.dq,
        ddq=prep.ddq,
        tau_pred=np.einsum("mnk,k->mn", s.X_full, x),
        robot=structure.robot,
        fs=prep.fs,
        runs=prep.runs,
        torque_at=_torque_function(structure, x),
        tau_link=np.einsum("mnk,k->mn", s.X_full[:, :, :nb], x[:nb]),
        link_torque_at=_torque_function(structure, x_link),
    )
    return Side(prep=prep, rows=s.rows, y=s.y, X0=s.X0, moving=s.moving, src=src)


# ---------------------------------------------------------------------------- baseline refit
@dataclass(frozen=True, eq=False)
class Baseline:
    """The baseline refitted on the training data.

    Attributes
    ----------
    fit : WeightedFit
        The last weighted fit (its covariance, and the candidates' projections).
    x : ndarray, shape (k0,)
        Coefficients of the baseline columns.
    weights : ndarray, shape (m, n)
        Weight per training row and joint (the moving mask over the residual level per joint).
    passes : int
        Reweighting passes run.
    settled : bool
        The weights moved by less than 5 % in the last pass.
    """

    fit: WeightedFit
    x: NDArray[np.float64]
    weights: NDArray[np.float64]
    passes: int
    settled: bool


def refit_baseline(tr: Sample) -> Baseline:
    """Weighted least squares of the baseline on training data: weights from a first unweighted pass,
    then the residual level per joint, until they settle."""
    n = tr.y.shape[1]
    mt = tr.moving
    fit = WeightedFit(tr.X0, tr.y, mt)
    x, _, _ = fit.solve()
    # Reweighted until the weights settle: one pass from the unweighted fit leaves a light joint (a
    # wrist) under-weighted, its residual inflated by the heavy joints' model errors (an effect-free
    # UR5 showed 3.4x the noise floor on joint 6 after one pass, 1.3x after three).
    w = np.zeros(n)
    settled, passes = False, 0
    W = mt
    for passes in range(1, _WEIGHT_PASSES + 1):  # noqa: B007 - the count is reported
        w_new = 1.0 / np.maximum(np.sqrt(mse(tr.y - predict(tr.X0, x, None, None), mt)), 1e-12)
        settled = bool(np.all(np.abs(w_new - w) <= 0.05 * w_new))
        w = w_new
        W = mt * w[None, :]
        fit = WeightedFit(tr.X0, tr.y, W)
        x, _, _ = fit.solve()
        if settled:
            break
    return Baseline(fit=fit, x=x, weights=W, passes=passes, settled=settled)


# ---------------------------------------------------------------------------- held-out error and excess
@dataclass(frozen=True, eq=False)
class HeldOutBaseline:
    """The refitted baseline (and the model as given) on the held-out data.

    Attributes
    ----------
    residual : ndarray, shape (m, n)
        Filtered held-out torque minus the refit's prediction (N m).
    loss : ndarray, shape (m,)
        Per-sample loss ``sum_j mask_j r_j^2 / sigma_j^2`` (noise variances).
    mse : ndarray, shape (n,)
        Mean squared residual per joint (N^2 m^2).
    mse_model : ndarray, shape (n,)
        The same of the model as given (its own prediction path).
    """

    residual: NDArray[np.float64]
    loss: NDArray[np.float64]
    mse: NDArray[np.float64]
    mse_model: NDArray[np.float64]


def heldout_baseline(model, heldout: Dataset, ho: Side, x: NDArray[np.float64], sigma) -> HeldOutBaseline:
    """The refit's held-out residual and error, and the error of the model as given on the same rows."""
    mh = ho.moving
    r_base = ho.y - predict(ho.X0, x, None, None)
    mse_base = mse(r_base, mh)
    if model is not None:
        prep_all = model.prepare(heldout)
        pred = model.predict(heldout)
        ref = prep_all.tau_reference
        pick = np.searchsorted(prep_all.rows, ho.rows)
        mse_model = mse(ref[pick] - pred[pick], mh)
    else:
        mse_model = mse_base.copy()
    return HeldOutBaseline(residual=r_base, loss=losses(r_base, sigma, mh), mse=mse_base, mse_model=mse_model)


def _estimation_weights(
    fit: WeightedFit,
    X: NDArray[np.float64],
    mask: NDArray[np.float64],
    sigma: NDArray[np.float64],
    block: int,
) -> list[NDArray[np.float64]]:
    """Per joint, the eigenvalues of the mean held-out squared error (in noise variances) that the
    refit's parameter error leaves: ``delta^T H_j delta`` with ``delta ~ N(0, C)``, C the refit's block
    (HAC) covariance and ``H_j`` the held-out mean of ``x x^T`` on joint j.  Their sum is its expectation."""
    cov = np.nan_to_num(fit.covariance(block))
    lam, V = np.linalg.eigh(0.5 * (cov + cov.T))
    L = V * np.sqrt(np.maximum(lam, 0.0))[None, :]
    out = []
    for j in range(X.shape[1]):
        XL = X[:, j, :] @ L
        H = (XL * mask[:, j, None]).T @ XL / max(float(np.sum(mask[:, j])), 1.0) / sigma[j] ** 2
        out.append(np.maximum(np.linalg.eigvalsh(0.5 * (H + H.T)), 0.0))
    return out


def state_estimation_variance(
    structure: ModelStructure,
    ds: Dataset,
    s: Sample,
    x: NDArray[np.float64],
    sigma: NDArray[np.float64],
    *,
    seed: int = 0,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """What quantised angles add to the held-out error, per joint, in noise variances.

    The encoder's step is read from the angles (:func:`dynid.validation.noise.encoder_step`).  The
    angles' error is taken as uniform within one step, white: the angles are moved by such an error, put
    through the same preparation (filter, central differences) and the baseline refit's torque, and the
    change of the filtered torque at the rows used, over the noise floor, is the share of the held-out
    error that differentiating coarse angles leaves (the error of the measured angles themselves is of
    the same size and independent of the torque noise).  Angles that are not quantised give zeros.

    Parameters
    ----------
    structure : ModelStructure
    ds : Dataset
        The held-out data as given.
    s : Sample
        Its prepared sample (:func:`sample`).
    x : ndarray, shape (k0,)
        The baseline refit's coefficients.
    sigma : ndarray, shape (n,)
        Noise floor (N m).
    seed : int
        Seed of the simulated angle error (reproducible).

    Returns
    -------
    (variance, step) : tuple of ndarray, shape (n,)
        Mean squared torque change over the moving rows in noise variances, and the step (rad) per joint.
    """

    from dynid.validation.noise import encoder_step

    n = structure.robot.n
    step = encoder_step(ds.q)
    if not np.any(step > 0):
        return np.zeros(n), step
    prep = _moved_angles(structure, ds, s, step, seed)
    if prep is None:
        return np.zeros(n), step
    tau = prep.filter(np.einsum("mnk,k->mn", _structure_columns(structure, prep.q, prep.dq, prep.ddq), x))
    change = tau[s.rows] - predict(s.X0, x, None, None)
    return mse(change, s.moving) / sigma**2, step


def _moved_angles(structure: ModelStructure, ds: Dataset, s: Sample, step: NDArray[np.float64], seed: int):
    """The held-out run prepared with its angles moved by a white error uniform within ``step`` (seeded),
    or None when the preparation keeps other rows than ``s``."""
    from dataclasses import replace

    rng = np.random.default_rng(seed)
    moved = replace(ds, q=ds.q + rng.uniform(-0.5, 0.5, ds.q.shape) * step[None, :])
    prep = prepare(moved, Preprocessing.from_settings(structure.preprocessing), n_joints=structure.robot.n)
    if len(prep.rows) != len(s.prep.rows) or np.any(prep.rows != s.prep.rows):
        return None
    return prep


STATE_DRAWS = 3
"""Draws of the angles' error through which a candidate's gain from the state estimation is measured
(:class:`StateNoise`)."""


@dataclass(frozen=True, eq=False)
class StateNoise:
    """Draws of the quantised angles' error put through the held-out preparation: what the candidates'
    columns and the baseline's prediction share of it (errors in the variables).

    The angles are differentiated twice, so their error reaches every column built from the states: the
    baseline's prediction, whose error is part of the held-out residual, and a candidate's columns.  A
    candidate whose columns move with that error (second derivatives of the torque: elasticity, backlash)
    cancels part of the residual's share of it, on held-out data as on training data, with no effect
    behind it (:func:`dynid.diagnosis.screening.state_gain`).  Each draw moves the held-out angles by a
    white error uniform within the encoder's step, as :func:`state_estimation_variance` does (the first
    draw is its draw), and prepares them as the held-out run.

    Attributes
    ----------
    sides : list of Side
        Per draw, the held-out run with its angles moved, with the baseline refit's torque (the
        candidates' columns are built from it).
    dX : list of ndarray, shape (m, n, k0)
        Per draw, the change of the filtered baseline columns at the rows used.
    """

    sides: list[Side]
    dX: list[NDArray[np.float64]]


def state_noise(
    structure: ModelStructure, ds: Dataset, s: Sample, x: NDArray[np.float64], *, draws: int = STATE_DRAWS
) -> StateNoise | None:
    """The held-out run's draws of the angles' error (:class:`StateNoise`); None when the angles are not
    quantised or the preparation keeps other rows.

    Parameters
    ----------
    structure : ModelStructure
    ds : Dataset
        The held-out data as given.
    s : Sample
        Its prepared sample (:func:`sample`).
    x : ndarray, shape (k0,)
        The baseline refit's coefficients.
    draws : int
        Draws, seeded 0, 1, ... (reproducible).
    """

    from dynid.validation.noise import encoder_step

    step = encoder_step(ds.q)
    if not np.any(step > 0):
        return None
    sides, dX = [], []
    for seed in range(draws):
        prep = _moved_angles(structure, ds, s, step, seed)
        if prep is None:
            return None
        X_full = _structure_columns(structure, prep.q, prep.dq, prep.ddq)
        drawn = Sample(
            prep=prep, rows=s.rows, y=s.y, X0=prep.filter(X_full)[s.rows], X_full=X_full, moving=s.moving
        )
        sides.append(side(drawn, structure, x))
        dX.append(drawn.X0 - s.X0)
    return StateNoise(sides=sides, dX=dX)


def crossfit_residual(
    tr: Side | Sample,
    weights: NDArray[np.float64],
    ho: Side | Sample,
    sigma: NDArray[np.float64],
    folds: int = FOLDS,
) -> NDArray[np.float64]:
    """Held-out residual of the baseline refitted on the training data and the other held-out folds.

    The held-out run is cut into ``folds`` contiguous stretches; each is predicted by the baseline
    identified (weighted least squares, the training rows with the refit's weights, the held-out rows with
    the moving mask over the noise floor) on the training data together with the other stretches.  What
    the baseline's own parameters can learn from held-out data (a gravity error where the held-out motion
    leaves the training states) is then predicted; what no parameter of the baseline predicts on data it
    was not fitted on (an unmodelled effect, noise) is left.

    Parameters
    ----------
    tr, ho : Side or Sample
        Training and held-out data (their filtered baseline columns ``X0`` and torque ``y``).
    weights : ndarray, shape (m_tr, n)
        The refit's training weights (1 / N m).
    sigma : ndarray, shape (n,)
        Held-out noise floor (N m).
    folds : int
        Contiguous held-out stretches.

    Returns
    -------
    ndarray, shape (m_ho, n)
        Cross-fitted held-out residual (N m).
    """
    from dynid.diagnosis.crossfold import CrossFold

    cf = CrossFold(tr.X0, tr.y, weights, ho.X0, ho.y, ho.moving / sigma[None, :], folds)
    return cf.residual()


def excess_over_floor(
    fit: WeightedFit,
    ho: Side,
    base: HeldOutBaseline,
    sigma: NDArray[np.float64],
    block: int,
    settings: DiagnosisSettings,
    *,
    crossfit: NDArray[np.float64] | None = None,
    state_variance: NDArray[np.float64] | None = None,
    floor_rel_se: NDArray[np.float64] | None = None,
) -> dict[str, Any]:
    """Excess of the refit's held-out error over the noise floor, per joint, and its significance.

    Per joint: is the excess above ``1 + tol`` noise variances (plus the state estimation's share,
    ``state_variance``), beyond the serial correlation and beyond what the baseline's own parameters
    explain on held-out data?  Where the floor states its precision (``floor_rel_se``, the relative
    standard error of its variance per joint: a floor measured across periods), the test integrates the
    floor's own error (:func:`dynid.diagnosis.stats.excess_test`'s ``rel_se``) and ``tol`` is
    ``settings.measured_excess_tol``; elsewhere the floor is taken as exact and the wider
    ``settings.excess_tol`` absorbs its error.

    A training run that excites a joint poorly leaves its parameters uncertain, and the held-out motion
    can see that error at many times the noise floor (an effect-free UR5 run on an aperiodic held-out
    motion showed 16 noise variances of it on joint 2, 17 times what the refit's covariance allows: what
    the training run's noise cannot show).  With ``crossfit`` (the residual of
    :func:`crossfit_residual`) the test runs on what a baseline that has seen the rest of the held-out run
    still leaves; without it, the refit's parameter error is allowed for through its block covariance.
    Block means are capped at ``_CAP`` noise variances above the level (:func:`dynid.diagnosis.stats.excess_test`).

    Returns
    -------
    dict
        ``ratio`` (per joint: the refit's held-out MSE over the floor), ``ratio_tested`` (what the test
        ran on: the cross-fitted residual's), ``ratio_overall``, ``p_joint`` (Holm-adjusted), ``p_value``,
        ``significant_joint``, ``significant``, ``tolerance`` (per joint), ``floor_rel_se`` (per joint,
        None where not integrated), ``estimation`` (the share of the refit's
        parameter error, noise variances per joint: expected from its covariance, or, cross-fitted, what
        the refit on the other held-out folds removes), ``state_estimation`` (noise variances per joint),
        ``explainable`` (the sources counted as noise-like).
    """
    mh = ho.moving
    n = mh.shape[1]
    rel = np.full(n, np.nan) if floor_rel_se is None else np.asarray(floor_rel_se, dtype=float)
    known = np.isfinite(rel) & (rel > 0)
    tol = np.where(known, settings.measured_excess_tol, settings.excess_tol)
    ratio_joint = base.mse / sigma**2
    ratio_all = float(np.sum(base.loss) / np.sum(mh))
    state = np.zeros(n) if state_variance is None else np.asarray(state_variance, dtype=float)
    if crossfit is None:
        r_test = base.residual
        est_w = _estimation_weights(fit, ho.X0, mh, sigma, block)
        sources = ["torque noise (floor)", "the refit's parameter error (block covariance)"]
    else:
        r_test = crossfit
        est_w = [np.zeros(0) for _ in range(n)]
        sources = ["torque noise (floor)", "the baseline's parameters refitted on the other held-out folds"]
    if known.any():
        sources.insert(
            1,
            f"the floor's own sampling error (its variance known to +-{100 * float(np.median(rel[known])):.0f} %; "
            f"{settings.measured_excess_tol:g} noise variance of misfit allowed beside it"
            + (f", {settings.excess_tol:g} where its precision is unknown" if not known.all() else "")
            + ")",
        )
    if np.any(state > 0):
        sources.append("state estimation from quantised angles")
    ratio_test = mse(r_test, mh) / sigma**2
    share = np.mean(mh, axis=0)
    p_joint = np.array(
        [
            st.excess_test(
                mh[:, j] * (r_test[:, j] / sigma[j]) ** 2,
                (1 + tol[j] + state[j]) * mh[:, j],
                share[j] * est_w[j],
                block=block,
                cap=_CAP,
                scaled=(1 + tol[j]) * mh[:, j],
                rel_se=float(rel[j]) if known[j] else None,
            )
            for j in range(n)
        ]
    )
    p_joint = st.holm(p_joint)
    sig_joint = (p_joint < settings.alpha) & (ratio_test > 1 + tol + state)
    return {
        "ratio": ratio_joint,
        "ratio_tested": ratio_test,
        "ratio_overall": ratio_all,
        "p_joint": p_joint,
        "p_value": float(p_joint.min()),
        "significant_joint": sig_joint,
        "significant": bool(sig_joint.any()),
        "tolerance": tol,
        "floor_rel_se": [float(r) if k else None for r, k in zip(rel, known, strict=True)],
        "estimation": (
            np.array([float(np.sum(wj)) for wj in est_w])
            if crossfit is None
            else np.maximum(ratio_joint - ratio_test, 0.0)
        ),
        "state_estimation": state,
        "explainable": sources,
    }
