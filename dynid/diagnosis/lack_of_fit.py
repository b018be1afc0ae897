"""Does the training run's residual repeat across its periods?  A lack-of-fit test against pure error.

A training run that repeats its period holds replicates: at each phase of the excitation the robot passed
through the same states K times.  Whatever the state determines repeats; noise does not.  So the training
refit's residual, averaged over the periods phase by phase, holds the misfit of the baseline (what no
choice of its parameters reproduces) plus the noise over K, and its deviation from that mean is noise
alone (the classical lack-of-fit test against pure error with replicated design points; Draper and Smith,
*Applied Regression Analysis*, 3rd ed., section 2.1).  An effect the model lacks leaves a misfit there
whatever the held-out run shows: the refit absorbs what it can of it, on the training motion, and the rest
repeats.  No held-out data and no noise floor enter.

* The statistic, per joint: ``K`` times the mean square of the residual's periodic mean, over the mean
  square of its deviation from that mean (scaled to the noise's variance), on the phases where the joint
  moves in the ``K`` (two or more) periods that hold the phase (the stretch that repeats holds its whole
  periods and part of one more, as :func:`dynid.validation.noise.periodic_deviation` stacks them).  Without misfit and without the fit it is 1 on average; the fit removes part
  of the periodic mean, which holds the noise over K, so its mean is below 1.
* Its null distribution is drawn by the sieve bootstrap of :mod:`.consistency`: an autoregressive model
  of the training run's deviation from its periodic mean draws the noise, the refit's projection (weights
  and all) is applied to it, and the statistic is computed again.  A moment-matched gamma gives the tail.
* The misfit in noise variances is the statistic minus its null mean, over the mean ``K``: about the
  mean square of the misfit over the noise's variance.  A joint counts as a lead where that reaches
  :data:`LEAD_MISFIT` and its own p-value is below ``alpha``.

The check needs at least two whole periods in the training run (``dynid simulate`` records three by
default, ``dynid excite --csv`` writes three between the approach and the retreat).  What repeats is what
the state determines, which includes the state estimation's error when the angles are quantised (the same
angles give the same error each period): a multiple of its white model's share is taken off the misfit
(:data:`QUANTISATION_FACTOR`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from dynid.diagnosis import stats as st
from dynid.diagnosis.fitting import WeightedFit
from dynid.validation.noise import periodic_deviation, repeated_periods

__all__ = ["DRAWS", "LEAD_MISFIT", "QUANTISATION_FACTOR", "LackOfFit", "training_lack_of_fit"]

DRAWS = 200
"""Bootstrap draws of the null distribution."""
LEAD_MISFIT = 0.3
"""A joint whose periodic misfit (noise variances, less what the quantised angles repeat) reaches this,
with its own p-value below ``alpha``, is a lead: the training run holds something the baseline cannot fit.
Set on the largest misfit over a run's joints in 200 simulated effect-free field runs (the tuning seeds
1000-1099, UR5 and Panda, three training periods, coloured noise, 18-bit angles): it reached 0.297 on the
UR5 (its 99th percentile 0.276; before the quantisation allowance, which can only lower it) and 0.195 on
the Panda (0.192).  Coupled wrist friction outside the catalogue at 1x the noise, on 38 tuning runs (25 UR5,
13 Panda), left 0.23-1.37 on its joint, at or above 0.3 in 37.  The bootstrap's p-value alone is rough
here as in :mod:`.consistency` (8-9 % of the effect-free joints had p < 0.05), so the decision rests on
both."""
QUANTISATION_FACTOR = 4.0
"""How many times the white model of the angles' quantisation error
(:func:`dynid.diagnosis.baseline.state_estimation_variance`) the lead rule takes off the misfit.  The
same angles give the same error in every period, so it repeats, and the white model (uniform within one
encoder step, independent from sample to sample) understates what repeats: on the simulated default path
of ``dynid simulate`` (a UR5, 1 kHz, 18-bit angles, no effect), the misfit fell by 0.12-0.49 noise
variances per joint when the angles were logged exactly, 0.9-3.6 times the white model's 0.11-0.14; on
simulated field runs with 14-bit angles the misfit reached 1.5 times it.  (The controller's feedback on the
quantised angles repeats too, in the torque, with motion below the encoder's step that the logged angles
cannot show.)"""
CURVE_POINTS = 400
"""Points per joint of the periodic mean kept for the report."""


@dataclass(frozen=True, eq=False)
class LackOfFit:
    """The lack-of-fit test of the training refit, per joint.

    Attributes
    ----------
    ratio : ndarray, shape (n,)
        ``K`` times the mean square of the residual's periodic mean over the noise's variance measured by
        its deviation from that mean.
    null_mean : ndarray, shape (n,)
        The bootstrap's mean of the same without misfit.
    misfit : ndarray, shape (n,)
        ``(ratio - null_mean) / K`` (``K`` averaged over the phases): the mean square of the misfit over
        the noise's variance.
    p_raw : ndarray, shape (n,)
        Bootstrap (gamma tail) p-value per joint.
    p_joint : ndarray, shape (n,)
        The same, Holm-adjusted across the joints.
    state : ndarray, shape (n,)
        What differentiating the quantised angles adds (noise variances, the white model): it repeats too.
        The lead rule takes :data:`QUANTISATION_FACTOR` times it off the misfit.
    periods : float
        Periods the training run's repeating stretch holds (its whole periods and the part of one more).
    curve : dict
        For the report: ``phase_s`` (time into the period, s), ``mean`` (per joint, the residual's mean over
        the periods at that phase, N m; None where unused) and ``band`` (per joint, two noise stds of such a
        mean).
    """

    ratio: NDArray[np.float64]
    null_mean: NDArray[np.float64]
    misfit: NDArray[np.float64]
    p_raw: NDArray[np.float64]
    p_joint: NDArray[np.float64]
    state: NDArray[np.float64]
    periods: float
    curve: dict = field(default_factory=dict, repr=False)

    def leads(self, alpha: float) -> NDArray[np.bool_]:
        """Joints whose misfit, less what the quantised angles may repeat, reaches :data:`LEAD_MISFIT` with
        their own p-value below ``alpha``."""
        return (self.misfit - QUANTISATION_FACTOR * self.state >= LEAD_MISFIT) & (self.p_raw < alpha)

    def to_dict(self, alpha: float) -> dict:
        """JSON-ready figures, with the leads at ``alpha``."""
        return {
            "ratio": self.ratio.tolist(),
            "null_mean": self.null_mean.tolist(),
            "misfit": self.misfit.tolist(),
            "p_raw": self.p_raw.tolist(),
            "p_joint": self.p_joint.tolist(),
            "lead_joint": self.leads(alpha).tolist(),
            "state_estimation": self.state.tolist(),
            "quantisation_factor": QUANTISATION_FACTOR,
            "lead_misfit": LEAD_MISFIT,
            "periods": self.periods,
            "curve": self.curve,
        }


def _layout(
    prep, rows: NDArray[np.intp]
) -> tuple[NDArray[np.intp], NDArray[np.intp], int, int, float] | None:
    """Per row: the period it falls in (0 for the part of one more before the whole ones, -1 outside the
    stretch that repeats) and its phase bin (one row's stride wide); the count of periods (the whole ones
    and that part) and of bins, and the periods the stretch holds (a fraction).  None when the run does not
    repeat two whole periods."""
    found = repeated_periods(prep)
    if found is None or len(rows) < 2:
        return None
    start, stop, per = found
    count = (stop - start) // per
    stride = max(1, int(np.median(np.diff(rows))))
    bins = per // stride
    if bins < 2:
        return None
    origin = stop - (count + 1) * per  # the start of the part period before the whole ones
    off = rows - origin
    inside = (rows >= start) & (rows < stop)
    period = np.where(inside, off // per, -1)
    phase = np.where(inside, np.minimum((off % per) // stride, bins - 1), -1)
    return period, phase, count + 1, bins, (stop - start) / per


def _stack(
    r: NDArray[np.float64], moving: NDArray[np.bool_], period: NDArray[np.intp], phase: NDArray[np.intp], K: int, B: int
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_], NDArray[np.float64]]:
    """Residuals ``r`` (m, n, d) by period and phase: sums (K, B, n, d) and counts (K, B, n) of the moving
    rows, the phases used (B, n: at least two periods hold a moving row there, none holds two) and the
    periods holding each (B, n; zero where unused)."""
    _, n, d = r.shape
    inside = period >= 0
    sums = np.zeros((K, B, n, d))
    counts = np.zeros((K, B, n))
    np.add.at(sums, (period[inside], phase[inside]), r[inside] * moving[inside][:, :, None])
    np.add.at(counts, (period[inside], phase[inside]), moving[inside].astype(float))
    held = counts.sum(axis=0)
    good = (held >= 2) & np.all(counts <= 1, axis=0)
    return sums, counts, good, np.where(good, held, 0.0)


def _ratio(
    r: NDArray[np.float64], moving: NDArray[np.bool_], period: NDArray[np.intp], phase: NDArray[np.intp], K: int, B: int
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The statistic (n, d) of residuals ``r`` (m, n, d) on the phases :func:`_stack` uses, the periods
    holding each phase (B, n; zero where unused), the periodic mean (B, n, d) and the within-phase variance
    (n, d)."""
    sums, counts, good, k = _stack(r, moving, period, phase, K, B)
    used = np.maximum(good.sum(axis=0), 1)  # (n,)
    mean = sums.sum(axis=0) / np.maximum(k, 1.0)[:, :, None]  # (B, n, d)
    between = np.einsum("bn,bnd->nd", k, mean**2) / used[:, None]
    dev = (sums - mean[None] * counts[:, :, :, None]) * good[None, :, :, None]
    within = np.einsum("kbnd->nd", dev**2) / np.maximum(np.sum(k - good, axis=0), 1.0)[:, None]
    return between / np.maximum(within, 1e-300), k, np.where(good[:, :, None], mean, np.nan), within


