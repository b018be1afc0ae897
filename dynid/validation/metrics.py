"""Prediction-error metrics and a measured noise floor.

:func:`torque_metrics` compares a measured with a predicted torque, per joint; :func:`noise_floor`
measures how much of the torque no model can predict (never assumed): from repeated periods of a
periodic excitation when the data hold several, else from the high-frequency part of the spectrum.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import welch

from dynid.exceptions import DataError, ShapeError

__all__ = ["NoiseFloor", "noise_floor", "torque_metrics"]


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
    """

    std: np.ndarray
    method: str
    detail: str

    @property
    def rms_mean(self) -> float:
        return float(np.mean(self.std))


def noise_floor(
    t: np.ndarray,
    tau: np.ndarray,
    *,
    period: float | None = None,
    band_start: float | None = None,
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
            start = t.size - count * per  # whole periods at the end (the start may hold an approach)
            stack = tau[start:].reshape(count, per, -1)
            # Unbiased spread across periods, averaged over the phase.
            var = np.mean(np.var(stack, axis=0, ddof=1), axis=0)
            return NoiseFloor(
                std=np.sqrt(var), method="periods", detail=f"spread across {count} periods of {period:g} s"
            )
    fs = 1.0 / dt
    nyquist = fs / 2
    start_f = band_start if band_start is not None else nyquist / 4
    if not 0 < start_f < nyquist:
        raise DataError(
            f"band_start is {start_f:g} Hz; give a frequency between 0 and the Nyquist {nyquist:g} Hz."
        )
    nper = min(t.size, 1024)
    freqs, psd = welch(tau, fs=fs, nperseg=nper, axis=0, detrend="constant")
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
