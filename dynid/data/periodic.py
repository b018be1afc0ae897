"""The period of a motion that repeats: one detector, two rules.

Two users need the period of a periodic excitation, for different ends, and each keeps its own rule
(so no figure changes with the choice):

* ``rule="correlation"`` (:mod:`dynid.identify.gmr`, which keeps phase windows of every period aside
  to validate its correction): the autocorrelation of the standardised inputs, summed over columns, at
  its first stretch above 0.98 beyond its first drop below 0.5; 1.5 periods suffice.
* ``rule="repeat"`` (the noise floor of :mod:`dynid.validation.noise`, the spread of the torque across
  periods): the raw angles must repeat after the period to ``1e-3`` of their spread (quantised encoders
  and noise pass; a non-periodic run does not), and the data must hold two periods.

>>> lag = period_of(q)                                   # samples, or None
>>> lag = period_of(q, rule="repeat", min_lag=500)       # samples, at least 500
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from dynid.exceptions import UsageError

__all__ = ["PERIOD_RULES", "overlap_autocorrelation", "period_of"]

PERIOD_RULES = ("correlation", "repeat")
"""The rules :func:`period_of` knows."""

_PERIODIC = 0.98  # "correlation": autocorrelation at a lag above which the data count as periodic
_REPEAT_TOL = 1e-3  # "repeat": relative mismatch of the data over one period for them to count as periodic


def period_of(
    u: NDArray[np.float64], *, rule: Literal["correlation", "repeat"] = "correlation", min_lag: int = 1
) -> int | None:
    """Period (in samples) of data that repeat, or None.

    Parameters
    ----------
    u : ndarray, shape (m, d)
        Signals in time order, uniformly sampled (inputs ``[q, dq]``, or joint angles in rad).
    rule : {"correlation", "repeat"}
        ``"correlation"``: the peak of the first stretch of lags where the autocorrelation of the
        standardised signals (summed over columns, unbiased at each lag) exceeds 0.98, beyond its first
        drop below 0.5, if the data hold 1.5 periods (two periods trimmed at both ends for a filter
        still count).  ``"repeat"``: among the 20 highest peaks of the overlap-normalised
        autocorrelation of the raw signals (lags ``min_lag`` to ``m / 2``), the shortest whose
        mismatch ``mean((u[k:] - u[:-k])^2)`` is below a tenth of the signals' spread; the exact period
        is the least mismatch within 1 % around it, and counts only if that mismatch is within
        ``1e-3`` of the spread (so the data hold two periods).
    min_lag : int
        Shortest period considered (samples; ``"repeat"`` only).

    Returns
    -------
    int or None
        The period in samples.

    Raises
    ------
    UsageError
        An unknown rule.
    """
    if rule == "correlation":
        return _correlation_period(u)
    if rule == "repeat":
        return _repeat_period(u, min_lag)
    raise UsageError(
        f"unknown period rule {rule!r}; the rules are {', '.join(PERIOD_RULES)}: use one of those."
    )


def _correlation_period(u: NDArray[np.float64]) -> int | None:
    m = len(u)
    if m < 40:
        return None
    x = u - u.mean(axis=0)
    sd = x.std(axis=0)
    x = x[:, sd > 0] / sd[sd > 0]
    if x.shape[1] == 0:
        return None
    size = 1 << int(np.ceil(np.log2(2 * m)))
    F = np.fft.rfft(x, n=size, axis=0)
    # lags up to 2 m / 3: beyond, under a third of the samples overlap and the estimate is noise
    acov = np.fft.irfft(np.abs(F) ** 2, n=size, axis=0)[: m * 2 // 3 + 1].sum(axis=1)
    r = acov / (acov[0] * (m - np.arange(len(acov))) / m)  # unbiased at each lag
    below = np.flatnonzero(r < 0.5)
    if len(below) == 0:
        return None
    high = below[0] + np.flatnonzero(r[below[0] :] > _PERIODIC)
    if len(high) == 0:
        return None
    # the first stretch of lags above the threshold holds the period (later ones its multiples)
    stop = high[0] + int(np.argmax(np.diff(high) > 1)) + 1 if np.any(np.diff(high) > 1) else high[-1] + 1
    lag = int(high[0] + np.argmax(r[high[0] : stop]))
    return lag if m >= 1.5 * lag else None


def overlap_autocorrelation(x: NDArray[np.float64], lo: int, hi: int) -> NDArray[np.float64]:
    """Autocorrelation of the signals ``x`` (m, d), summed over the columns and divided by the overlap
    ``m - k``, at the lags ``k = lo..hi`` (``hi < m``): it peaks at multiples of a period.  ``x`` is taken
    as given (centre it first)."""
    m = len(x)
    nfft = 1 << math.ceil(math.log2(2 * m))
    f = np.fft.rfft(x, nfft, axis=0)
    ac = np.fft.irfft(np.sum(np.abs(f) ** 2, axis=1), nfft)
    lags = np.arange(lo, hi + 1)
    return ac[lags] / (m - lags)


def _repeat_period(u: NDArray[np.float64], min_lag: int) -> int | None:
    q = np.asarray(u, dtype=float)
    m = len(q)
    if m < 8:
        return None
    x = q - q.mean(axis=0)
    spread = float(np.sum(x**2) / m)
    if spread <= 0:
        return None
    lo = max(1, int(min_lag))
    hi = m // 2
    if hi <= lo:
        return None
    # Normalised by the overlap, the autocorrelation peaks at multiples of the period.
    lags = np.arange(lo, hi + 1)
    score = overlap_autocorrelation(x, lo, hi)
    order = np.argsort(score)[::-1][:20]

    def mismatch(k: int) -> float:
        return float(np.mean((x[k:] - x[:-k]) ** 2))

    for L in sorted(lags[order]):
        if mismatch(L) < 0.1 * spread:
            # The exact period: the least mismatch in a window around the peak.
            width = max(3, int(0.01 * L))
            best = min(range(max(lo, L - width), min(hi, L + width) + 1), key=mismatch)
            if mismatch(best) < _REPEAT_TOL**2 * spread * 1e2:
                return int(best)
    return None
