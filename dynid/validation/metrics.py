"""Prediction-error metrics and a measured noise floor.

:func:`torque_metrics` compares a measured with a predicted torque, per joint; :func:`noise_floor`
measures how much of the torque no model can predict (never assumed): from repeated periods of a
periodic excitation when the data hold several, else from the high-frequency part of the spectrum.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dynid.data.dsp import welch
from dynid.exceptions import DataError, ShapeError

__all__ = ["NoiseFloor", "noise_floor", "period_stack", "torque_metrics", "variance_rel_se"]


def torque_metrics(tau: np.ndarray, tau_pred: np.ndarray) -> dict:
    """Per-joint error figures of a prediction.

    Parameters
    ----------
    tau, tau_pred : ndarray, shape (m, n)
        Measured and predicted joint torques (N m).

    Returns
    -------
    dict
        ``rms`` (n,) root mean square error (N m); ``rms_mean``: its average over the joints (the
        paper's figure); ``nrms`` (n,): rms / standard deviation of the measured torque; ``r2`` (n,):
        coefficient of determination; ``max_error`` (n,): largest absolute error (N m).
    """
    tau = np.asarray(tau, dtype=float)
    tau_pred = np.asarray(tau_pred, dtype=float)
    if tau.shape != tau_pred.shape or tau.ndim != 2:
        raise ShapeError(
            f"the measured torque has shape {tau.shape} and the prediction {tau_pred.shape}; both must be (m, n)."
        )
    err = tau - tau_pred
    rms = np.sqrt(np.mean(err**2, axis=0))
    spread = np.std(tau, axis=0)
    sst = np.sum((tau - tau.mean(axis=0)) ** 2, axis=0)
    sse = np.sum(err**2, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        nrms = np.where(spread > 0, rms / spread, np.inf)
        r2 = np.where(sst > 0, 1.0 - sse / sst, np.nan)
    return {
        "rms": rms,
        "rms_mean": float(rms.mean()),
        "nrms": nrms,
        "r2": r2,
        "max_error": np.max(np.abs(err), axis=0),
    }


@dataclass(frozen=True)
class NoiseFloor:
    """Standard deviation per joint of the torque that no model can predict.

    Attributes
    ----------
    std : ndarray, shape (n,)
        Noise standard deviation (N m).
    method : str
        ``"periods"`` (spread across repeated periods), ``"training periods"`` (the diagnosis: the
        training run's spread across its periods, for held-out data that do not repeat) or ``"spectrum"``
        (high-frequency level, a lower bound for coloured noise).
    detail : str
        How it was measured, in words.
    rel_se : ndarray, shape (n,), optional
        Standard error of the measured variance relative to it, per joint (a floor from periods:
        :func:`variance_rel_se`); None or NaN where it is not known (a spectral lower bound).
    """

    std: np.ndarray
    method: str
    detail: str
    rel_se: np.ndarray | None = None

    @property
    def rms_mean(self) -> float:
        return float(np.mean(self.std))

    def std_interval(self, level: float = 0.95) -> tuple[np.ndarray, np.ndarray]:
        """Two-sided ``level`` confidence interval of the noise std per joint (N m), NaN where
        :attr:`rel_se` is unknown.

        The measured variance is taken as a scaled chi^2 with ``nu = 2 / rel_se^2`` degrees of freedom
        (Satterthwaite): its interval is ``[var nu / chi2_nu(1 - a/2), var nu / chi2_nu(a/2)]``.
        """
        from scipy.stats import chi2

        n = np.size(self.std)
        rel = np.full(n, np.nan) if self.rel_se is None else np.asarray(self.rel_se, dtype=float)
        ok = np.isfinite(rel) & (rel > 0)
        lo, hi = np.full(n, np.nan), np.full(n, np.nan)
        nu = 2.0 / rel[ok] ** 2
        a = 1.0 - level
        lo[ok] = self.std[ok] * np.sqrt(nu / chi2.isf(a / 2, nu))
        hi[ok] = self.std[ok] * np.sqrt(nu / chi2.ppf(a / 2, nu))
        return lo, hi


CORRELATION_SECONDS = 0.5
"""Longest lag (s) of the noise's autocovariance that the floor's standard error sums
(:func:`variance_rel_se`): several times the correlation time of the squared noise (half the 0.1 s of the
field's AR(1) torque noise); longer lags add estimation noise, not information."""


def variance_rel_se(deviations: np.ndarray, rows_per_lag_window: int) -> np.ndarray:
    """Relative standard error of a floor's variance: the spread across periods pooled over the phase.

    The spread at neighbouring phases is correlated (coloured noise, the filter), so its samples are not
    independent.  For Gaussian noise with autocovariance ``g(h)`` along the phase, independent between
    periods, the spread ``s_k`` across ``P`` periods at phase ``k`` has ``cov(s_i, s_j) = 2 g(i - j)^2 /
    (P - 1)`` (Isserlis), so its mean over ``K`` phases has variance
    ``2 / ((P - 1) K) [g(0)^2 + 2 sum_h (1 - h / K) g(h)^2]``; with a different number of periods per
    phase, ``(P - 1) K`` is the pooled degrees of freedom ``D``.  ``g`` is estimated from the deviations
    from the period mean (the products of the samples present, scaled by samples over ``D`` for the mean
    removed) and summed up to ``rows_per_lag_window`` lags (Bartlett weights there would drop a sixth of
    the sum for the field's noise).  On AR(1) + white noise, filtered, 2 or 3 periods, it is within 5 % of
    the spread of the floor over 400 runs, and the 95 % interval of :meth:`NoiseFloor.std_interval`
    covers the true variance in 93-96 % of them.  Heavy-tailed noise (spikes) makes it optimistic.

    Parameters
    ----------
    deviations : ndarray, shape (P, K, n)
        The torque minus its mean over the periods, per period and phase; NaN where a period holds no
        sample at that phase (the same phases for every joint).
    rows_per_lag_window : int
        Largest lag summed (rows).

    Returns
    -------
    ndarray, shape (n,)
        NaN for a joint whose spread is zero.
    """
    from dynid.identify.estimators import autocovariance  # here: torque_metrics' users need not load it

    dev = np.asarray(deviations, dtype=float)
    if dev.ndim == 2:
        dev = dev[:, :, None]
    present = np.isfinite(dev[:, :, 0])
    dev = np.where(np.isfinite(dev), dev, 0.0)
    per = dev.shape[1]
    dof = float(np.sum(np.maximum(present.sum(axis=0) - 1, 0)))
    if dof <= 0:
        return np.full(dev.shape[2], np.nan)
    lag = int(min(max(rows_per_lag_window, 0), per - 1))

    def lagged(x: np.ndarray) -> np.ndarray:
        """Lagged products along the phase, summed over the periods: (lag + 1, columns)."""
        count, _, cols = x.shape
        acov = autocovariance(x.transpose(1, 0, 2).reshape(per, count * cols), lag)
        return acov.reshape(lag + 1, count, cols).sum(axis=1)

    pairs = lagged(present.astype(float)[:, :, None])  # samples paired at each lag, (lag + 1, 1)
    g = lagged(dev) / np.maximum(pairs, 1.0) * (present.sum() / dof)
    weight = 1.0 - np.arange(1, lag + 1) / per
    total = g[0] ** 2 + 2.0 * (weight @ g[1:] ** 2)
    var_mean = 2.0 * total / dof
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(g[0] > 0, np.sqrt(var_mean) / g[0], np.nan)


def period_stack(x: np.ndarray, per: int, lead: int = 0) -> tuple[np.ndarray, int]:
    """A signal's whole periods at its end, one row each, and ``lead`` samples before them at the last
    phases of one more (NaN where a period holds no sample).

    Parameters
    ----------
    x : ndarray, shape (m, n)
        The signal, uniformly sampled.
    per : int
        Samples per period; at least two whole periods must fit.
    lead : int
        Samples before the whole periods to add (clipped to what the signal holds).

    Returns
    -------
    (stack, lead)
        The stack, shape (K + (lead > 0), per, n) for ``K`` whole periods, and the ``lead`` used.
    """
    count = x.shape[0] // per
    start = x.shape[0] - count * per  # whole periods at the end (the start may hold an approach)
    lead = int(min(max(lead, 0), start))
    stack = np.full((count + (lead > 0), per, x.shape[1]), np.nan)
    stack[int(lead > 0) :] = x[start:].reshape(count, per, -1)
    if lead:
        stack[0, per - lead :] = x[start - lead : start]
    return stack, lead


def noise_floor(
    t: np.ndarray,
    tau: np.ndarray,
    *,
    period: float | None = None,
    band_start: float | None = None,
    lead: int = 0,
) -> NoiseFloor:
    """Measure the noise floor of a torque recording.

    Parameters
    ----------
    t : ndarray, shape (m,)
        Uniform time stamps (s).
    tau : ndarray, shape (m, n)
        Measured torque (N m).
    period : float, optional
        Period (s) of a periodic excitation.  With at least two whole periods, the noise is the spread
        of the torque across periods at the same phase (it then includes whatever does not repeat:
        sensor noise, coloured noise, non-repeatable disturbances).
    band_start : float, optional
        Without periods: frequency (Hz) above which the torque is taken to hold noise only; default a
        quarter of the Nyquist frequency.  The level of the Welch spectrum there (its median, robust
        to leftover harmonics) extended to the whole band gives the variance: right for white noise,
        a lower bound for noise coloured towards low frequencies.
    lead : int
        Samples before the whole periods at the end that repeat too (a part of one more period: what
        trimming the ends of a run of whole periods leaves); they join the spread at their phases.  The
        caller checks that they repeat (:func:`dynid.validation.noise.measure_noise`).
    """
    t = np.asarray(t, dtype=float)
    tau = np.atleast_2d(np.asarray(tau, dtype=float))
    if tau.shape[0] != t.size:
        raise ShapeError(f"t has {t.size} samples and tau {tau.shape[0]} rows; give one row per time stamp.")
    dt = float(np.median(np.diff(t)))
    if not np.allclose(np.diff(t), dt, rtol=1e-3, atol=1e-9):
        raise DataError(
            "the noise floor needs uniform time stamps; resample the data first (dynid preprocess)."
        )
    if period is not None and period > 0:
        per = round(period / dt)
        count = t.size // per
        if count >= 2 and abs(per * dt - period) < 0.01 * dt * per:
            stack, lead = period_stack(tau, per, lead)
            dev = stack - np.nanmean(stack, axis=0)
            dof = np.sum(np.isfinite(stack[:, :, 0]), axis=0) - 1
            # Unbiased spread across periods at each phase, pooled over the phase.
            var = np.nansum(dev**2, axis=(0, 1)) / dof.sum()
            rel = variance_rel_se(dev, round(CORRELATION_SECONDS / dt))
            known = np.isfinite(rel)
            precision = (
                f"; its variance known to +-{100 * float(np.median(rel[known])):.0f} % (one standard error, "
                "median over the joints)"
                if known.any()
                else ""
            )
            return NoiseFloor(
                std=np.sqrt(var),
                method="periods",
                detail=f"spread across {count} periods of {period:g} s"
                + (f" and {lead * dt:.3g} s of one more" if lead else "")
                + precision,
                rel_se=rel,
            )
    fs = 1.0 / dt
    nyquist = fs / 2
    start_f = band_start if band_start is not None else nyquist / 4
    if not 0 < start_f < nyquist:
        raise DataError(
            f"band_start is {start_f:g} Hz; give a frequency between 0 and the Nyquist {nyquist:g} Hz."
        )
    nper = min(t.size, 1024)
    freqs, psd = welch(tau, fs, nper, detrend="constant")
    band = freqs >= start_f
    if band.sum() < 4:
        raise DataError("too few samples to measure a noise floor from the spectrum; record a longer run.")
    level = np.median(psd[band], axis=0)  # one-sided PSD, (N m)^2 / Hz
    var = level * nyquist
    return NoiseFloor(
        std=np.sqrt(var),
        method="spectrum",
        detail=f"median spectral level above {start_f:g} Hz extended to the whole band (white-noise model)",
    )
