"""Resampling of irregularly stamped data onto a uniform grid, without interpolating across gaps.

:func:`resample_uniform` interpolates one signal array; :func:`resample` does a whole dataset run by
run and splits it into separate runs where the stamps jump (:data:`GAP_STEPS`, :data:`GAP_SECONDS`).
Split out of :mod:`dynid.data.preprocess`, which re-exports its names.
"""

from __future__ import annotations

import itertools
import warnings
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynid.data.dataset import Dataset
from dynid.exceptions import DataError, DataWarning

__all__ = [
    "GAP_SECONDS",
    "GAP_STEPS",
    "MIN_PIECE_SAMPLES",
    "ResampleMethod",
    "resample",
    "resample_uniform",
]

ResampleMethod = Literal["linear", "cubic"]
_METHODS = ("linear", "cubic")


def resample_uniform(
    t: ArrayLike,
    y: ArrayLike,
    *,
    dt: float | None = None,
    method: ResampleMethod = "linear",
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Interpolate irregularly stamped samples onto a uniform time grid.

    Rows whose stamp repeats the previous one are dropped (the first is kept).

    Parameters
    ----------
    t : array_like, shape (m,)
        Time stamps (s), non-decreasing.
    y : array_like, shape (m, ...)
        Samples; time along axis 0.
    dt : float, optional
        Grid step (s).  Default: the median step of the stamps.
    method : {"linear", "cubic"}
        Linear interpolation, or a not-a-knot cubic spline (smooth signals, fine stamps).

    Returns
    -------
    t_new : ndarray, shape (k,)
        ``t[0] + dt * arange(k)``, the last point not after ``t[-1]``.
    y_new : ndarray, shape (k, ...)
        Interpolated samples.

    Raises
    ------
    DataError
        Stamps that go backwards, non-finite stamps, fewer than 2 distinct stamps, a bad ``dt`` or method.
    """
    if method not in _METHODS:
        raise DataError(f"method must be 'linear' or 'cubic'; got {method!r}; pick one of those")
    t = np.asarray(t, dtype=np.float64).ravel()
    y = np.asarray(y, dtype=np.float64)
    if y.shape[:1] != t.shape:
        rows = y.shape[0] if y.ndim else 0
        raise DataError(f"y has {rows} rows but t has {len(t)}; give one row per time stamp")
    if not np.isfinite(t).all():
        k = int(np.argmax(~np.isfinite(t)))
        raise DataError(f"t is {t[k]} at row {k}; time stamps must be finite: drop that row")
    steps = np.diff(t)
    if (steps < 0).any():
        k = int(np.argmax(steps < 0))
        raise DataError(
            f"t goes backwards at row {k + 1} ({t[k + 1]:.9g} s after {t[k]:.9g} s); "
            "sort the rows by time before resampling"
        )
    keep = np.concatenate(([True], steps > 0))
    if not keep.all():
        t, y = t[keep], y[keep]
    if len(t) < 2:
        raise DataError(f"resampling needs at least 2 distinct time stamps; got {len(t)}; keep more samples")
    if dt is None:
        dt = float(np.median(np.diff(t)))
    if not (np.isfinite(dt) and dt > 0):
        raise DataError(f"dt must be a positive number of seconds; got {dt!r}; pass e.g. dt=0.001")
    k = int(np.floor((t[-1] - t[0]) / dt * (1.0 + 1e-12))) + 1
    t_new = t[0] + dt * np.arange(k)
    if method == "linear":
        i = np.clip(np.searchsorted(t, t_new, side="right") - 1, 0, len(t) - 2)
        w = ((t_new - t[i]) / (t[i + 1] - t[i])).reshape((-1,) + (1,) * (y.ndim - 1))
        y_new = y[i] + w * (y[i + 1] - y[i])
    else:
        from scipy.interpolate import CubicSpline  # here: only a recording that needs it pays the import

        y_new = CubicSpline(t, y, axis=0)(t_new)
    return t_new, np.asarray(y_new, dtype=np.float64)


GAP_STEPS = 10.0
"""A step between stamps longer than this many median steps (and than :data:`GAP_SECONDS`) is a gap."""
GAP_SECONDS = 0.1
"""Shortest gap (s): shorter holes (a late sample of a real-time log) are interpolated across."""
MIN_PIECE_SAMPLES = 64
"""Fewest samples of a piece between gaps that :func:`resample` keeps (shorter ones are dropped, with a
warning): no filter or derivative can use fewer."""


def _split_at_gaps(t: NDArray[np.float64], step: float) -> list[slice]:
    """Row ranges of ``t`` between gaps (steps longer than :data:`GAP_STEPS` steps and :data:`GAP_SECONDS`)."""
    jumps = np.flatnonzero(np.diff(t) > max(GAP_STEPS * step, GAP_SECONDS)) + 1
    bounds = [0, *jumps.tolist(), len(t)]
    return [slice(a, b) for a, b in itertools.pairwise(bounds)]


def resample(ds: Dataset, *, dt: float | None = None, method: ResampleMethod = "linear") -> Dataset:
    """Resample a dataset onto a uniform grid, run by run.

    A gap in the stamps (a step longer than :data:`GAP_STEPS` median steps and :data:`GAP_SECONDS`)
    is never interpolated across: the run is split there into separate runs, so that filters and
    derivatives do not cross it, and the samples after it keep their time.  Pieces between gaps with
    fewer than :data:`MIN_PIECE_SAMPLES` samples are dropped.  Both come with a :class:`DataWarning`.

    Parameters
    ----------
    ds : Dataset
        Data with irregular stamps (e.g. the Panda recording).
    dt : float, optional
        Grid step (s); default ``ds.dt`` (the median step).
    method : {"linear", "cubic"}
        Interpolation, see :func:`resample_uniform`.

    Returns
    -------
    Dataset
        Uniform data: one grid ``t[0] + dt * k`` over all runs (each run starts one step after the previous
        ends; a piece after a gap starts at its own first stamp), ``meta["resampled"]`` records ``dt``,
        ``method``, the rows before and the gaps (start time and length, s).

    Raises
    ------
    DataError
        When no piece between gaps is long enough to keep.
    """
    step = ds.dt if dt is None else float(dt)
    signals = [name for name in ("q", "tau", "dq", "ddq") if getattr(ds, name) is not None]
    stacked = np.concatenate([getattr(ds, name) for name in signals], axis=1)
    pieces, times, starts, offset = [], [], [], 0
    gaps: list[list[float]] = []
    dropped = 0
    for run in ds.runs:
        t_run = ds.t[run]
        t_start = ds.t[0] + step * offset  # where the run starts on the one grid
        for piece in _split_at_gaps(t_run, step):
            if piece.start > 0:
                before, after = float(t_run[piece.start - 1]), float(t_run[piece.start])
                gaps.append([before, after - before])
            if piece.stop - piece.start < MIN_PIECE_SAMPLES:
                dropped += piece.stop - piece.start
                continue
            _, y_new = resample_uniform(t_run[piece], stacked[run][piece], dt=step, method=method)
            first = t_start + (t_run[piece.start] - t_run[0])
            if times and first <= times[-1][-1]:
                first = times[-1][-1] + step
            pieces.append(y_new)
            times.append(first + step * np.arange(len(y_new)))
            starts.append(offset)
            offset += len(y_new)
    if gaps:
        where = ", ".join(f"{length:.3g} s at t = {t0:.6g} s" for t0, length in gaps[:3])
        warnings.warn(
            f"the time stamps jump {len(gaps)} time{'s' if len(gaps) > 1 else ''} ({where}"
            f"{', ...' if len(gaps) > 3 else ''}); the data are split there into separate runs, not "
            "interpolated across the gap"
            + (
                f", and {dropped} samples in pieces shorter than {MIN_PIECE_SAMPLES} samples are dropped"
                if dropped
                else ""
            ),
            DataWarning,
            stacklevel=2,
        )
    if not pieces:
        raise DataError(
            f"the data hold no stretch of at least {MIN_PIECE_SAMPLES} samples between gaps in the time "
            "stamps; record without gaps"
        )
    y_all = np.concatenate(pieces)
    t_all = np.concatenate(times)
    meta = {key: value for key, value in ds.meta.items() if key != "run_starts"}
    meta["resampled"] = {"dt": step, "method": method, "rows_before": ds.m}
    if gaps:
        meta["resampled"]["gaps"] = gaps
    if len(starts) > 1:
        meta["run_starts"] = starts
    split = np.split(y_all, np.cumsum([ds.n] * (len(signals) - 1)), axis=1)
    arrays = dict(zip(signals, split, strict=True))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)  # already checked on ds
        return Dataset(
            t_all, arrays["q"], arrays["tau"], dq=arrays.get("dq"), ddq=arrays.get("ddq"), meta=meta
        )
