"""The zero-phase Butterworth low-pass: its design and the filtering of signals laid out in rows.

:func:`butter_sos` designs the filter (cached per cut-off, rate and order), :func:`filtfilt_rows` runs
it forward and backward along each row exactly as :func:`scipy.signal.sosfiltfilt` does,
:func:`filter_padding` and :func:`filter_order` describe it for the checks before filtering.  The
filtering of data run by run (:func:`dynid.data.preprocess.lowpass`,
:func:`dynid.data.preprocess.parallel_filter`) builds on these.  Split out of
:mod:`dynid.data.preprocess`, which re-exports its names.
"""

from __future__ import annotations

import functools

import numpy as np
from numpy.typing import NDArray
from scipy.signal import butter, sosfilt, sosfilt_zi

from dynid.exceptions import DataError

__all__ = ["butter_sos", "filter_order", "filter_padding", "filtfilt_rows"]


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
