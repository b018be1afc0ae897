"""Preprocessing of measured data: resampling, zero-phase low-pass filtering, differentiation, decimation.

The usual path from a raw recording to data an estimator can use is :func:`preprocess`::

    ds = preprocess(raw, cutoff=20.0, decimate=5)      # resample if irregular, filter, dq/ddq, decimate, trim

Every step works run by run (``Dataset.runs``), so a filter never smears one run into the next.

Parallel filtering
------------------
Filtering the torque but building the regressor from filtered states is not the same model: the regressor
is nonlinear in the states, so ``Y(filtered states) @ p != filtered(Y(states) @ p)`` and the difference looks
like an unmodelled effect (DIAGNOSIS.md, section 3).  :func:`parallel_filter` applies one filter to the torque
and to every column of the regressor, so that ``filtered(tau) = filtered(Y) @ p`` holds exactly when
``tau = Y @ p``::

    states = preprocess(raw, cutoff=50.0, filter_torque=False, trim=0.0)  # states for the regressor
    Y = regressor(states.q, states.dq, states.ddq)                         # (m, n, p)
    tau_f, Y_f = parallel_filter(states.tau, Y, fs=1 / states.dt, cutoff=10.0, runs=states.runs,
                                 decimate=10, trim=0.2)

On long data (hundreds of thousands of samples, a regressor of a gigabyte) :func:`parallel_filter` filters
a few columns at a time and writes only the rows kept (or filters in place with ``inplace=True``), so the
memory needed stays close to the size of the result.

The steps live in modules of their own, whose names this module re-exports (import them from here or
from there): :mod:`dynid.data.cutoff` (the cut-off chosen from the data), :mod:`dynid.data.resampling`
(uniform grids, gaps), :mod:`dynid.data.filters` (the zero-phase filter's design) and
:mod:`dynid.data.rows` (runs, trimming, decimation).  This module filters data run by run
(:func:`lowpass`, :func:`parallel_filter`), differentiates (:func:`central_difference`) and holds the
whole path (:func:`preprocess`).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynid.data.cutoff import BANDWIDTH_FACTOR, SIGNAL_DB, choose_cutoff
from dynid.data.dataset import Dataset
from dynid.data.filters import butter_sos, filter_order, filter_padding, filtfilt_rows
from dynid.data.resampling import (
    GAP_SECONDS,
    GAP_STEPS,
    MIN_PIECE_SAMPLES,
    ResampleMethod,
    resample,
    resample_uniform,
)
from dynid.data.rows import as_runs, decimate, kept_rows, trim, whole_samples
from dynid.exceptions import DataError, DataWarning

__all__ = [
    "BANDWIDTH_FACTOR",
    "GAP_SECONDS",
    "GAP_STEPS",
    "MIN_PIECE_SAMPLES",
    "SIGNAL_DB",
    "butter_sos",
    "central_difference",
    "choose_cutoff",
    "decimate",
    "filter_order",
    "filter_padding",
    "filtfilt_rows",
    "kept_rows",
    "lowpass",
    "parallel_filter",
    "preprocess",
    "resample",
    "resample_uniform",
    "trim",
]

#: Number of float64 values filtered at once (about 32 MB); bounds the filter's temporary memory.
_CHUNK_VALUES = 4_000_000


# ---------------------------------------------------------------------- filtering
def _filter_columns(
    y2: NDArray[np.float64],
    sos: NDArray[np.float64],
    runs: list[slice],
    rows: NDArray[np.intp] | None,
    out2: NDArray[np.float64],
) -> None:
    """Filter the columns of ``y2`` (m, k) run by run, a few at a time, into ``out2`` (rows kept only).

    ``rows`` None means all rows (``out2`` may then be ``y2`` itself: in place).
    """
    k = y2.shape[1]
    longest = max(run.stop - run.start for run in runs)
    chunk = max(1, _CHUNK_VALUES // max(longest, 1))
    pad = filter_padding(sos)
    for r, run in enumerate(runs):
        length = run.stop - run.start
        if length <= pad:
            raise DataError(
                f"run {r} has {length} samples, too short for an order-{filter_order(sos)} zero-phase filter "
                f"(needs more than {pad}); drop that run or record longer"
            )
        if rows is None:
            dest_rows: slice | NDArray[np.intp] = run
            local: NDArray[np.intp] | None = None
        else:
            lo, hi = np.searchsorted(rows, [run.start, run.stop])
            if hi == lo:
                continue
            dest_rows = np.arange(lo, hi)
            local = rows[lo:hi] - run.start
        for j in range(0, k, chunk):
            cols = slice(j, min(j + chunk, k))
            filtered = filtfilt_rows(sos, y2[run, cols].T)
            out2[dest_rows, cols] = filtered.T if local is None else filtered[:, local].T


def lowpass(
    y: ArrayLike,
    *,
    fs: float,
    cutoff: float,
    order: int = 5,
    runs: Sequence[slice] | None = None,
    inplace: bool = False,
) -> NDArray[np.float64]:
    """Zero-phase Butterworth low-pass along time (axis 0), run by run.

    Parameters
    ----------
    y : array_like, shape (m, ...)
        Samples; time along axis 0, any trailing shape (e.g. (m, n) signals, (m, n, p) regressor).
    fs : float
        Sampling frequency (Hz); the samples must be uniform.
    cutoff : float
        Cut-off frequency (Hz).
    order : int
        Butterworth order (default 5).
    runs : sequence of slice, optional
        Row ranges filtered separately (``Dataset.runs``); default one run.
    inplace : bool
        Overwrite ``y`` (which must then be a writeable, C-contiguous float64 array) instead of allocating.

    Returns
    -------
    ndarray, shape (m, ...)
        The filtered samples (``y`` itself when ``inplace``).
    """
    sos = butter_sos(cutoff, fs, order)
    if inplace:
        if not (
            isinstance(y, np.ndarray) and y.dtype == np.float64 and y.flags.c_contiguous and y.flags.writeable
        ):
            raise DataError(
                "inplace=True needs a writeable, C-contiguous float64 array; "
                "pass np.ascontiguousarray(y, dtype=float) or inplace=False"
            )
        arr = y
    else:
        arr = np.ascontiguousarray(y, dtype=np.float64)
    if arr.ndim == 0:
        raise DataError("y must have a time axis 0; got a scalar; pass an array of shape (m, ...)")
    y2 = arr.reshape(arr.shape[0], -1)
    out2 = y2 if inplace else np.empty_like(y2)
    _filter_columns(y2, sos, as_runs(runs, arr.shape[0]), None, out2)
    return arr if inplace else out2.reshape(arr.shape)


# ---------------------------------------------------------------------- differentiation
def _second_difference(y: NDArray[np.float64], dt: float) -> NDArray[np.float64]:
    out = np.empty_like(y)
    out[1:-1] = (y[2:] - 2.0 * y[1:-1] + y[:-2]) / dt**2
    out[0] = (2.0 * y[0] - 5.0 * y[1] + 4.0 * y[2] - y[3]) / dt**2
    out[-1] = (2.0 * y[-1] - 5.0 * y[-2] + 4.0 * y[-3] - y[-4]) / dt**2
    return out


def central_difference(
    y: ArrayLike,
    dt: float,
    *,
    derivative: Literal[1, 2] = 1,
    runs: Sequence[slice] | None = None,
) -> NDArray[np.float64]:
    """Second-order accurate derivative of uniformly sampled data, run by run.

    Interior points use central differences, ``(y[i+1] - y[i-1]) / (2 dt)`` and
    ``(y[i+1] - 2 y[i] + y[i-1]) / dt^2``; the end points use one-sided second-order formulas
    (:func:`numpy.gradient` with ``edge_order=2`` for the first derivative).  The error is ``O(dt^2)``
    everywhere.

    Parameters
    ----------
    y : array_like, shape (m, ...)
        Samples, time along axis 0 (e.g. q in rad).
    dt : float
        Sample time (s).
    derivative : {1, 2}
        Order of the derivative.
    runs : sequence of slice, optional
        Row ranges differentiated separately; default one run.

    Returns
    -------
    ndarray, shape (m, ...)
        dy/dt (e.g. rad/s) or d2y/dt2 (rad/s^2).
    """
    if derivative not in (1, 2):
        raise DataError(f"derivative must be 1 or 2; got {derivative!r}; differentiate twice for more")
    if not (np.isfinite(dt) and dt > 0):
        raise DataError(f"dt must be a positive number of seconds; got {dt!r}; pass dt=ds.dt")
    arr = np.asarray(y, dtype=np.float64)
    out = np.empty_like(arr)
    need = 3 if derivative == 1 else 4
    for r, run in enumerate(as_runs(runs, len(arr))):
        seg = arr[run]
        if len(seg) < need:
            raise DataError(
                f"run {r} has {len(seg)} samples; derivative {derivative} to second order needs at least "
                f"{need}; drop that run"
            )
        if derivative == 1:
            out[run] = np.gradient(seg, dt, axis=0, edge_order=2)
        else:
            out[run] = _second_difference(seg, dt)
    return out


def _check_decimation(cutoff: float, fs: float, decimate: int) -> None:
    """The cut-off must lie below the Nyquist frequency after decimation."""
    if cutoff >= fs / (2 * decimate):
        raise DataError(
            f"decimating by {decimate} puts the Nyquist frequency at {fs / (2 * decimate):g} Hz, not above "
            f"the {cutoff:g} Hz cut-off; lower the cut-off or decimate less"
        )


# ---------------------------------------------------------------------- parallel filtering
def parallel_filter(
    tau: ArrayLike,
    Y: ArrayLike,
    *,
    fs: float,
    cutoff: float,
    order: int = 5,
    runs: Sequence[slice] | None = None,
    decimate: int = 1,
    trim: float = 0.0,
    inplace: bool = False,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Apply one zero-phase low-pass to the torque and to every regressor column, then decimate and trim.

    Because the filter is linear and the same for both, ``tau = Y @ p`` implies
    ``tau_f = Y_f @ p``: filtering creates no fake effect (DIAGNOSIS.md section 3).

    Parameters
    ----------
    tau : array_like, shape (m, n)
        Joint torques (N m).
    Y : array_like, shape (m, n, p) or (m, ...)
        Regressor evaluated on the (unfiltered or lightly filtered) states; time along axis 0.
    fs : float
        Sampling frequency (Hz) of the uniform samples.
    cutoff : float
        Cut-off frequency (Hz); below ``fs / (2 decimate)``.
    order : int
        Butterworth order (default 5).
    runs : sequence of slice, optional
        Row ranges filtered separately (``Dataset.runs``).
    decimate : int
        Keep one sample in ``decimate`` after filtering.
    trim : float
        Time (s) dropped at each end of each run after filtering.
    inplace : bool
        With ``decimate=1`` and ``trim=0``, overwrite ``Y`` (a writeable, C-contiguous float64 array)
        instead of allocating a second array of its size.  Otherwise only the rows kept are allocated.

    Returns
    -------
    tau_f : ndarray, shape (k, n)
    Y_f : ndarray, shape (k, n, p)
        Rows :func:`kept_rows` ``(runs, decimate=decimate, trim_samples=ceil(trim * fs))``.
    """
    tau_arr = np.asarray(tau, dtype=np.float64)
    if inplace and not (
        isinstance(Y, np.ndarray) and Y.dtype == np.float64 and Y.flags.c_contiguous and Y.flags.writeable
    ):
        raise DataError(
            "inplace=True needs Y as a writeable, C-contiguous float64 array; "
            "pass np.ascontiguousarray(Y, dtype=float) or inplace=False"
        )
    Y_arr: NDArray[np.float64] = (
        Y if isinstance(Y, np.ndarray) and inplace else np.asarray(Y, dtype=np.float64)
    )
    if tau_arr.ndim != 2:
        raise DataError(f"tau must have shape (m, n); got {tau_arr.shape}; give one row per sample")
    m, n = tau_arr.shape
    if Y_arr.ndim < 2 or Y_arr.shape[0] != m:
        raise DataError(
            f"Y has shape {Y_arr.shape} but tau has {m} rows; Y needs shape (m, n, p) = ({m}, {n}, p)"
        )
    if Y_arr.ndim == 3 and Y_arr.shape[1] != n:
        raise DataError(f"Y has {Y_arr.shape[1]} joint rows but tau has {n} columns; build Y for {n} joints")
    sos = butter_sos(cutoff, fs, order)
    run_list = as_runs(runs, m)
    _check_decimation(cutoff, fs, decimate)
    rows = kept_rows(run_list, decimate=decimate, trim_samples=whole_samples(trim, 1.0 / fs))
    all_rows = len(rows) == m
    tau_f = np.empty((len(rows), n))
    _filter_columns(np.ascontiguousarray(tau_arr), sos, run_list, None if all_rows else rows, tau_f)
    Y2 = Y_arr.reshape(m, -1) if Y_arr.flags.c_contiguous else np.ascontiguousarray(Y_arr).reshape(m, -1)
    if inplace and all_rows:
        _filter_columns(Y2, sos, run_list, None, Y2)
        return tau_f, Y_arr
    out = np.empty((len(rows), Y2.shape[1]))
    _filter_columns(Y2, sos, run_list, None if all_rows else rows, out)
    return tau_f, out.reshape((len(rows), *Y_arr.shape[1:]))


