"""The least-squares machinery of the friction fits (:mod:`dynid.identify.friction`).

Bounded linear least squares compressed by QR first (:func:`bounded_lsq`, :func:`bounded_solve`,
:func:`compress_rows`), the search of a shape parameter over candidates refined by golden section
(:func:`shape_search`, :func:`near_candidates`, :func:`sample_stride`), the checks of a joint's inputs
(:func:`checked_inputs`) and the filtering of a model's columns like the torque (:class:`Sampling`, the
parallel filtering of :mod:`dynid.identify.friction`'s docstring).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynid.data.preprocess import filtfilt_rows
from dynid.exceptions import DataError
from dynid.identify._qr import r_factor

__all__ = [
    "Sampling",
    "bounded_lsq",
    "bounded_solve",
    "checked_inputs",
    "compress_rows",
    "near_candidates",
    "sample_stride",
    "shape_search",
]

_SEARCH_SAMPLES = 10_000  # samples used in shape-parameter searches (evenly strided)
_SEARCH_WINDOW = 10_000  # full-rate samples filtered per candidate in a search on filtered data
_GOLDEN_STEPS = 20  # at most, golden-section refinements of a threshold search
#: A threshold search stops when its bracket spans less than this relative width and its two inner
#: costs agree to :data:`_SHAPE_FTOL`: a threshold known to 0.5 %, far inside its own uncertainty on
#: measured data, whose cost is flat there (the bracket between the best candidate's neighbours spans
#: 30-70 %; 20 steps, the earlier fixed count, narrowed it to 0.002 %, each step one more filtered fit).
#: A noise-free cost, whose minimum is sharp, is searched the 20 steps.
_SHAPE_RTOL = 0.005
_SHAPE_FTOL = 1e-6


def _check_pair(
    dq: ArrayLike, F: ArrayLike, need: int, name: str
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    dq = np.asarray(dq, dtype=np.float64).ravel()
    F = np.asarray(F, dtype=np.float64).ravel()
    if dq.shape != F.shape:
        raise DataError(
            f"dq has {dq.size} values but F has {F.size}; give one friction torque (N m) per velocity sample"
        )
    for label, a in (("dq", dq), ("F", F)):
        if not np.all(np.isfinite(a)):
            raise DataError(
                f"{label} holds a non-finite value at sample {int(np.argmax(~np.isfinite(a)))}; drop or "
                "interpolate that sample"
            )
    if dq.size < need:
        raise DataError(
            f"the {name} friction model needs at least {need} samples; got {dq.size}: record longer"
        )
    return dq, F


def _compress(
    A: NDArray[np.float64], b: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """(R, Q^T b, ||b||^2 - ||Q^T b||^2): ``||A x - b||^2 = ||R x - Q^T b||^2 + rest``."""
    k = A.shape[1]
    Ab = np.empty((k + 1, len(b)))  # [A b] transposed: a Fortran-ordered [A b] for the QR, no copy
    Ab[:k] = A.T
    Ab[k] = b
    return compress_rows(Ab)


def compress_rows(Ab: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """:func:`_compress` of ``[A b]`` given transposed, ``Ab`` (k + 1, m), C order (overwritten)."""
    k = Ab.shape[0] - 1
    R = r_factor(Ab.T, overwrite=True)
    if R.shape[0] < k + 1:
        R = np.vstack([R, np.zeros((k + 1 - R.shape[0], k + 1))])
    return R[:k, :k], R[:k, k], float(R[k, k] ** 2)


def sample_stride(m: int, limit: int = _SEARCH_SAMPLES) -> slice:
    """Every k-th of ``m`` samples, k the least that keeps at most ``limit`` (the thinning of the searches)."""
    return slice(None, None, max(1, -(-m // limit)))


class Sampling:
    """How one joint's model columns at full rate become comparable with the filtered residual.

    ``full(A)``: filter the full-rate columns ``A`` (M, k) like the torque, take the kept rows (m, k).
    ``search_into(At_window, out)``: the same on the search window only (columns given transposed, on
    ``window`` rows), writing the kept rows inside it away from its edges, to compare with
    ``F[search_rows]``.
    """

    def __init__(self, prepared: Any, window: int = _SEARCH_WINDOW) -> None:
        self.prepared = prepared
        rows = np.asarray(prepared.rows)
        runs = prepared.runs
        longest = max(runs, key=lambda r: r.stop - r.start)
        length = longest.stop - longest.start
        start = longest.start + max(0, (length - window) // 2)
        stop = min(longest.stop, start + window)
        self.window = slice(start, stop)
        edge = (
            int(np.ceil(5.0 * prepared.fs / prepared.settings["cutoff_hz"]))
            if prepared.parallel_filter
            else 0
        )
        inside = (rows >= start + edge) & (rows < stop - edge)
        if inside.sum() < 20:  # a short record: search on every kept row
            self.window = None
            inside = np.ones(len(rows), dtype=bool)
        self.search_rows = np.flatnonzero(inside)
        self._local = rows[inside] - (start if self.window is not None else 0)
        self._sos = prepared.sos  # None without the parallel filter

    def full(self, A: NDArray[np.float64]) -> NDArray[np.float64]:
        return self.prepared.filter(A)[self.prepared.rows]

    def search_into(self, At: NDArray[np.float64], out: NDArray[np.float64]) -> None:
        """``search`` of columns given transposed, ``At`` (k, len(window)), written into ``out`` (k, m_s).

        The window's columns filtered as :func:`dynid.data.preprocess.lowpass` filters them (one run,
        the same arithmetic), in the transposed layout the QR of the search takes without a copy.
        """
        if self.window is None:
            out[:] = self.full(At.T).T
        elif not self.prepared.parallel_filter:
            out[:] = At[:, self._local]
        else:
            out[:] = filtfilt_rows(self._sos, At)[:, self._local]

    def window_of(self, dq: NDArray[np.float64]) -> NDArray[np.float64]:
        return dq if self.window is None else dq[self.window]


def bounded_lsq(
    A: NDArray[np.float64], F: NDArray[np.float64], bounds: tuple[float, ...]
) -> tuple[NDArray[np.float64], float]:
    """``min ||A c - F||^2`` with ``c >= bounds`` (0 or -inf each), compressed by QR first: (c, rss).

    Parameters
    ----------
    A : ndarray, shape (m, k)
        Columns.
    F : ndarray, shape (m,)
        Target.
    bounds : tuple of float, length k
        Lower bound of each coefficient: 0 or -inf.

    Returns
    -------
    c : ndarray, shape (k,)
        Coefficients.
    rss : float
        Residual sum of squares at ``c``.
    """
    return bounded_solve(*_compress(A, F), bounds)


def bounded_solve(
    R: NDArray[np.float64], qtb: NDArray[np.float64], rest: float, bounds: tuple[float, ...]
) -> tuple[NDArray[np.float64], float]:
    """:func:`bounded_lsq` on the compressed problem ``(R, Q^T b, rest)`` of :func:`_compress`."""
    from scipy.optimize import lsq_linear, nnls  # here: a linear friction pays no scipy.optimize import

    lb = np.asarray(bounds, dtype=np.float64)
    if np.all(lb == 0):
        coef, res = nnls(R, qtb, maxiter=50 * R.shape[1])
        return coef, float(res**2) + rest
    if np.all(np.isinf(lb)):
        coef = np.linalg.lstsq(R, qtb, rcond=None)[0]
    else:
        coef = lsq_linear(R, qtb, bounds=(lb, np.inf), method="bvls").x
    return coef, float(np.sum((R @ coef - qtb) ** 2)) + rest


def checked_inputs(
    dq: ArrayLike, F: ArrayLike, sampling: Sampling | None, need: int, name: str
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Checked (dq, F, dq at the samples of F): dq is at full rate when ``sampling`` is given."""
    if sampling is None:
        dq, F = _check_pair(dq, F, need, name)
        return dq, F, dq
    dq = np.asarray(dq, dtype=np.float64).ravel()
    F = np.asarray(F, dtype=np.float64).ravel()
    rows = sampling.prepared.rows
    if dq.size != len(sampling.prepared.t) or F.size != len(rows):
        raise DataError(
            f"with prepared data, dq must be at full rate ({len(sampling.prepared.t)} samples, got {dq.size}) "
            f"and F at the kept rows ({len(rows)}, got {F.size})"
        )
    dq_k, F = _check_pair(dq[rows], F, need, name)
    if not np.all(np.isfinite(dq)):
        raise DataError("dq holds a non-finite value; drop or interpolate that sample")
    return dq, F, dq_k


