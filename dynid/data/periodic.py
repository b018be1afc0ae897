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
>>> check_period(t, q, 2.0, source="V.csv")              # a period given by hand, checked against the angles
"""

from __future__ import annotations

import math
import warnings
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from dynid.exceptions import DataWarning, UsageError

__all__ = ["PERIOD_RULES", "check_period", "overlap_autocorrelation", "period_of"]

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


_APART = 0.1  # check_period: angles one lag apart differ by this much of their spread: they have moved
_FITS = 1e-2  # check_period: angles one period apart within this of their spread: the period fits


def _lag_mismatch(x: NDArray[np.float64]) -> NDArray[np.float64] | None:
    """``mean((x[k:] - x[:-k])^2)`` summed over columns, relative to the spread of ``x`` (centred), at every
    lag ``k = 0..m-1``; None when ``x`` does not move."""
    m = len(x)
    power = np.sum(x**2, axis=1)
    spread = float(power.mean())
    if not spread > 0:
        return None
    nfft = 1 << math.ceil(math.log2(2 * m))
    power_spectrum = np.zeros(nfft // 2 + 1)
    for column in x.T:  # one column at a time: a long recording's spectra need not sit in memory together
        power_spectrum += np.abs(np.fft.rfft(column, nfft)) ** 2
    ac = np.fft.irfft(power_spectrum, nfft)[:m]
    cum = np.concatenate([[0.0], np.cumsum(power)])
    lags = np.arange(m)
    head = cum[m - lags]  # the first m - k rows
    tail = cum[m] - cum[lags]  # the last m - k rows
    return np.maximum(head + tail - 2.0 * ac, 0.0) / (m - lags) / spread


def check_period(
    t: NDArray[np.float64],
    q: NDArray[np.float64],
    period: float,
    *,
    source: str = "the data",
    option: str = "--period",
) -> None:
    """Check a period given by hand against the angles it is to describe.

    A noise floor measured across periods takes the spread of the torque from one period to the next: a
    period the motion does not have makes it meaningless, and one of a few samples (angles that have
    not yet moved) makes it the torque's whole variation, silently.  The rule:

    * refused: a period no longer than the lag at which the angles first differ by a tenth of their
      spread (they have not moved apart, so they "repeat" trivially);
    * refused: angles that repeat (:func:`period_of`, rule ``"repeat"``) with another period, of which
      the one given is not a whole multiple (to 1 %, or 2 samples);
    * accepted: angles that repeat after the period given, to 1 % of their spread, as a whole or on a
      stretch of two periods that moves (a recording of rests and moves around its periods);
    * warned (a :class:`DataWarning`; the data cannot tell, or the noise floor will not use the period): a
      recording shorter than two periods, or angles that do not repeat after it.

    Parameters
    ----------
    t : ndarray, shape (m,)
        Time stamps (s), about uniform.
    q : ndarray, shape (m, n)
        Joint angles (rad).
    period : float
        The period given (s).
    source : str
        What the data came from (a file name), for the messages.
    option : str
        The option that gave the period, for the messages.

    Raises
    ------
    UsageError
        A period that is not a positive number, or that the angles contradict.

    Warns
    -----
    DataWarning
        When the angles cannot confirm the period.
    """
    try:
        period = float(period)
    except (TypeError, ValueError):
        period = math.nan
    if not (period > 0 and math.isfinite(period)):
        raise UsageError(f"{option} is {period}; give the period of the motion in seconds (> 0).")
    t = np.asarray(t, dtype=float).ravel()
    x = np.asarray(q, dtype=float).reshape(len(t), -1)
    m = len(t)
    if m < 8:
        return
    dt = float(np.median(np.diff(t)))
    k = round(period / dt)
    x = x - x.mean(axis=0)
    mismatch = _lag_mismatch(x)
    moved = None if mismatch is None else np.flatnonzero(mismatch[1:] >= _APART) + 1
    if moved is None or moved.size == 0:
        warnings.warn(
            f"{source}: the angles hardly move, so {option} {period:g} s cannot be checked against them",
            DataWarning,
            stacklevel=2,
        )
        return
    apart = int(moved[0])
    if k <= apart:
        length = f"{k} sample{'s' if k != 1 else ''}" if k else f"less than one sample (every {dt:.3g} s)"
        raise UsageError(
            f"{option} {period:g} s is {length} of {source}, over which its angles hardly "
            f"move (they first move apart by a tenth of their spread after {apart * dt:.3g} s), so it cannot be "
            f"the motion's period; give the excitation's period (1 / its base frequency), or leave {option} out "
            "to detect it"
        )
    lag = period_of(x, rule="repeat", min_lag=apart)
    if lag is not None:
        whole = max(1, round(k / lag))
        if abs(k - whole * lag) <= max(2.0, 0.01 * whole * lag):
            return
        raise UsageError(
            f"{option} {period:g} s does not fit {source}: its angles repeat every {lag * dt:.6g} s, and "
            f"{period:g} s is {k / lag:.3g} of those periods, not a whole number; give {option} {lag * dt:.6g} "
            f"(or a whole multiple of it), or leave {option} out to detect it"
        )
    if k < m and (mismatch[k] <= _FITS or _repeating_stretch(x, k)):
        return
    if 2 * k > m:
        warnings.warn(
            f"{source} lasts {t[-1] - t[0]:.4g} s, less than two periods of {option} {period:g} s, so its angles "
            "cannot confirm the period and the noise floor is not measured across periods; record at least "
            "two periods to use it",
            DataWarning,
            stacklevel=2,
        )
        return
    warnings.warn(
        f"the angles of {source} do not repeat after {option} {period:g} s (one period apart they differ by "
        f"{100 * math.sqrt(mismatch[k]):.3g} % of their spread, and no stretch of two periods repeats), so the "
        f"noise floor does not use it; check the period (1 / the excitation's base frequency) or leave {option} "
        "out",
        DataWarning,
        stacklevel=2,
    )


def _repeating_stretch(x: NDArray[np.float64], k: int) -> bool:
    """Whether a stretch of ``x`` (centred) spanning two periods of ``k`` samples repeats after ``k``, sample by
    sample to :data:`_FITS` of the spread, and moves (its spread a tenth of the whole's at least): the periods
    of a recording that rests and moves around them."""
    spread = float(np.mean(np.sum(x**2, axis=1)))
    ok = np.sum((x[k:] - x[:-k]) ** 2, axis=1) <= _FITS * spread
    edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(np.int8), [0]])))
    if edges.size == 0:
        return False
    starts, stops = edges[::2], edges[1::2]
    best = int(np.argmax(stops - starts))
    a, b = int(starts[best]), int(stops[best])
    if b - a < k:
        return False
    part = x[a : b + k] - x[a : b + k].mean(axis=0)
    return float(np.mean(np.sum(part**2, axis=1))) >= _APART * spread