# ---------------------------------------------------------------------- the whole path
def _reference(steps: list[str]) -> str:
    if not steps:
        return "raw"
    if len(steps) == 1:
        return steps[0]
    return ", ".join(steps[:-1]) + " and " + steps[-1]


def _check_filter(cutoff: float | None, fs: float, order: int, decimate: int) -> None:
    """Check the filter settings of :func:`preprocess` before any work (warn, to its caller, of aliasing)."""
    if cutoff is not None:
        butter_sos(cutoff, fs, order)  # checks cutoff and order before any work
        _check_decimation(cutoff, fs, decimate)
    elif decimate > 1:
        warnings.warn(
            f"decimating by {decimate} without a low-pass filter aliases everything above "
            f"{fs / (2 * decimate):g} Hz; pass a cutoff",
            DataWarning,
            stacklevel=3,
        )


def _derivatives(
    ds: Dataset,
    q: NDArray[np.float64],
    filt: Callable[[NDArray[np.float64]], NDArray[np.float64]],
    *,
    filtered: bool,
    velocity: str,
) -> tuple[NDArray[np.float64], NDArray[np.float64], str, str]:
    """``dq`` and ``ddq`` of :func:`preprocess` (step 3) from the filtered ``q`` (``filt`` filters a
    measured signal), and what each is (its ``meta["preprocess"]`` entries)."""
    step, runs = ds.dt, ds.runs
    if ds.dq is not None and velocity == "measured":
        dq = filt(ds.dq)
        dq_note = "measured" + (", filtered" if filtered else "")
        derived_from_q = False
    else:
        dq = central_difference(q, step, derivative=1, runs=runs)
        dq_note = "central difference of " + ("filtered q" if filtered else "q")
        derived_from_q = True
    if ds.ddq is not None and not derived_from_q:
        ddq = filt(ds.ddq)
        ddq_note = "measured" + (", filtered" if filtered else "")
    elif derived_from_q:
        ddq = central_difference(q, step, derivative=2, runs=runs)
        ddq_note = "second difference of " + ("filtered q" if filtered else "q")
    else:
        ddq = central_difference(dq, step, derivative=1, runs=runs)
        ddq_note = "central difference of dq"
    return dq, ddq, dq_note, ddq_note


