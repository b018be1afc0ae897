"""The triangular factor of a tall matrix, as :func:`scipy.linalg.qr` ``mode="r"`` computes it, cheaper.

``scipy.linalg.qr(A, mode="r")`` returns R with as many rows as A (``numpy.triu`` over the whole
factored matrix) and copies a C-ordered A to Fortran order; the identification only keeps the top
``min(m, k)`` rows of R and factors hundreds of tall blocks (the friction searches, the joint refits).
:func:`r_factor` calls the same LAPACK routine (``geqrf``, the same workspace query) on a Fortran-ordered
matrix, filled once, and keeps the top rows: the same R to the bit.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import get_lapack_funcs

__all__ = ["fortran_stack", "q_factor", "r_factor"]


def fortran_stack(*blocks: NDArray[np.float64]) -> NDArray[np.float64]:
    """``numpy.column_stack(blocks)`` as a new Fortran-ordered float64 array, ready for :func:`r_factor`.

    Parameters
    ----------
    *blocks : ndarray, shape (m,) or (m, k_i)
        Columns, all with the same number of rows.

    Returns
    -------
    ndarray, shape (m, sum k_i), Fortran order
    """
    cols = [b[:, None] if b.ndim == 1 else b for b in blocks]
    out = np.empty((cols[0].shape[0], sum(c.shape[1] for c in cols)), order="F")
    a = 0
    for c in cols:
        out[:, a : a + c.shape[1]] = c
        a += c.shape[1]
    return out


def r_factor(A: NDArray[np.float64], *, overwrite: bool = False) -> NDArray[np.float64]:
    """Upper-triangular R (min(m, k), k) of ``A = Q R``: ``scipy.linalg.qr(A, mode="r")[0][:k]`` to the bit.

    Parameters
    ----------
    A : ndarray, shape (m, k)
        Matrix (float64, finite; not checked).  Fortran order avoids a copy.
    overwrite : bool
        May destroy ``A`` (a Fortran-ordered float64 ``A`` is then factored in place).

    Returns
    -------
    ndarray, shape (min(m, k), k)
    """
    a1 = np.asarray(A)
    m, k = a1.shape
    if a1.size == 0:
        return np.zeros((min(m, k), k))
    (geqrf,) = get_lapack_funcs(("geqrf",), (a1,))
    lwork = geqrf(a1, lwork=-1)[-2][0].real.astype(np.int_)
    qr, _, _, info = geqrf(a1, lwork=lwork, overwrite_a=overwrite)
    if info < 0:
        raise ValueError(f"illegal value in {-info}th argument of internal geqrf")
    return np.triu(qr[: min(m, k)])


def q_factor(A: NDArray[np.float64]) -> NDArray[np.float64]:
    """Q (m, k) of the economic ``A = Q R`` (m >= k): ``scipy.linalg.qr(A, mode="economic")[0]`` to the bit.

    The same LAPACK calls (``geqrf``, ``orgqr``, each with its workspace query); a Fortran-ordered
    float64 ``A`` is factored in place (it is overwritten).

    Parameters
    ----------
    A : ndarray, shape (m, k)
        Matrix with m >= k (float64, finite; not checked).

    Returns
    -------
    ndarray, shape (m, k)
    """
    a1 = np.asarray(A)
    m, k = a1.shape
    if m < k or a1.size == 0:
        import scipy.linalg

        return scipy.linalg.qr(a1, mode="economic", check_finite=False)[0]
    geqrf, orgqr = get_lapack_funcs(("geqrf", "orgqr"), (a1,))
    lwork = geqrf(a1, lwork=-1)[-2][0].real.astype(np.int_)
    qr, tau, _, info = geqrf(a1, lwork=lwork, overwrite_a=True)
    if info < 0:
        raise ValueError(f"illegal value in {-info}th argument of internal geqrf")
    lwork = orgqr(qr, tau, lwork=-1)[-2][0].real.astype(np.int_)
    Q, _, info = orgqr(qr, tau, lwork=lwork, overwrite_a=1)
    if info < 0:
        raise ValueError(f"illegal value in {-info}th argument of internal orgqr")
    return Q
