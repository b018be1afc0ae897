"""Sim-to-real gap diagnosis: where the identified model's error lies, which effect causes it, and how
far adding that effect shrinks it (DIAGNOSIS.md).

>>> from dynid import load_dataset, load_model
>>> result = diagnose(load_model("M.json"), load_dataset("D.csv"), load_dataset("V.csv"))
>>> result.verdict                      # ["stribeck"], ["none"] or ["unexplained"]
>>> print(result.summary())
>>> result.to_dict()                    # gap_map, ranking, verdict, parametric, decomposition

Method, in the order it runs:

1. Both datasets are preprocessed as the model's identification data were (the same filter on the
   torque and on every regressor column: parallel filtering).  The held-out noise floor is measured
   (:func:`dynid.validation.noise.measure_noise`: spread of the filtered torque across the periods of a
   periodic excitation, else the spectral level), never assumed.
2. Baseline: the base parameters and the model's own extra columns (armature, linear friction, and
   the shape of its friction layer) are identified again on the training data by weighted least squares
   (weights: the baseline residual level per joint, reweighted until they settle).  The held-out error of the model as given minus
   that of the refit is the *parametric* part of the gap.
3. Screen: every catalogue candidate on every joint (:mod:`dynid.diagnosis.candidates`) is tuned on
   the training data (never on the held-out data) and scored by the reduction of the held-out loss
   ``sum_j r_j^2 / sigma_j^2`` on two footings: refitted with the baseline on the training data (a
   one-sided Diebold-Mariano test on the per-sample loss difference with a Newey-West variance, widened
   by the chance gain that the refit's parameter error allows: fixed over the whole held-out run, so
   invisible to the serial correlation; its covariance is a sandwich over blocks of the training data
   with their lags weighed as the test weighs its block means, so noise correlated beyond a block
   counts), and cross-fitted with the baseline on the training data and the
   other held-out folds (the same test, block means capped as the excess test's).  On both, what the
   candidate gains by cancelling the error that differentiating quantised angles leaves in the baseline's
   prediction and in its own columns (errors in the variables, measured on draws of the encoder's error:
   :func:`dynid.diagnosis.screening.state_gain`) is taken off its gain and closure first.  Its p-value is the
   smaller of the two, doubled, then corrected for the many candidates in two families at half the
   level each: Holm across all of them, and Holm across the ``screen_top`` that the training data alone
   rank first (the Wald test of their columns on the training residual, which the held-out noise does
   not touch: :func:`dynid.diagnosis.stats.screened_holm`).  Its gain and closure are those of the
   footing that gave it, and so is the ranking's order.  The choice among the acceptable
   candidates and the simpler-candidate test compare them on the training footing.
4. Forward selection: among the significant candidates that close at least ``min_closure`` of the
   gap on their own joint(s) (in noise variances), the one that lowers the held-out loss of the whole
   arm most is accepted (a simpler candidate on the same joints that it does not beat significantly
   is preferred), refitted (nonlinear least squares for elasticity and delay, a grid and a bounded
   search for backlash's reversal threshold and crossing time: their first-order columns recover only
   part of the gap; the continuous hyper-parameters of the others), and the screen repeats on top of
   it, up to ``max_effects``.
5. Verdict: the accepted effects; else ``["unexplained"]`` when the excess of some joint over the
   noise floor is significant, or the training and held-out runs disagree on a joint's parameters
   (:mod:`.consistency`: the cross-fitted coefficients fit the training run worse than noise and state
   estimation explain, as when the cross-fitted baseline absorbs an effect the model lacks; no floor
   enters), or the training refit's residual repeats across the training run's periods beyond what
   noise repeats (:mod:`.lack_of_fit`: a lack-of-fit test against the pure error of the replicates; no
   floor and no held-out data enter), ``["none"]`` when none of these.  The excess is tested on what the baseline cannot
   predict even when refitted with the rest of the held-out run (contiguous folds, cross-fitted: an
   aperiodic held-out motion that leaves the training states shows the refit's parameter error at many
   times the floor, which its covariance does not foresee), above ``1 + measured_excess_tol`` noise
   variances with the floor's own sampling error integrated where the floor is measured across periods
   and states its precision, else above ``1 + excess_tol`` with the floor taken as exact (sticking leaves
   a small excess even on an effect-free robot), plus what differentiating quantised
   angles adds (the encoder's step read from the angles and propagated through the preparation and the
   refit's torque), with block means capped so that an excess on a few moves is not lost in its own
   variance (:func:`dynid.diagnosis.stats.excess_test`); the sources counted as noise are listed.  A
   "none" notes how far the measured floor's own 95 % interval reaches
   (:meth:`dynid.validation.metrics.NoiseFloor.std_interval`).
   When the verdict is "unexplained", or the floor is only a spectral lower bound, a check that does
   not rest on the floor runs (:mod:`.remainder`): gradient-boosted trees on the state, fitted on the
   training run and the other held-out folds, predict each fold's residual of the final model; a
   significant gain says that something the state predicts remains.  A lower-bound floor can only
   overstate the gap: on it "none" stands; accepted effects stand when they remove at least
   ``min_closure`` of the whole held-out error on the joints they act on (no floor enters); "unexplained"
   stands when this check finds a joint with a significant excess predictable and no significant
   candidate was turned down for closing too little.  Otherwise the verdict is provisional.  Candidates whose columns are nearly parallel once the baseline is projected
   out (small principal angle) are reported as not separable with this excitation.
6. Parametric test: identified minus nominal base parameters, with a block (HAC) covariance (the
   block sums alone, the covariance its allowances were set on), against
   structured hypotheses (common drive gain, a torque gain on one joint, payload on the last link, an
   armature per joint) by chi^2 / BIC; then the model's own torque offsets and armatures against
   their nominal values.

Each step is a stage with typed inputs and a typed record out, one module each: the noise floor
(:mod:`dynid.validation.noise`), the data and the baseline refit (:mod:`.baseline`), the candidates'
screening (:mod:`.screening`), their nonlinear refinement (:mod:`.refinement`), the forward selection
(:mod:`.selection`), the parameter-change test (:mod:`.parameter_change`) and the result
(:mod:`.result`); the settings are one :class:`~dynid.diagnosis.settings.DiagnosisSettings`.  This
module runs the stages; :mod:`.verdict` turns their records into the verdict and its notes.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynid._progress import say
from dynid._threads import single_blas_thread
from dynid.data.dataset import Dataset
from dynid.data.preparation import Prepared
from dynid.diagnosis import baseline as bl
from dynid.diagnosis.candidates import enumerate_candidates
from dynid.diagnosis.consistency import MEMORY_SECONDS, Consistency, parameter_consistency
from dynid.diagnosis.gapmap import gap_map
from dynid.diagnosis.lack_of_fit import LackOfFit, training_lack_of_fit
from dynid.diagnosis.parameter_change import parameter_change_test
from dynid.diagnosis.remainder import Remainder, predictable_remainder
from dynid.diagnosis.result import Diagnosis, RankedCandidate
from dynid.diagnosis.screening import Context, CrossFitted, cross_fitted
from dynid.diagnosis.selection import Selection, select
from dynid.diagnosis.settings import DiagnosisSettings
from dynid.diagnosis.verdict import (
    MEASURED_FLOORS,
    decomposition,
    provisional_status,
    remainder_notes,
    undecided_candidates,
    verdict_and_notes,
)
from dynid.exceptions import DataError
from dynid.validation.metrics import NoiseFloor
from dynid.validation.noise import measure_noise, periodic_deviation

__all__ = ["Diagnosis", "DiagnosisSettings", "RankedCandidate", "diagnose", "heldout_noise_floor", "run_diagnosis"]


def diagnose(
    model,
    train: Dataset,
    heldout: Dataset,
    *,
    robot=None,
    effects: Sequence[str] | None = None,
    alpha: float = 0.05,
    max_effects: int = 3,
    min_gain: float = 0.15,
    min_closure: float = 0.5,
    excess_tol: float = 1.0,
    measured_excess_tol: float = 0.5,
    period: float | None = None,
    max_samples: int = 12000,
    block_seconds: float = 0.1,
    refit: bool = True,
    confound_deg: float = 15.0,
    stick_fraction: float = 0.02,
    screen_top: int = 5,
) -> Diagnosis:
    """Diagnose the gap between an identified model and the robot on held-out data.

    Parameters
    ----------
    model : IdentifiedModel or None
        The identified model (``dynid identify``, :func:`dynid.identify.load_model`).  None: the
        baseline (base parameters, Coulomb, viscous and offset per joint) is identified on ``train``
        with the default preprocessing, and ``robot`` must be given.
    train : Dataset
        The data the model was identified on (or other training data of the same robot).
    heldout : Dataset
        Held-out data of the same robot: preferably several periods of a periodic excitation (the
        noise floor is then the spread across periods).
    robot : RobotModel, optional
        The robot, when ``model`` is None.
    effects, alpha, max_effects, min_gain, min_closure, excess_tol, measured_excess_tol, period, max_samples, block_seconds, refit, confound_deg, stick_fraction, screen_top
        The settings, documented once in :class:`~dynid.diagnosis.settings.DiagnosisSettings` (the
        defaults there are the method's).

    Returns
    -------
    Diagnosis

    Raises
    ------
    ShapeError
        Data of another robot (joint count).
    DataError
        Held-out data whose noise floor cannot be measured, data too short for the tests.
    UsageError
        Unknown effect names or bad settings.
    IdentificationError
        Too few samples for the baseline and a candidate.
    """
    settings = DiagnosisSettings(
        effects=None if effects is None else tuple(effects),
        alpha=alpha,
        max_effects=max_effects,
        min_gain=min_gain,
        min_closure=min_closure,
        excess_tol=excess_tol,
        measured_excess_tol=measured_excess_tol,
        period=period,
        max_samples=max_samples,
        block_seconds=block_seconds,
        refit=refit,
        confound_deg=confound_deg,
        stick_fraction=stick_fraction,
        screen_top=screen_top,
    )
    return run_diagnosis(model, train, heldout, settings, robot=robot)


def run_diagnosis(
    model, train: Dataset, heldout: Dataset, settings: DiagnosisSettings, *, robot=None
) -> Diagnosis:
    """:func:`diagnose` with its settings as one record.

    Parameters
    ----------
    model, train, heldout, robot
        As in :func:`diagnose`.
    settings : DiagnosisSettings

    Returns
    -------
    Diagnosis
    """
    with single_blas_thread():
        return _run(model, train, heldout, settings, robot)


@dataclass(frozen=True, eq=False)
class _Refit:
    """The baseline refitted on the training run, both runs with its torque, and the noise of the states."""

    base: bl.Baseline
    tr: bl.Side
    ho: bl.Side
    state_var: NDArray[np.float64]
    state: bl.StateNoise | None
    train_noise: NDArray[np.float64] | None
    lack: LackOfFit | None


@dataclass(frozen=True, eq=False)
class _GapTests:
    """The baseline cross-fitted on the held-out folds, the runs' agreement, and the excess over the floor."""

    cross0: CrossFitted
    consistency: Consistency
    excess: dict[str, Any]


def _run(model, train: Dataset, heldout: Dataset, settings: DiagnosisSettings, robot) -> Diagnosis:
    say("[1/6] preparing the training and held-out runs")
    structure = bl.model_structure(model, robot, train, heldout)
    robot = structure.robot
    bl.check_training_length(structure, train)
    tr_sample = bl.sample(structure, train, settings)
    ho_sample = bl.sample(structure, heldout, settings)
    noise = heldout_noise_floor(tr_sample.prep, ho_sample.prep, settings.period)
    sigma = np.maximum(noise.std, 1e-12)
    block = _block_rows(ho_sample, settings.block_seconds)

    say("[2/6] refitting the model's structure on the training run (the baseline)")
    refit = _refit(structure, train, heldout, tr_sample, ho_sample, sigma)
    del tr_sample, ho_sample  # their full-rate columns are no longer needed
    base, tr, ho = refit.base, refit.tr, refit.ho
    held = bl.heldout_baseline(model, heldout, ho, base.x, sigma)
    ctx = Context(
        tr=tr,
        ho=ho,
        sigma=sigma,
        block=block,
        mask=ho.moving,
        min_delay=float(np.median(np.diff(heldout.t))),
        state=refit.state,
        alpha=settings.alpha,
    )
    # The baseline cross-fitted on the held-out folds: the excess test's residual
    # (:func:`~dynid.diagnosis.baseline.crossfit_residual`) and the first round's cross-fitted footing.
    say("[3/6] cross-fitting the baseline on the held-out folds; the runs' agreement and the excess")
    gap = _gap_tests(ctx, refit, held, noise, settings)

    say("[4/6] screening the candidate effects")
    skip = _in_model(structure)
    groups = enumerate_candidates(tr.src, settings.effects, skip=skip, motor_inertia="armature" not in skip)
    sel = select(ctx, base, held, groups, settings, gap.excess["significant_joint"], cross0=gap.cross0)

    say("[5/6] the parameter change and the gap map")
    par = _parameter_change(structure, base, tr, sel, block, settings, sigma)
    gmap = _heldout_gap_map(ho, held, noise, block, robot, sel)
    say("[6/6] the verdict")
    verdict, notes = verdict_and_notes(sel, gap.excess, gap.consistency, refit.lack, noise, base, settings, robot.joint_names)
    notes = _held_by_the_model(model, sel) + notes
    measured = noise.method in MEASURED_FLOORS
    remainder = None
    if verdict == ["unexplained"] or not measured:
        remainder = _remainder(sel, tr, ho, sigma, block, settings)
    floor_free = _floor_free(gap.consistency, refit.lack, settings.alpha)
    status = provisional_status(verdict, measured, remainder, sel, gap.excess, settings, held.mse, floor_free)
    provisional = status[0]
    notes = remainder_notes(verdict, measured, status, remainder, robot.joint_names) + notes
    undecided = [] if sel.accepted else undecided_candidates(ctx, base, sel.ranking, settings)
    return Diagnosis(
        verdict=verdict,
        accepted=sel.accepted,
        ranking=sel.ranking,
        decomposition=decomposition(held, sel, sigma, ho.moving),
        gap_map=gmap,
        parametric=par,
        noise=noise,
        excess=gap.excess,
        notes=notes,
        joint_names=list(robot.joint_names),
        settings=_settings_record(settings, structure, base, tr, ho),
        residuals={
            "t": ho.t,
            "before": held.residual,
            "after": sel.residual if sel.accepted else held.residual,
            "noise_std": sigma,
        },
        provisional=provisional,
        undecided=undecided,
        remainder=None if remainder is None else remainder.to_dict(),
        consistency=gap.consistency.to_dict(settings.alpha),
        lack_of_fit=None if refit.lack is None else refit.lack.to_dict(settings.alpha),
    )


def _refit(
    structure: bl.ModelStructure,
    train: Dataset,
    heldout: Dataset,
    tr_sample: bl.Sample,
    ho_sample: bl.Sample,
    sigma: NDArray[np.float64],
) -> _Refit:
    """Refit the baseline on the training run; the states' noise and the training run's lack of fit."""
    base = bl.refit_baseline(tr_sample)
    tr = bl.side(tr_sample, structure, base.x)
    ho = bl.side(ho_sample, structure, base.x)
    state_var, _ = bl.state_estimation_variance(structure, heldout, ho_sample, base.x, sigma)
    state = bl.state_noise(structure, heldout, ho_sample, base.x)
    train_noise = _training_noise(tr)
    lack = _training_lack(structure, train, tr_sample, tr, base, train_noise)
    return _Refit(
        base=base, tr=tr, ho=ho, state_var=state_var, state=state, train_noise=train_noise, lack=lack
    )


def _training_lack(
    structure: bl.ModelStructure,
    train: Dataset,
    tr_sample: bl.Sample,
    tr: bl.Side,
    base: bl.Baseline,
    train_noise: NDArray[np.float64] | None,
) -> LackOfFit | None:
    """The training refit's lack of fit across the training periods (None without periods)."""
    # Does the training refit's residual repeat across the training periods?  Evidence on the training
    # run alone (a lack-of-fit test against the pure error of its replicates); no floor enters.
    if train_noise is None:
        return None
    train_state, _ = bl.state_estimation_variance(
        structure, train, tr_sample, base.x, np.sqrt(np.maximum(np.mean(train_noise**2, axis=0), 1e-300))
    )
    return training_lack_of_fit(
        tr.prep, tr.rows, base.fit, _rows_in(tr, MEMORY_SECONDS), noise=train_noise, state_variance=train_state
    )


def _gap_tests(
    ctx: Context, refit: _Refit, held: bl.HeldOutBaseline, noise: NoiseFloor, settings: DiagnosisSettings
) -> _GapTests:
    """Cross-fit the baseline on the held-out folds; test the runs' agreement and the excess over the floor."""
    base, tr, ho, block = refit.base, refit.tr, refit.ho, ctx.block
    cross0 = cross_fitted(ctx, base.fit, tr.X0, ho.X0, bl.FOLDS)
    # Do the two runs agree on the baseline's parameters?  Evidence that does not rest on the floor.
    consistency = parameter_consistency(
        cross0.fold,
        max(1, round(MEMORY_SECONDS / settings.block_seconds * block)),
        noise=refit.train_noise,
    )
    excess = bl.excess_over_floor(
        base.fit,
        ho,
        held,
        ctx.sigma,
        block,
        settings,
        crossfit=cross0.residual,
        state_variance=refit.state_var,
        floor_rel_se=noise.rel_se,
    )
    return _GapTests(cross0=cross0, consistency=consistency, excess=excess)


def _parameter_change(
    structure: bl.ModelStructure,
    base: bl.Baseline,
    tr: bl.Side,
    sel: Selection,
    block: int,
    settings: DiagnosisSettings,
    sigma: NDArray[np.float64],
) -> dict[str, Any]:
    """What the refit absorbed beside the accepted effects: the parameter-change test, with the screen's
    one-joint gains and the base tilt as hypotheses.

    The refit holds the verdict's effects (the selection's final fit): what they explain is not a change
    of the nominal parameters (a coupled friction absorbed by the last links' inertia read as a payload of
    0.2 g, or as "the nominal inertial parameters are off").
    """
    fit = sel.fit  # the baseline's own fit when nothing was accepted
    x = fit.solve()[0] if sel.accepted else base.x
    # An accepted effect's columns are in the fit: as a hypothesis it would be a direction of rounding.
    held = {a.candidate.key for a in sel.accepted}
    tuned = [(c, C) for c, C in sel.tuned.values() if c.key not in held]
    # A torque gain on one joint scales that joint's measured torque: what the refit absorbs of it.
    # Its columns were built for the screen (round 0 tunes every candidate).
    gain_dirs = {c.joint: fit.regress(C) for c, C in tuned if c.effect == "drive_gain"}
    # A tilt of the base rotates gravity: what the refit absorbs of its two columns (the screen's).
    tilt = [fit.regress(C) for c, C in tuned if c.effect == "base_tilt"]
    return parameter_change_test(
        tr.src.ddq[tr.rows],
        structure.columns,
        fit,
        x,
        structure.robot,
        block,
        settings.alpha,
        sigma,
        gain_dirs,
        tilt_dirs=tilt[0] if tilt else None,
        beside=[a.candidate.effect if a.candidate.effect == "base_tilt" else a.candidate.key for a in sel.accepted],
    )


def _heldout_gap_map(
    ho: bl.Side, held: bl.HeldOutBaseline, noise: NoiseFloor, block: int, robot, sel: Selection
) -> dict[str, Any]:
    """The gap map of the baseline's held-out residual."""
    return gap_map(
        t=ho.t,
        q=ho.src.q[ho.rows],
        dq=ho.src.dq[ho.rows],
        ddq=ho.src.ddq[ho.rows],
        tau=ho.y,
        tau_pred=ho.y - held.residual,
        residual=held.residual,
        noise=noise,
        block=block,
        robot=robot,
        gear_ratio=_gear_ratio(sel.accepted),
        filter_gain=_filter_gain_function(ho.prep),
    )


def _remainder(
    sel: Selection,
    tr: bl.Side,
    ho: bl.Side,
    sigma: NDArray[np.float64],
    block: int,
    settings: DiagnosisSettings,
) -> Remainder:
    """What a flexible state model predicts of the residual the selection leaves, on unseen held-out folds."""
    # What a flexible state model predicts of what the model leaves, on held-out folds it did not see:
    # evidence that does not rest on the floor.
    return predictable_remainder(
        sel.cross.fold,
        (tr.src.q[tr.rows], tr.src.dq[tr.rows], tr.src.ddq[tr.rows]),
        tr.t,
        tr.moving,
        (ho.src.q[ho.rows], ho.src.dq[ho.rows], ho.src.ddq[ho.rows]),
        ho.t,
        ho.moving,
        sigma,
        block,
        settings.alpha,
    )


def _floor_free(consistency: Consistency, lack: LackOfFit | None, alpha: float) -> NDArray[np.bool_]:
    """Joints with evidence that no floor enters: the runs disagree, or the training residual repeats."""
    floor_free = consistency.leads(alpha)
    if lack is not None:
        floor_free = floor_free | lack.leads(alpha)
    return floor_free


def _settings_record(
    settings: DiagnosisSettings, structure: bl.ModelStructure, base: bl.Baseline, tr: bl.Side, ho: bl.Side
) -> dict[str, Any]:
    """The settings the diagnosis ran with, the samples it used and the baseline's reweighting."""
    return {
        "effects": list(settings.effects),
        "alpha": settings.alpha,
        "max_effects": settings.max_effects,
        "min_gain": settings.min_gain,
        "min_closure": settings.min_closure,
        "excess_tol": settings.excess_tol,
        "measured_excess_tol": settings.measured_excess_tol,
        "block_seconds": settings.block_seconds,
        "screen_top": settings.screen_top,
        "stick_fraction": settings.stick_fraction,
        "confound_deg": settings.confound_deg,
        "samples_train": int(tr.y.shape[0]),
        "samples_heldout": int(ho.y.shape[0]),
        "weight_passes": base.passes,
        "weights_settled": base.settled,
        "preprocessing": structure.preprocessing,
    }


def _rows_in(side: bl.Side, seconds: float) -> int:
    """Rows of ``side`` in ``seconds`` (at least one)."""
    t = side.t
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 1.0 / side.prep.fs
    return max(1, round(seconds / dt))


def _training_noise(tr: bl.Side) -> NDArray[np.float64] | None:
    """The training run's noise at its rows' rate: its deviation from the mean over its periods, or None
    when it does not repeat a period."""
    found = periodic_deviation(tr.prep)
    if found is None or len(tr.rows) < 2:
        return None
    stride = max(1, int(np.median(np.diff(tr.rows))))  # the sample's thinning
    return found[0][::stride]


def heldout_noise_floor(train_prep, heldout_prep, period: float | None) -> NoiseFloor:
    """The held-out data's noise floor, from the training run's periods when the held-out run has none.

    The spread across repeated periods measures the noise; the spectrum's high-frequency level is only a
    lower bound when the noise is coloured.  A held-out run that does not repeat a period (most field
    recordings) takes the floor of a training run that does, recorded at the same rate and put through the
    same filter, assuming the noise of one robot does not change between two recordings of a session.  The
    held-out spectral level stays a lower bound per joint: where it is higher, the held-out run is noisier
    than training, and it is used.
    """
    noise = measure_noise(heldout_prep, period=period)
    if noise.method == "periods" or abs(train_prep.fs - heldout_prep.fs) > 1e-6 * heldout_prep.fs:
        return noise
    try:
        trained = measure_noise(train_prep)
    except DataError:
        return noise
    if trained.method != "periods":
        return noise
    higher = noise.std > trained.std
    detail = "training run: " + trained.detail
    if np.any(higher):
        joints = ", ".join(str(j + 1) for j in np.flatnonzero(higher))
        detail += f"; the held-out spectral level is higher on joint(s) {joints} and is used there"
    rel = None if trained.rel_se is None else np.where(higher, np.nan, trained.rel_se)
    return NoiseFloor(
        std=np.maximum(noise.std, trained.std), method="training periods", detail=detail, rel_se=rel
    )


def _block_rows(ho: bl.Sample, block_seconds: float) -> int:
    """Rows per block of the tests; refuse held-out data shorter than eight blocks."""
    t = ho.prep.t[ho.rows]
    dt_rows = float(np.median(np.diff(t))) if len(t) > 1 else 1.0 / ho.prep.fs
    block = max(1, round(block_seconds / dt_rows))
    if len(t) < 8 * block:
        raise DataError(
            f"the held-out data give {len(t)} samples after preprocessing ({len(t) * dt_rows:.2g} s), "
            f"too short for the tests on blocks of {block_seconds:g} s; give at least {8 * block_seconds:g} s."
        )
    return block


def _held_by_the_model(model, sel: Selection) -> list[str]:
    """A note for each accepted effect that the model carries already as an effect term.

    The baseline refits the model's link and friction columns without its effect terms, which are then
    screened like any other candidate: an accepted one is the model's own term at work, not a gap the
    model leaves (a default identification gives a joint a drive gain, for one).
    """
    own = {t.key for t in getattr(model, "effects", ())} if model is not None else set()
    held = [a.candidate.key for a in sel.accepted if a.candidate.key in own]
    if not held:
        return []
    return [
        f"The model carries {', '.join(held)} already as effect term(s): the diagnosis refits the model without "
        "its effect terms and tests them as candidates like any other, so what is named there is what those "
        "terms do, not a gap the model leaves."
    ]


def _in_model(structure: bl.ModelStructure) -> tuple[str, ...]:
    """Effects the model already holds (not screened)."""
    cols = structure.columns
    skip = []
    kinds = set(cols.kinds)
    if "offset" in kinds or structure.friction_shape is not None:
        skip.append("offset")
    if "armature" in kinds or cols.armature:
        skip.append("armature")
    return tuple(skip)


def _gear_ratio(accepted: list[RankedCandidate]) -> float:
    for a in accepted:
        if a.candidate.effect == "cogging":
            return float(a.candidate.hyper["N"])
    return 100.0


def _filter_gain_function(prep: Prepared):
    """``f -> |H(f)|^4``: power gain of the zero-phase torque filter (None without a filter)."""
    if prep.sos is None:
        return None
    from dynid.data.dsp import frequency_response

    sos, fs = prep.sos, prep.fs

    def gain(f):
        return np.abs(frequency_response(sos, f, fs)) ** 4

    return gain
