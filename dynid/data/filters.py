"""The zero-phase Butterworth low-pass: its design and the filtering of signals laid out in rows.

:func:`butter_sos` designs the filter (cached per cut-off, rate and order), :func:`filtfilt_rows` runs
it forward and backward along each row exactly as :func:`scipy.signal.sosfiltfilt` does (on
:mod:`dynid.data.dsp`, which spares every command scipy.signal's import),
:func:`filter_padding` and :func:`filter_order` describe it for the checks before filtering.  The
filtering of data run by run (:func:`dynid.data.preprocess.lowpass`,
:func:`dynid.data.preprocess.parallel_filter`) builds on these.  Split out of
:mod:`dynid.data.preprocess`, which re-exports its names.
"""

from __future__ import annotations

import functools

import numpy as np
from numpy.typing import NDArray

from dynid.data import dsp
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
    sos = dsp.butter_lowpass(order, cutoff, fs)
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
    zi = dsp.sosfilt_zi(sos)
    zi.setflags(write=False)
    return 3 * ntaps, zi


def filtfilt_rows(sos: NDArray[np.float64], x: NDArray[np.float64], padded: bool = True) -> NDArray[np.float64]:
    """Zero-phase filter of each row of ``x`` (k, L): :func:`scipy.signal.sosfiltfilt` along the last axis.

    ``sosfiltfilt(sos, x, axis=-1)`` with its default odd padding (``padded=False``: ``padlen=0``), the
    same arithmetic, so the same values to the bit (:func:`dynid.data.dsp.sosfilt_inplace`); its setup
    (padding length, initial conditions) is computed once per filter, and the signals are filtered
    side by side, time-major, without reversed copies.

    Parameters
    ----------
    sos : ndarray, shape (n_sections, 6)
        Second-order sections (:func:`butter_sos`).
    x : ndarray, shape (k, L)
        Signals, one per row, time along axis 1; ``L`` must exceed the padding (``3 (2 n_sections + 1)``
        at most).
    padded : bool
        Pad each end by odd extension as scipy does by default; False filters the signal as it is.

    Returns
    -------
    ndarray, shape (k, L)
        The filtered signals (a transposed view of a new time-major array).
    """
    sos = np.ascontiguousarray(sos, dtype=np.float64)
    edge, zi = _filtfilt_setup(sos.tobytes(), sos.shape)
    edge = edge if padded else 0
    k, length = x.shape
    if length <= edge:
        raise DataError(
            f"{length} samples are too short for an order-{filter_order(sos)} zero-phase filter (it pads with {edge}); "
            "record longer"
        )
    ext = np.empty((length + 2 * edge, k))  # time-major: the signals of one sample side by side
    ext[edge : edge + length] = x.T
    if edge > 0:  # odd extension at both ends (scipy.signal's odd_ext)
        ext[:edge] = 2 * ext[edge] - ext[2 * edge : edge : -1]
        ext[edge + length :] = 2 * ext[edge + length - 1] - ext[edge + length - 2 : length - 2 : -1]
    dsp.sosfilt_inplace(sos, ext, zi[:, :, None] * ext[0])
    dsp.sosfilt_inplace(sos, ext, zi[:, :, None] * ext[-1], reverse=True)
    return ext[edge : edge + length].T


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