def near_candidates(value: float, lo: float, hi: float) -> NDArray[np.float64]:
    """Candidates of a warm-started shape search: 9 values within a factor 3 of ``value``, in [lo, hi]."""
    return np.unique(np.clip(float(value) * np.geomspace(1 / 3, 3, 9), lo, hi))


def shape_search(
    cost, candidates: NDArray[np.float64], refine: bool = True
) -> tuple[float, NDArray[np.float64]]:
    """Best shape parameter: least cost among the candidates, refined by golden section (log scale)."""
    sse = np.array([cost(c) for c in candidates])
    k = int(np.argmin(sse))
    if not refine or len(candidates) < 3:
        return float(candidates[k]), sse
    a_lo, a_hi = np.log(candidates[max(k - 1, 0)]), np.log(candidates[min(k + 1, len(candidates) - 1)])
    g = (np.sqrt(5.0) - 1) / 2
    x1, x2 = a_hi - g * (a_hi - a_lo), a_lo + g * (a_hi - a_lo)
    f1, f2 = cost(np.exp(x1)), cost(np.exp(x2))
    for _ in range(_GOLDEN_STEPS):
        if a_hi - a_lo < _SHAPE_RTOL and abs(f1 - f2) <= _SHAPE_FTOL * max(abs(f1), abs(f2)):
            break
        if f1 < f2:
            a_hi, x2, f2 = x2, x1, f1
            x1 = a_hi - g * (a_hi - a_lo)
            f1 = cost(np.exp(x1))
        else:
            a_lo, x1, f1 = x1, x2, f2
            x2 = a_lo + g * (a_hi - a_lo)
            f2 = cost(np.exp(x2))
    best = [(sse[k], candidates[k]), (f1, np.exp(x1)), (f2, np.exp(x2))]
    return float(min(best)[1]), sse