def _curve(
    mean: NDArray[np.float64], within: NDArray[np.float64], k: NDArray[np.float64], dt: float, points: int = CURVE_POINTS
) -> dict:
    """The residual's periodic mean per joint over the phase (thinned to about ``points``), and two noise
    stds of a mean over the periods holding each phase."""
    B = mean.shape[0]
    keep = np.arange(0, B, max(1, B // points))
    band = 2.0 * np.sqrt(within[None, :] / np.maximum(k, 1.0))
    band = np.where(k > 0, band, np.nan)
    return {
        "phase_s": (keep * dt).tolist(),
        "mean": mean[keep].T.tolist(),
        "band": band[keep].T.tolist(),
    }


def training_lack_of_fit(
    prep,
    rows: NDArray[np.intp],
    fit: WeightedFit,
    order: int,
    *,
    noise: NDArray[np.float64] | None = None,
    state_variance: NDArray[np.float64] | None = None,
    draws: int = DRAWS,
    seed: int = 0,
) -> LackOfFit | None:
    """Test per joint whether the training refit's residual repeats across the periods beyond noise.

    Parameters
    ----------
    prep : Prepared
        The training data as the model sees them.
    rows : ndarray of int, shape (m,)
        The rows of ``prep`` the refit used (evenly thinned).
    fit : WeightedFit
        The baseline refitted on those rows (its weights are zero where a joint does not move).
    order : int
        Order of the autoregressive model of the noise (rows).
    noise : ndarray, shape (L, n), optional
        The training run's deviation from its mean over its periods at the rows' rate
        (:func:`dynid.validation.noise.periodic_deviation`, thinned like ``rows``), when the caller has it;
        found here otherwise.
    state_variance : ndarray, shape (n,), optional
        What differentiating the quantised angles adds to the training residual, in noise variances
        (:func:`dynid.diagnosis.baseline.state_estimation_variance`); zeros when not given.
    draws : int
        Bootstrap draws.
    seed : int
        Seed of the bootstrap (the result is reproducible).

    Returns
    -------
    LackOfFit or None
        None when the training run does not repeat two whole periods.
    """
    layout = _layout(prep, rows)
    if layout is None:
        return None
    stride = max(1, int(np.median(np.diff(rows))))
    if noise is None:
        found = periodic_deviation(prep)
        if found is None:
            return None
        noise = found[0][::stride]
    period, phase, K, B, held = layout
    m, n = fit.shape
    moving = np.asarray(fit.w) > 0
    w = np.where(moving, fit.w, 1.0)
    r = (fit.r0.reshape(m, n) / w)[:, :, None]
    observed, k, periodic, within = _ratio(r, moving, period, phase, K, B)
    observed = observed[:, 0]
    mean_k = np.sum(k, axis=0) / np.maximum((k > 0).sum(axis=0), 1)  # periods per phase used, on average
    curve = _curve(periodic[:, :, 0], within[:, 0], k, stride / prep.fs)
    ar = [st.ar_model(noise[:, j], order) for j in range(n)]
    rng = np.random.default_rng(seed)

    def drawn_ratios(d: int) -> NDArray[np.float64]:
        """The statistic (n, d) of ``d`` draws of the noise through the refit's projection."""
        e = st.ar_noise(ar, m, d, rng).transpose(1, 2, 0)  # (m, n, d)
        ew = (e * fit.w[:, :, None]).reshape(m * n, d)
        rw = ew - fit.Q @ (fit.Q.T @ ew)
        return _ratio(rw.reshape(m, n, d) / w[:, :, None], moving, period, phase, K, B)[0]

    null_ = st.bootstrap_null(drawn_ratios, draws)  # (n, draws)
    mean = null_.mean(axis=1)
    p = st.gamma_tail(observed, null_)
    return LackOfFit(
        ratio=observed,
        null_mean=mean,
        misfit=(observed - mean) / np.maximum(mean_k, 1.0),
        p_raw=p,
        p_joint=st.holm(p),
        state=np.zeros(n) if state_variance is None else np.asarray(state_variance, dtype=float),
        periods=float(held),
        curve=curve,
    )