def _preprocessed_meta(
    ds: Dataset, info: dict[str, Any], *, resampled: bool, decimate: int, trim_s: float
) -> dict[str, Any]:
    """``ds.meta`` with the runs' starts, ``meta["preprocess"] = info`` and the ``meta["reference"]``
    that says how the torque was treated."""
    steps = []
    if resampled:
        steps.append("resampled")
    if info["torque_filtered"]:
        steps.append("filtered")
    if decimate > 1:
        steps.append("decimated")
    if trim_s > 0:
        steps.append("trimmed")
    runs = ds.runs
    meta = {key: value for key, value in ds.meta.items() if key != "run_starts"}
    if len(runs) > 1:
        meta["run_starts"] = [run.start for run in runs]
    meta["preprocess"] = info
    meta["reference"] = _reference(steps)
    return meta


def preprocess(
    ds: Dataset,
    *,
    cutoff: float | None,
    order: int = 5,
    decimate: int = 1,
    trim: float | None = None,
    resample_method: ResampleMethod = "linear",
    dt: float | None = None,
    velocity: Literal["measured", "differentiate"] = "measured",
    filter_torque: bool = True,
) -> Dataset:
    """Resample (if irregular), low-pass, differentiate, decimate and trim a dataset.

    Steps, each run by run:

    1. if the stamps are irregular (or ``dt`` is given): :func:`resample` onto a uniform grid;
    2. zero-phase Butterworth low-pass of ``q``, ``dq`` and ``ddq`` when present, and of ``tau`` (unless
       ``filter_torque=False``);
    3. missing derivatives by :func:`central_difference`: ``dq`` from the filtered ``q`` (also when
       ``velocity="differentiate"``), ``ddq`` from the filtered measured ``dq`` if there is one, else as
       the second difference of ``q``;
    4. trim ``trim`` seconds at both ends of each run, then keep one sample in ``decimate``.

    Parameters
    ----------
    ds : Dataset
        Raw data.
    cutoff : float or None
        Low-pass cut-off (Hz); None skips filtering (then ``decimate > 1`` aliases and warns).
    order : int
        Butterworth order (default 5).
    decimate : int
        Decimation factor after filtering; the cut-off must lie below the new Nyquist frequency.
    trim : float, optional
        Time (s) cut at each end of each run.  Default ``2 / cutoff`` (the filter's transient; 0 without
        a filter).
    resample_method : {"linear", "cubic"}
        Interpolation used when resampling.
    dt : float, optional
        Resample onto this step (s) even if the stamps are uniform.
    velocity : {"measured", "differentiate"}
        Keep the measured ``dq`` (filtered) or replace it by the derivative of the filtered ``q``.
    filter_torque : bool
        Filter ``tau`` too (default).  Set False to leave it for :func:`parallel_filter`.

    Returns
    -------
    Dataset
        Uniform data with ``dq`` and ``ddq``.  ``meta["preprocess"]`` records the settings and what each
        signal is; ``meta["reference"]`` says how the torque was treated (``"raw"``,
        ``"filtered and trimmed"``, ``"resampled, filtered, decimated and trimmed"``, ...).
    """
    if velocity not in ("measured", "differentiate"):
        raise DataError(f"velocity must be 'measured' or 'differentiate'; got {velocity!r}")
    resampled = dt is not None or not ds.is_uniform
    if resampled:
        ds = resample(ds, dt=dt, method=resample_method)
    step = ds.dt
    fs = 1.0 / step
    _check_filter(cutoff, fs, order, decimate)
    trim_s = (2.0 / cutoff if cutoff is not None else 0.0) if trim is None else float(trim)
    runs = ds.runs

    def filt(a: NDArray[np.float64]) -> NDArray[np.float64]:
        return a.copy() if cutoff is None else lowpass(a, fs=fs, cutoff=cutoff, order=order, runs=runs)

    q = filt(ds.q)
    tau = filt(ds.tau) if filter_torque else ds.tau.copy()
    info: dict[str, Any] = {
        "cutoff_hz": cutoff,
        "order": order if cutoff is not None else None,
        "fs_hz": fs,
        "decimate": int(decimate),
        "trim_s": trim_s,
        "resampled": resample_method if resampled else None,
        "torque_filtered": bool(filter_torque and cutoff is not None),
    }
    dq, ddq, info["dq"], info["ddq"] = _derivatives(
        ds, q, filt, filtered=cutoff is not None, velocity=velocity
    )
    rows = kept_rows(runs, decimate=decimate, trim_samples=whole_samples(trim_s, step))
    meta = _preprocessed_meta(ds, info, resampled=resampled, decimate=decimate, trim_s=trim_s)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)  # already checked on ds
        full = Dataset(ds.t, q, tau, dq=dq, ddq=ddq, meta=meta)
    return full if len(rows) == full.m else full.select_rows(rows)  # every row kept: no copy of it all
