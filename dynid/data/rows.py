"""Rows of a recording run by run: its runs as row slices, and the rows that trimming and decimation keep.

:func:`kept_rows` is the one rule by which :func:`dynid.data.preprocess.preprocess` and
:func:`dynid.data.preprocess.parallel_filter` select rows, so data and regressor processed with the
same settings stay aligned row for row; :func:`decimate` and :func:`trim` apply it to a dataset.
Split out of :mod:`dynid.data.preprocess`, which re-exports its public names.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from dynid.data.dataset import Dataset
from dynid.exceptions import DataError, DataWarning

__all__ = ["as_runs", "decimate", "kept_rows", "trim", "whole_samples"]


def as_runs(runs: Sequence[slice] | None, m: int) -> list[slice]:
    """The row ranges ``runs`` of ``m`` rows as contiguous, non-empty slices (None: one run of all rows).

    Raises
    ------
    DataError
        A slice with a step or without rows.
    """
    if runs is None:
        return [slice(0, m)]
    out = []
    for run in runs:
        start, stop, step = run.indices(m)
        if step != 1 or stop <= start:
            raise DataError(f"runs must be contiguous, non-empty row slices; got {run}; use Dataset.runs")
        out.append(slice(start, stop))
    return out


def whole_samples(seconds: float, dt: float) -> int:
    """Whole samples covering ``seconds`` (s) at step ``dt`` (s)."""
    return int(np.ceil(seconds / dt - 1e-9))


# ---------------------------------------------------------------------- row selection
def kept_rows(
    runs: Sequence[slice],
    *,
    decimate: int = 1,
    trim_samples: int = 0,
) -> NDArray[np.intp]:
    """Row indices kept by trimming each run's ends and then taking every ``decimate``-th sample.

    :func:`~dynid.data.preprocess.preprocess` and :func:`~dynid.data.preprocess.parallel_filter` both
    select rows with this function, so data and regressor processed with the same settings stay aligned row for row.

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
    out = ds.select_rows(kept_rows(ds.runs, trim_samples=whole_samples(seconds, ds.dt)))
    out.meta["trimmed_s"] = float(ds.meta.get("trimmed_s", 0.0)) + float(seconds)
    return out
