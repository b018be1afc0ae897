"""The noise floor of prepared data: the level a model's held-out error is compared with.

Both :func:`dynid.validation.validate.reference_noise_floor` and the gap diagnosis
(:func:`dynid.diagnosis.core.diagnose`) measure it here, so a validation and a diagnosis of the same data
agree: the spread of the filtered torque across the periods of a periodic excitation
(:func:`dynid.validation.metrics.noise_floor`), over the stretch of the run that repeats when the run
also holds rests and moves that do not (:func:`repeating_stretch`), else the spectral level of the raw
torque through the filter's noise gain.

>>> floor = measure_noise(model.prepare(heldout))      # NoiseFloor: std (N m) per joint
>>> detect_period(prep.t, prep.q)                       # s, or None
>>> encoder_step(heldout.q)                             # rad per joint, 0 where not quantised
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import binary_opening, uniform_filter1d

from dynid.data.periodic import overlap_autocorrelation, period_of
from dynid.data.preparation import Prepared
from dynid.exceptions import DataError
from dynid.validation.metrics import NoiseFloor, noise_floor, period_stack

__all__ = [
    "MIN_SPECTRAL_SAMPLES",
    "REPEAT_TOL",
    "detect_period",
    "encoder_step",
    "filter_noise_gain",
    "measure_noise",
    "periodic_deviation",
    "repeated_periods",
    "repeating_stretch",
]

MIN_SPECTRAL_SAMPLES = 2048
"""Fewest samples of one run for the spectral noise floor (when the data do not repeat a period): three
half-overlapping Welch segments of 1024 samples, so that a 37 s recording at 100 Hz is measured."""


def detect_period(t: NDArray[np.float64], q: NDArray[np.float64], *, min_period: float = 0.5) -> float | None:
    """Period (s) of a periodic motion, or None when the data hold fewer than two periods.

    The angles must repeat after the period to ``1e-3`` of their spread (quantised encoders and noise
    pass; a non-periodic run does not): :func:`dynid.data.periodic.period_of` with
    ``rule="repeat"``, in seconds.

    Parameters
    ----------
    t : ndarray, shape (M,)
        Uniform time stamps (s).
    q : ndarray, shape (M, n)
        Joint angles (rad).
    min_period : float
        Shortest period considered (s).
    """
    if len(t) < 2:
        return None
    dt = float(np.median(np.diff(t)))
    lag = period_of(np.asarray(q, dtype=float), rule="repeat", min_lag=int(min_period / dt))
    return None if lag is None else lag * dt


def filter_noise_gain(prep: Prepared) -> float:
    """Variance gain of the parallel filter (run forward and backward) on white noise (1 without a filter).

    Parameters
    ----------
    prep : Prepared
        The prepared data (their torque filter).
    """
    if prep.sos is None:
        return 1.0
    from dynid.data.dsp import frequency_response

    h = frequency_response(prep.sos, np.arange(8192) / 8192 * 0.5, 1.0)  # sosfreqz's 8192 points to Nyquist
    return float(np.mean(np.abs(h) ** 4))


def measure_noise(prep: Prepared, *, period: float | None = None) -> NoiseFloor:
    """Noise floor of the filtered torque of prepared data (the level the model's residual is compared with).

    Parameters
    ----------
    prep : Prepared
        The data as the model sees them.
    period : float, optional
        Period (s) of the excitation; detected from the angles when not given.  When the run as a whole
        does not repeat (to :data:`REPEAT_TOL`), the stretch of it that does is used
        (:func:`repeating_stretch`: a robot playing the CSV of ``dynid excite`` records a rest and an
        approach before the periods, a retreat and a rest after them), with the part period it holds
        beyond its whole periods; without such a stretch a given period is not used, and the floor's
        detail says so.

    Returns
    -------
    NoiseFloor
        Standard deviation per joint (N m) of the filtered torque that does not repeat.

    Raises
    ------
    DataError
        Fewer than two periods and too few samples for the spectral method.
    """
    run = max(prep.runs, key=lambda r: r.stop - r.start)
    rows = prep.rows[(prep.rows >= run.start) & (prep.rows < run.stop)]
    span = slice(int(rows[0]), int(rows[-1]) + 1)
    t = prep.t[span]
    ignored = ""
    given = period
    tau_f = prep.filter(prep.tau)[span]
    if period is not None and not (
        _repeats(prep.q[span], period * prep.fs) or _repeats(tau_f, period * prep.fs)
    ):
        ignored = (
            f"; neither the angles nor the torque repeat after the period of {period:g} s given, so it is "
            "not used"
        )
        period = None
    elif period is None:
        period = detect_period(t, prep.q[span])
    if period is not None and (t[-1] - t[0]) >= 2 * period - 1.5 / prep.fs:
        floor = noise_floor(t, tau_f, period=period)
        if floor.method == "periods":
            return floor
    # A periodic excitation recorded between rests and moves that do not repeat (a robot playing the CSV
    # of dynid excite: rest, approach, the periods, retreat, rest): the stretch that repeats.
    found = repeating_stretch(prep.q[span], prep.fs, ddq=prep.ddq[span], period=given)
    if found is not None:
        a, b, per = found
        # The stretch holds whole periods and part of one more, which repeats too: it joins the spread.
        lead = (b - a) % round(per * prep.fs)
        floor = noise_floor(t[a:b], tau_f[a:b], period=per, lead=lead)
        if floor.method == "periods":
            return replace(
                floor,
                detail=f"{floor.detail}; over t = {t[a]:.4g}..{t[b - 1]:.4g} s, the stretch that repeats (the "
                "rest of the run does not)",
            )
    m = run.stop - run.start
    if m < MIN_SPECTRAL_SAMPLES:
        have = f"{(t[-1] - t[0]) / period:.2f} periods of {period:.3g} s" if period else "no repeated period"
        raise DataError(
            f"cannot measure the noise floor of the held-out data: they hold {have} and {m} samples, "
            f"fewer than the {MIN_SPECTRAL_SAMPLES} the spectral method needs{ignored}; record at least two "
            "whole periods of a periodic excitation (or a longer run)."
        )
    raw = noise_floor(prep.t[run], prep.tau[run])
    gain = filter_noise_gain(prep)
    return NoiseFloor(
        std=raw.std * math.sqrt(gain),
        method="spectrum",
        detail=raw.detail + (f", times the filter's noise gain {gain:.3g}" if gain != 1.0 else "") + ignored,
    )


def periodic_deviation(prep: Prepared) -> tuple[NDArray[np.float64], int] | None:
    """The filtered torque's deviation from its mean over the periods: the part that does not repeat.

    Found as :func:`measure_noise` finds the periods (the whole run, else the stretch that repeats, with
    the part of one more period it holds); at a phase held by ``K`` periods the deviation is scaled by
    ``sqrt(K / (K - 1))``, so that it has the noise's variance.  Any effect of the state is periodic in a
    periodic run and drops out: what is left is noise (and drift), over the whole band, the motion's
    frequencies included (bar narrow notches at its harmonics).  :mod:`dynid.diagnosis.consistency`
    models the training noise on it.

    Parameters
    ----------
    prep : Prepared
        The prepared data.

    Returns
    -------
    (deviation, start) or None
        The deviation, shape (M, n) at the full rate over the ``M`` samples that repeat, and the index in
        ``prep`` of its first sample; None when the data do not repeat at least two whole periods.
    """
    found = _repeating_span(prep)
    if found is None:
        return None
    a0, b0, per = found
    tau_f = prep.filter(prep.tau)[a0:b0]
    # The whole periods and the part of one more before them, at its last phases.
    stack, _lead = period_stack(tau_f, per, (b0 - a0) % per)
    have = np.sum(np.isfinite(stack[:, :, 0]), axis=0)  # periods holding each phase: 2 or more
    dev = (stack - np.nanmean(stack, axis=0)) * np.sqrt(have / (have - 1))[None, :, None]
    dev = dev.reshape(-1, tau_f.shape[1])
    return dev[np.isfinite(dev[:, 0])], a0  # time order: the lead, then the whole periods


def repeated_periods(prep: Prepared) -> tuple[int, int, int] | None:
    """Where a run repeats its period: the stretch :func:`periodic_deviation` stacks.

    Parameters
    ----------
    prep : Prepared
        The prepared data.

    Returns
    -------
    (start, stop, per) or None
        Indices in ``prep`` of the stretch that repeats (its whole periods at its end, the part of one
        more before them) and the samples per period; None when the data do not repeat two whole periods.
    """
    return _repeating_span(prep)


def _repeating_span(prep: Prepared) -> tuple[int, int, int] | None:
    """``(a, b, per)``: the stretch of ``prep`` (indices) that repeats a period of ``per`` samples at least
    twice (the longest run, as a whole when it repeats, else its stretch that does), or None."""
    run = max(prep.runs, key=lambda r: r.stop - r.start)
    rows = prep.rows[(prep.rows >= run.start) & (prep.rows < run.stop)]
    if rows.size < 8:
        return None
    a0, b0 = int(rows[0]), int(rows[-1]) + 1
    per_s = detect_period(prep.t[a0:b0], prep.q[a0:b0])
    a, b = 0, b0 - a0
    if per_s is None:
        found = repeating_stretch(prep.q[a0:b0], prep.fs, ddq=prep.ddq[a0:b0])
        if found is None:
            return None
        a, b, per_s = found
    per = round(per_s * prep.fs)
    if per <= 0 or (b - a) // per < 2:
        return None
    return a0 + a, a0 + b, per


STRETCH_TOL = 1e-4
"""Largest mismatch of the angles one period apart, sample by sample, relative to their spread, inside a
stretch that repeats (:func:`repeating_stretch`)."""
STRETCH_TOL_DDQ = 1e-3
"""The same for the filtered accelerations."""


def repeating_stretch(
    q: NDArray[np.float64],
    fs: float,
    *,
    ddq: NDArray[np.float64] | None = None,
    period: float | None = None,
    min_period: float = 0.5,
) -> tuple[int, int, float] | None:
    """The longest stretch of a run whose angles repeat a period, and the period.

    A robot playing an excitation records more than its periods: a rest, an approach, the periods, a
    retreat, a rest.  The run as a whole then does not repeat, but the middle does.  For each candidate
    lag (the period given, else the peaks of the overlap-normalised autocorrelation of the angles from
    ``min_period`` to half the run, shortest first) the angles are compared one lag apart sample by
    sample; the longest stretch within :data:`STRETCH_TOL` of their spread that spans at least two
    periods, and moves (its spread at least a tenth of the run's: a long rest also repeats), is taken.
    With ``ddq``, the accelerations must repeat too: their mismatch, averaged over 0.05 s, may exceed
    :data:`STRETCH_TOL_DDQ` of their spread (and ten times its median where the angles repeat) for less
    than 0.2 s only, the bursts of differentiated quantised angles.  Where a retreat leaves the periodic
    motion, the angles stay within a few microradians for a tenth of a second while the accelerations, and
    so the torque, already differ.  A detected lag is first moved, within 1 % (at most 200 samples), to the
    one at which most samples repeat, then to the one that matches best over the stretch.

    Parameters
    ----------
    q : ndarray, shape (m, n)
        Joint angles (rad), uniformly sampled.
    fs : float
        Sample rate (Hz).
    ddq : ndarray, shape (m, n), optional
        Joint accelerations (rad/s^2), filtered.
    period : float, optional
        Period (s) of the excitation, if known.
    min_period : float
        Shortest period considered when detecting (s).

    Returns
    -------
    (start, stop, period) or None
        Sample indices of the stretch (``stop`` exclusive) and the period (s).
    """
    x = np.asarray(q, dtype=float)
    x = x - x.mean(axis=0)
    m = len(x)
    spread = float(np.mean(np.sum(x**2, axis=1))) if m else 0.0
    if spread <= 0 or m < 8:
        return None
    if period is not None:
        candidates = [round(period * fs)]
    else:
        lo, hi = max(1, int(min_period * fs)), m // 2
        if hi <= lo + 2:
            return None
        lags = np.arange(lo, hi + 1)
        score = overlap_autocorrelation(x, lo, hi)
        peak = np.flatnonzero((score[1:-1] >= score[:-2]) & (score[1:-1] >= score[2:])) + 1
        candidates = sorted(int(k) for k in lags[peak[np.argsort(score[peak])[::-1][:10]]])

    if ddq is not None:
        a2 = np.asarray(ddq, dtype=float)
        a2 = a2 - a2.mean(axis=0)
        spread2 = max(float(np.mean(np.sum(a2**2, axis=1))), 1e-300)

    def stretch(k: int, accelerations: bool) -> tuple[int, int] | None:
        good = np.sum((x[k:] - x[:-k]) ** 2, axis=1) <= STRETCH_TOL * spread
        if accelerations and ddq is not None and good.any():
            # Where the accelerations differ for a fifth of a second or more, the motion differs; shorter
            # bursts are the noise of differentiated quantised angles (an angle one count off in one
            # period), which the torque does not share.
            e2 = uniform_filter1d(np.sum((a2[k:] - a2[:-k]) ** 2, axis=1), max(1, round(0.05 * fs)))
            bad = e2 > max(STRETCH_TOL_DDQ * spread2, 10.0 * float(np.median(e2[good])))
            good &= ~binary_opening(bad, structure=np.ones(max(1, round(0.2 * fs)), dtype=bool))
        edges = np.flatnonzero(np.diff(np.concatenate([[0], good.astype(np.int8), [0]])))
        if not edges.size:
            return None
        starts, stops = edges[0::2], edges[1::2]
        i = int(np.argmax(stops - starts))
        return int(starts[i]), int(stops[i])

    # Lags tried around a candidate (within 1 %, at most 200 samples), compared on about 20000 rows of
    # the run at most: a long log that does not repeat stays quick.
    stride = max(1, m // 20000)

    def near(k: int) -> range:
        width = max(2, min(int(0.01 * k), 200))
        return range(max(1, k - width), min(m // 2, k + width) + 1)

    def refine(k: int, a: int, b: int) -> int:
        """The lag near ``k`` whose angles match best over ``a:b``."""

        def mismatch(j: int) -> float:
            stop = min(b, m - j)
            return float(np.mean(np.sum((x[a + j : stop + j : stride] - x[a:stop:stride]) ** 2, axis=1)))

        return min(near(k), key=mismatch)

    def repeating(j: int) -> int:
        """Rows (of those compared) whose angles repeat after ``j``."""
        return int(np.sum(np.sum((x[j:][::stride] - x[:-j][::stride]) ** 2, axis=1) <= STRETCH_TOL * spread))

    for k in candidates:
        if not 0 < k <= m // 2:
            continue
        if period is None:
            # The autocorrelation's peak is only near the period: the lag that repeats most, then the one
            # that matches best over the stretch of the angles alone.
            k = max(near(k), key=repeating)
            found = stretch(k, False)
            if found is None or found[1] - found[0] < k:
                continue
            k = refine(k, *found)
        found = stretch(k, True)
        if found is None or found[1] - found[0] < k:
            continue
        a, b = found
        seg = x[a : b + k]
        if float(np.mean(np.sum((seg - seg.mean(axis=0)) ** 2, axis=1))) < 0.1 * spread:
            continue  # a rest repeats too
        return a, b + k, k / fs
    return None


REPEAT_TOL = 1e-2
"""Largest mean square mismatch of the angles (or of the filtered torque) one given period apart, relative
to their spread, for the data to count as repeating with that period (a wrong period on an aperiodic
motion gives about 2)."""


def _repeats(q: NDArray[np.float64], lag: float) -> bool:
    """Whether the signals ``q`` repeat after ``lag`` samples (to :data:`REPEAT_TOL` of their spread)."""
    k = round(lag)
    if not 0 < k < len(q):
        return True  # fewer than two periods: the spread across periods is not used anyway
    x = q - q.mean(axis=0)
    spread = float(np.mean(np.sum(x**2, axis=1)))
    if spread <= 0:
        return True
    return float(np.mean(np.sum((x[k:] - x[:-k]) ** 2, axis=1))) <= REPEAT_TOL * spread


def encoder_step(q: NDArray[np.float64], *, min_moves: int = 50, tol: float = 1e-3) -> NDArray[np.float64]:
    """The quantisation step (rad) of logged angles, per joint, read from their distinct increments.

    A joint's angles come from an encoder when every non-zero increment between samples is a whole
    multiple of one step, to within ``tol`` of a step (an absolute tolerance; the step is the smallest
    increment refined by least squares over all of them, so that a log's last digit does not bias it):
    a 14-bit encoder moves by multiples of ``2 pi / 2^14``; unquantised angles (a filter's output, a
    simulator's states) move by arbitrary amounts and give 0, even when one of their increments is tiny
    (a tolerance relative to each increment would let every increment of 1/tol steps or more pass as a
    whole multiple).

    Parameters
    ----------
    q : ndarray, shape (m, n)
        Logged angles (rad).
    min_moves : int
        Fewest non-zero increments for a step to be read (fewer: 0).
    tol : float
        Tolerance of the whole multiples, in steps.

    Returns
    -------
    ndarray, shape (n,)
        Step (rad) per joint; 0 where the angles do not look quantised.
    """
    q = np.asarray(q, dtype=float)
    out = np.zeros(q.shape[1])
    for j in range(q.shape[1]):
        d = np.abs(np.diff(q[:, j]))
        scale = max(float(np.max(np.abs(q[:, j]))), 1.0)
        d = d[d > 1e-12 * scale]
        if d.size < min_moves:
            continue
        step = float(np.min(d))
        # The smallest increment carries the rounding of the stored angles (a log's last digit); the step
        # is refined by least squares over every increment's whole multiple, and the multiples checked
        # against it to within tol steps (plus the float spacing of the angles).
        for _ in range(2):
            k = np.maximum(np.round(d / step), 1.0)
            step = float(np.sum(d * k) / np.sum(k * k))
        k = np.maximum(np.round(d / step), 1.0)
        if np.all(np.abs(d - k * step) <= tol * step + 4.0 * float(np.spacing(scale))):
            out[j] = step
    return out
