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
"""

from __future__ import annotations

import functools
import itertools
import warnings
from collections.abc import Sequence
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import CubicSpline
from scipy.signal import butter, sosfilt, sosfilt_zi

from dynid.data.dataset import Dataset
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
    "kept_rows",
    "lowpass",
    "parallel_filter",
    "preprocess",
    "resample",
    "resample_uniform",
    "trim",
]

ResampleMethod = Literal["linear", "cubic"]
_METHODS = ("linear", "cubic")
#: Number of float64 values filtered at once (about 32 MB); bounds the filter's temporary memory.
_CHUNK_VALUES = 4_000_000


# ---------------------------------------------------------------------- cut-off from the data
BANDWIDTH_FACTOR = 10.0
"""The cut-off :func:`choose_cutoff` chooses is at least this many times the motion's bandwidth."""
SIGNAL_DB = 30.0
"""How far (dB) above its high-frequency noise floor a spectrum counts as signal in :func:`choose_cutoff`."""


def _signal_edge(x: NDArray[np.float64], fs: float) -> tuple[float, float]:
    """Median over columns of the highest frequency (Hz) at which the spectrum of ``x`` stands
    :data:`SIGNAL_DB` above its noise floor (the median of the upper half of the band), and the
    frequency below which 99.9 % of its power lies."""
    from scipy.signal import welch

    m = len(x)
    nper = int(max(16, min(m // 4, round(2.0 * fs))))
    f, P = welch(x, fs=fs, nperseg=nper, axis=0, detrend="linear")
    floor = np.median(P[f >= fs / 4], axis=0)
    edges, bands = [], []
    for j in range(P.shape[1]):
        total = P[1:, j].sum()
        if not np.isfinite(total) or total <= 0:
            continue  # a still joint says nothing
        cum = np.cumsum(P[1:, j]) / total
        bands.append(float(f[1:][np.searchsorted(cum, 0.999)]))
        above = np.flatnonzero(P[1:, j] > 10 ** (SIGNAL_DB / 10) * max(floor[j], 1e-300))
        edges.append(float(f[1:][above.max()]) if len(above) else float(f[1]))
    if not edges:
        return float("nan"), float("nan")
    return float(np.median(edges)), float(np.max(bands))


def choose_cutoff(ds: Dataset, *, upper: float) -> tuple[float, dict[str, Any]]:
    """A low-pass cut-off (Hz) for torque and regressor, chosen from the recording itself.

    The filter should pass every frequency at which the data carry information and stop the rest:

    - the motion: the highest frequency at which the spectrum of ``q`` stands :data:`SIGNAL_DB` above
      its own noise floor (encoder noise, quantisation), median over the joints; above it the
      differentiated ``ddq`` is noise;
    - the torque: the same edge of the torque's spectrum; vibration and drive noise that no motion
      explains sit below it only where they are stronger than the motion's torque.

    The cut-off is the higher of the two edges (nothing that either signal carries is cut), at least
    :data:`BANDWIDTH_FACTOR` times the motion's bandwidth (99.9 % of the power of ``q``) and at most
    ``upper``.  The floor keeps the harmonics of the nonlinear dynamics (products of sines of the
    angles, the sign switch of Coulomb friction), which separate friction from the link columns.

    Measured on the real recordings (identified on the first part, scored on the rest, see
    ``benchmarks/real_robots_benchmark.py``): the Panda's q stands 30 dB above its floor up to 4.5 Hz,
    its torque up to 5 Hz, its bandwidth is 1.5 Hz; the TX40's q up to 52 Hz.  On the Panda, cut-offs
    of 6-12 Hz gave the lowest error of the whole model, but its physical layers alone then lost up to
    36 % against OLS with linear friction on some joints; from 15 Hz (ten times the bandwidth) they
    did not (the TX40: best from 40 Hz, both ways).

    Parameters
    ----------
    ds : Dataset
        The recording (uniform stamps; resample first otherwise).
    upper : float
        Largest cut-off allowed (Hz).

    Returns
    -------
    cutoff : float
        The cut-off (Hz).
    details : dict
        ``motion_hz`` (edge of q), ``torque_hz`` (edge of tau), ``bandwidth_hz`` (99.9 % of q's power),
        ``rule`` (one sentence).
    """
    fs = 1.0 / ds.dt
    motion, bandwidth = _signal_edge(np.asarray(ds.q, dtype=np.float64), fs)
    torque, _ = _signal_edge(np.asarray(ds.tau, dtype=np.float64), fs)
    if not np.isfinite(motion):
        return float(upper), {
            "motion_hz": None,
            "torque_hz": None,
            "bandwidth_hz": None,
            "rule": f"no joint moves: the largest cut-off, {upper:g} Hz",
        }
    chosen = max(motion, torque if np.isfinite(torque) else motion, BANDWIDTH_FACTOR * bandwidth)
    cutoff = float(min(chosen, upper))
    rule = (
        f"from the data: q carries signal up to {motion:.3g} Hz, the torque up to {torque:.3g} Hz "
        f"(30 dB above their noise floors), the motion's bandwidth is {bandwidth:.3g} Hz (the cut-off is at "
        f"least {BANDWIDTH_FACTOR:g} times that)" + (f"; capped at {upper:g} Hz" if chosen > upper else "")
    )
    return cutoff, {
        "motion_hz": motion,
        "torque_hz": torque if np.isfinite(torque) else None,
        "bandwidth_hz": bandwidth,
        "rule": rule,
    }


# ---------------------------------------------------------------------- resampling
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


# ---------------------------------------------------------------------- filtering
def butter_sos(cutoff: float, fs: float, order: int = 5) -> NDArray[np.float64]:
    """Butterworth low-pass in second-order sections.

    Parameters
    ----------
    cutoff : float
        Cut-off frequency (Hz), ``0 < cutoff < fs / 2``.
    fs : float
        Sampling frequency (Hz).
    order : int
        Filter order (>= 1).  :func:`scipy.signal.sosfiltfilt` runs it forward and backward, so the
        magnitude response is squared and the phase is zero.

    Returns
    -------
    ndarray, shape (ceil(order / 2), 6)
    """
    if not (isinstance(order, int | np.integer) and order >= 1):
        raise DataError(f"order must be a positive integer; got {order!r}; the default is 5")
    if not (np.isfinite(fs) and fs > 0):
        raise DataError(f"fs must be a positive sampling frequency (Hz); got {fs!r}; pass fs=1/ds.dt")
    if not (np.isfinite(cutoff) and 0 < cutoff < fs / 2):
        raise DataError(
            f"cutoff must lie between 0 and the Nyquist frequency {fs / 2:g} Hz of data sampled at "
            f"{fs:g} Hz; got {cutoff!r} Hz; choose a lower cut-off"
        )
    return _butter_sos(float(cutoff), float(fs), int(order)).copy()


@functools.lru_cache(maxsize=64)
def _butter_sos(cutoff: float, fs: float, order: int) -> NDArray[np.float64]:
    """The design of :func:`butter_sos`, computed once per (cut-off, rate, order).

    A default identification filters about a thousand times with the same filter (the friction shape
    searches filter their candidates' columns); designing it each time was 9 % of the run.
    """
    sos = np.asarray(butter(order, cutoff, btype="low", fs=fs, output="sos"), dtype=np.float64)
    sos.setflags(write=False)
    return sos


@functools.lru_cache(maxsize=64)
def _filtfilt_setup(key: bytes, shape: tuple[int, int]) -> tuple[int, NDArray[np.float64]]:
    """(edge, zi) of :func:`scipy.signal.sosfiltfilt` for the sections ``key`` (its bytes), once per filter.

    ``edge`` is the odd extension it pads each end with by default, ``zi`` (n_sections, 2) its
    steady-state initial conditions (:func:`scipy.signal.sosfilt_zi`, a linear solve per section:
    recomputed at every call it was a tenth of the filtering time of a default identification).
    """
    sos = np.frombuffer(key, dtype=np.float64).reshape(shape)
    ntaps = 2 * len(sos) + 1 - min(int((sos[:, 2] == 0).sum()), int((sos[:, 5] == 0).sum()))
    zi = np.ascontiguousarray(sosfilt_zi(sos), dtype=np.float64)
    zi.setflags(write=False)
    return 3 * ntaps, zi


def filtfilt_rows(sos: NDArray[np.float64], x: NDArray[np.float64]) -> NDArray[np.float64]:
    """Zero-phase filter of each row of ``x`` (k, L): :func:`scipy.signal.sosfiltfilt` along the last axis.

    The same arithmetic as ``sosfiltfilt(sos, x, axis=-1)`` with its default odd padding, so the same
    values to the bit; its setup (padding length, initial conditions) is computed once per filter and
    time runs along contiguous memory (no transposed copies).

    Parameters
    ----------
    sos : ndarray, shape (n_sections, 6)
        Second-order sections (:func:`butter_sos`).
    x : ndarray, shape (k, L)
        Signals, one per row, time along axis 1; ``L`` must exceed the padding (``3 (2 n_sections + 1)``
        at most).

    Returns
    -------
    ndarray, shape (k, L)
        The filtered signals (a view of a new array, time reversed twice).
    """
    sos = np.ascontiguousarray(sos, dtype=np.float64)
    edge, zi = _filtfilt_setup(sos.tobytes(), sos.shape)
    k, length = x.shape
    if length <= edge:
        raise DataError(
            f"{length} samples are too short for an order-{filter_order(sos)} zero-phase filter (it pads with {edge}); "
            "record longer"
        )
    ext = np.empty((k, length + 2 * edge))
    ext[:, edge : edge + length] = x
    if edge > 0:  # odd extension at both ends (scipy.signal's odd_ext)
        ext[:, :edge] = 2 * x[:, 0:1] - x[:, edge:0:-1]
        ext[:, edge + length :] = 2 * x[:, -1:] - x[:, -2 : -(edge + 2) : -1]
    y = sosfilt(sos, ext, axis=-1, zi=zi[:, None, :] * ext[None, :, 0:1])[0]
    y = sosfilt(sos, y[:, ::-1], axis=-1, zi=zi[:, None, :] * y[None, :, -1:])[0][:, ::-1]
    return y[:, edge : edge + length] if edge > 0 else y


def filter_padding(sos: NDArray[np.float64]) -> int:
    """Samples :func:`scipy.signal.sosfiltfilt` pads each end with by default: a run must be longer.

    The ``edge`` of :func:`filtfilt_rows`, one rule for every check before filtering (an odd order's
    first-order section pads less than ``3 (2 n_sections + 1)``: 18 samples at order 5, not 21).

    Parameters
    ----------
    sos : ndarray, shape (n_sections, 6)
        Second-order sections (:func:`butter_sos`).
    """
    sos = np.ascontiguousarray(sos, dtype=np.float64)
    return _filtfilt_setup(sos.tobytes(), sos.shape)[0]


def filter_order(sos: NDArray[np.float64]) -> int:
    """Order of a filter in second-order sections (its poles: an odd order's last section has one).

    Parameters
    ----------
    sos : ndarray, shape (n_sections, 6)
        Second-order sections (:func:`butter_sos`).
    """
    sos = np.asarray(sos, dtype=np.float64)
    return int(np.sum(sos[:, 4] != 0) + np.sum(sos[:, 5] != 0))


def _as_runs(runs: Sequence[slice] | None, m: int) -> list[slice]:
    if runs is None:
        return [slice(0, m)]
    out = []
    for run in runs:
        start, stop, step = run.indices(m)
        if step != 1 or stop <= start:
            raise DataError(f"runs must be contiguous, non-empty row slices; got {run}; use Dataset.runs")
        out.append(slice(start, stop))
    return out


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
    _filter_columns(y2, sos, _as_runs(runs, arr.shape[0]), None, out2)
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
    for r, run in enumerate(_as_runs(runs, len(arr))):
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


# ---------------------------------------------------------------------- row selection
def kept_rows(
    runs: Sequence[slice],
    *,
    decimate: int = 1,
    trim_samples: int = 0,
) -> NDArray[np.intp]:
    """Row indices kept by trimming each run's ends and then taking every ``decimate``-th sample.

    :func:`preprocess` and :func:`parallel_filter` both select rows with this function, so data and
    regressor processed with the same settings stay aligned row for row.

    Parameters
    ----------
    runs : sequence of slice
        Row ranges (``Dataset.runs``).
    decimate : int
        Keep one sample in ``decimate`` (counted from each run's first kept sample).
    trim_samples : int
        Samples dropped at each end of each run.

    Returns
    -------
    ndarray of int, shape (k,)
        A run too short for the trim (a piece after a gap in the stamps) is left out with a
        :class:`DataWarning`; a :class:`DataError` when no run is long enough.
    """
    if not (isinstance(decimate, int | np.integer) and decimate >= 1):
        raise DataError(f"decimate must be a positive integer; got {decimate!r}; 1 keeps every sample")
    if trim_samples < 0:
        raise DataError(f"trim must not be negative; got {trim_samples} samples; pass 0 to keep the ends")
    pieces, short = [], []
    for r, run in enumerate(runs):
        lo, hi = run.start + trim_samples, run.stop - trim_samples
        if hi - lo < 2:
            short.append((r, run, max(hi - lo, 0)))
            continue
        pieces.append(np.arange(lo, hi, int(decimate)))
    if not pieces:
        r, run, left = short[0]
        raise DataError(
            f"trimming {trim_samples} samples from both ends leaves {left} of run {r} ({run.stop - run.start} "
            f"samples); give a recording of at least {2 * trim_samples + 2} samples a run (the trim cuts the "
            "low-pass filter's transient; calling preprocess(), give a smaller trim)"
        )
    if short:
        listed = ", ".join(f"{r} ({run.stop - run.start} samples)" for r, run, _ in short)
        warnings.warn(
            f"run{'s' if len(short) > 1 else ''} {listed} {'are' if len(short) > 1 else 'is'} too short for "
            f"the {trim_samples} samples trimmed at both ends (the filter's transient) and left out",
            DataWarning,
            stacklevel=2,
        )
    return np.concatenate(pieces).astype(np.intp)


def decimate(ds: Dataset, factor: int) -> Dataset:
    """Keep every ``factor``-th sample of each run (filter first: this does not low-pass).

    Parameters
    ----------
    ds : Dataset
        Uniform data, already low-passed below ``1 / (2 factor ds.dt)`` Hz.
    factor : int
        Decimation factor (>= 1).

    Returns
    -------
    Dataset
        With step ``factor * ds.dt``; ``meta["decimated"]`` multiplied by ``factor``.
    """
    out = ds.select_rows(kept_rows(ds.runs, decimate=factor))
    out.meta["decimated"] = int(ds.meta.get("decimated", 1)) * int(factor)
    return out


def trim(ds: Dataset, seconds: float) -> Dataset:
    """Drop ``seconds`` (s) at both ends of each run (where a filter's start-up transient lives).

    Parameters
    ----------
    ds : Dataset
        Data.
    seconds : float
        Time cut from each end of each run (s, >= 0).

    Returns
    -------
    Dataset
        With ``meta["trimmed_s"]`` increased by ``seconds``.
    """
    if not (np.isfinite(seconds) and seconds >= 0):
        raise DataError(f"trim must be a non-negative number of seconds; got {seconds!r}; pass e.g. 0.1")
    out = ds.select_rows(kept_rows(ds.runs, trim_samples=_samples(seconds, ds.dt)))
    out.meta["trimmed_s"] = float(ds.meta.get("trimmed_s", 0.0)) + float(seconds)
    return out


def _samples(seconds: float, dt: float) -> int:
    """Whole samples covering ``seconds`` (s) at step ``dt`` (s)."""
    return int(np.ceil(seconds / dt - 1e-9))


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
    run_list = _as_runs(runs, m)
    _check_decimation(cutoff, fs, decimate)
    rows = kept_rows(run_list, decimate=decimate, trim_samples=_samples(trim, 1.0 / fs))
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
    if cutoff is not None:
        butter_sos(cutoff, fs, order)  # checks cutoff and order before any work
        _check_decimation(cutoff, fs, decimate)
    elif decimate > 1:
        warnings.warn(
            f"decimating by {decimate} without a low-pass filter aliases everything above "
            f"{fs / (2 * decimate):g} Hz; pass a cutoff",
            DataWarning,
            stacklevel=2,
        )
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
    if ds.dq is not None and velocity == "measured":
        dq = filt(ds.dq)
        info["dq"] = "measured" + (", filtered" if cutoff is not None else "")
        derived_from_q = False
    else:
        dq = central_difference(q, step, derivative=1, runs=runs)
        info["dq"] = "central difference of " + ("filtered q" if cutoff is not None else "q")
        derived_from_q = True
    if ds.ddq is not None and not derived_from_q:
        ddq = filt(ds.ddq)
        info["ddq"] = "measured" + (", filtered" if cutoff is not None else "")
    elif derived_from_q:
        ddq = central_difference(q, step, derivative=2, runs=runs)
        info["ddq"] = "second difference of " + ("filtered q" if cutoff is not None else "q")
    else:
        ddq = central_difference(dq, step, derivative=1, runs=runs)
        info["ddq"] = "central difference of dq"

    rows = kept_rows(runs, decimate=decimate, trim_samples=_samples(trim_s, step))
    steps = []
    if resampled:
        steps.append("resampled")
    if info["torque_filtered"]:
        steps.append("filtered")
    if decimate > 1:
        steps.append("decimated")
    if trim_s > 0:
        steps.append("trimmed")
    meta = {key: value for key, value in ds.meta.items() if key != "run_starts"}
    if len(runs) > 1:
        meta["run_starts"] = [run.start for run in runs]
    meta["preprocess"] = info
    meta["reference"] = _reference(steps)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)  # already checked on ds
        full = Dataset(ds.t, q, tau, dq=dq, ddq=ddq, meta=meta)
    return full if len(rows) == full.m else full.select_rows(rows)  # every row kept: no copy of it all
