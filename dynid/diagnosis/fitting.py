"""Weighted least squares of the diagnosis: the baseline columns with candidate columns beside them.

:class:`WeightedFit` solves the baseline (base parameters and the model's own columns) on training data
once, by a pivoted QR, and then any candidate's extra columns against its residual (variable
projection), with block (HAC) sandwich covariances of both.  :func:`predict`, :func:`losses` and
:func:`mse` are the held-out figures every stage scores with.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

from dynid.diagnosis.stats import default_lag
from dynid.identify.estimators import bartlett_weights

__all__ = ["WeightedFit", "losses", "mse", "predict"]


class WeightedFit:
    """Weighted LS of the baseline columns on training data, with extra candidate columns projected.

    Parameters
    ----------
    X : ndarray, shape (m, n, k)
        Baseline columns (filtered) per row and joint.
    y : ndarray, shape (m, n)
        Filtered torque (N m).
    w : ndarray, shape (m, n) or broadcastable
        Weight per row and joint (1 / N m).
    """

    def __init__(self, X: NDArray[np.float64], y: NDArray[np.float64], w: NDArray[np.float64]) -> None:
        m, n, k = X.shape
        w = np.broadcast_to(np.asarray(w, dtype=float), (m, n))
        self.w = w
        A = (X * w[:, :, None]).reshape(m * n, k)
        b = (y * w).reshape(m * n)
        scale = np.linalg.norm(A, axis=0)
        used = scale > 1e-12 * max(float(scale.max()), 1e-300)
        A = A[:, used] / scale[used]
        Q, R, piv = scipy.linalg.qr(A, mode="economic", pivoting=True)
        d = np.abs(np.diag(R))
        rank = int(np.sum(d > 1e-9 * d[0])) if d.size and d[0] > 0 else 0
        self.k = k
        self.Q = Q[:, :rank]
        self.R = R[:rank, :rank]
        idx = np.flatnonzero(used)
        self.cols = idx[piv[:rank]]
        self.scale = scale[self.cols]
        self.b = b
        self.Qb = self.Q.T @ b
        self.r0 = b - self.Q @ self.Qb
        self.shape = (m, n)
        self._cache: dict[Any, NDArray[np.float64]] = {}

    def _weighted(self, C: NDArray[np.float64]) -> NDArray[np.float64]:
        m, n = self.shape
        return (C * self.w[:, :, None]).reshape(m * n, C.shape[2])

    def solve(
        self, C: NDArray[np.float64] | None = None
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
        """Coefficients of the baseline (k,) and of the extra columns, and the training RSS (weighted)."""
        if C is None or C.shape[2] == 0:
            beta = np.zeros(0)
            rhs = self.Qb
            rss = float(self.r0 @ self.r0)
        else:
            Cw = self._weighted(C)
            QtC = self.Q.T @ Cw
            Cp = Cw - self.Q @ QtC
            beta, *_ = np.linalg.lstsq(Cp, self.r0, rcond=1e-10)
            res = self.r0 - Cp @ beta
            rss = float(res @ res)
            rhs = self.Qb - QtC @ beta
        z = scipy.linalg.solve_triangular(self.R, rhs)
        x = np.zeros(self.k)
        x[self.cols] = z / self.scale
        return x, beta, rss

    def regress(self, C: NDArray[np.float64]) -> NDArray[np.float64]:
        """Baseline coefficients (k, c) that best reproduce the columns C (m, n, c): what re-identification
        absorbs of an effect shaped like C."""
        z = scipy.linalg.solve_triangular(self.R, self.Q.T @ self._weighted(C))
        out = np.zeros((self.k, C.shape[2]))
        out[self.cols] = z / self.scale[:, None]
        return out

    def projected(self, C: NDArray[np.float64]) -> NDArray[np.float64]:
        """Weighted candidate columns with the baseline projected out: (m n, k)."""
        Cw = self._weighted(C)
        return Cw - self.Q @ (self.Q.T @ Cw)

    def varpro_residual(self, C: NDArray[np.float64]) -> NDArray[np.float64]:
        """Weighted training residual once the columns C are fitted with the baseline (m n,)."""
        Cp = self.projected(C)
        beta, *_ = np.linalg.lstsq(Cp, self.r0, rcond=1e-10)
        return self.r0 - Cp @ beta

    def projected_covariance(self, C: NDArray[np.float64], block: int) -> NDArray[np.float64]:
        """Block (HAC) sandwich covariance (c, c) of the coefficients of extra columns C (m, n, c) fitted
        with the baseline (their projected regression; independent of the baseline's own estimate)."""
        m, n = self.shape
        Cp = self.projected(C)
        beta, *_ = np.linalg.lstsq(Cp, self.r0, rcond=1e-10)
        e = (self.r0 - Cp @ beta).reshape(m, n)
        meat = _block_meat(np.einsum("mnc,mn->mc", Cp.reshape(m, n, -1), e), block)
        bread = np.linalg.pinv(Cp.T @ Cp, rcond=1e-10)
        return bread @ meat @ bread

    def covariance(self, block: int, *, lags: bool = True) -> NDArray[np.float64]:
        """Block (HAC) sandwich covariance of the baseline coefficients (k, k), NaN for dropped columns.

        ``lags=False`` leaves out the lagged block sums (:func:`_block_meat`): the covariance the
        parameter-change test's chi^2 allowances were set on."""
        key = ("covariance", block, lags)
        if key in self._cache:
            return self._cache[key]
        self._cache[key] = cov = self._covariance(block, lags)
        return cov

    def jackknife_covariance(self, groups: int) -> NDArray[np.float64]:
        """Delete-a-group jackknife covariance of the baseline coefficients (k, k), NaN for dropped columns.

        The training rows are cut into ``groups`` contiguous chunks; each chunk is left out in turn (exactly:
        the estimate moves by ``-R^-1 (I - Q_g^T Q_g)^-1 Q_g^T e_g``) and the spread of the leave-out
        estimates is the covariance.  Chunks of seconds hold noise correlated over hundreds of milliseconds
        and the model error of different parts of the motion, which blocks of 0.1 s do not; compare its
        ratios with Student's t on ``groups - 1`` degrees of freedom.
        """
        key = ("jackknife", groups)
        if key in self._cache:
            return self._cache[key]
        m, n = self.shape
        r = self.Q.shape[1]
        Qr = self.Q.reshape(m, n, r)
        e = self.r0.reshape(m, n)
        moves = []
        for rows in np.array_split(np.arange(m), groups):
            Qg = Qr[rows].reshape(-1, r)
            A = Qg.T @ Qg
            lam, V = np.linalg.eigh(0.5 * (A + A.T))
            # (I - A)^-1 s: a chunk that alone determines a direction leaves it free (a huge move, huge variance)
            s = V.T @ (Qg.T @ e[rows].reshape(-1))
            moves.append(V @ (s / np.maximum(1.0 - lam, 1e-9)))
        D = np.array(moves)
        D -= D.mean(axis=0)
        cz = scipy.linalg.solve_triangular(self.R, scipy.linalg.solve_triangular(self.R, D.T @ D).T)
        self._cache[key] = cov = self._embedded(cz * (groups - 1) / groups)
        return cov

    def _covariance(self, block: int, lags: bool = True) -> NDArray[np.float64]:
        m, n = self.shape
        e = self.r0.reshape(m, n)
        Qr = self.Q.reshape(m, n, -1)
        meat = _block_meat(np.einsum("mnk,mn->mk", Qr, e), block, lags=lags)
        Rinv = scipy.linalg.solve_triangular(self.R, np.eye(self.R.shape[0]))
        return self._embedded(Rinv @ meat @ Rinv.T)

    def _embedded(self, cz: NDArray[np.float64]) -> NDArray[np.float64]:
        """A covariance of the scaled, kept coefficients (rank, rank) as one of all k coefficients (k, k),
        NaN for the dropped columns."""
        cov = np.full((self.k, self.k), np.nan)
        s = 1.0 / self.scale
        cov[np.ix_(self.cols, self.cols)] = cz * np.outer(s, s)
        return cov


def _block_meat(g: NDArray[np.float64], block: int, *, lags: bool = True) -> NDArray[np.float64]:
    """Middle of a block (HAC) sandwich: the per-sample scores g (m, p) summed over blocks of ``block``
    samples, their outer products with Bartlett-weighted lags (Newey-West at :func:`default_lag` of the
    block count, as the Diebold-Mariano test weighs its block means), scaled to all m samples.

    Noise correlated beyond a block carries over into the next blocks: of AR(1) torque noise with a time
    constant as long as the block, the block sums alone hold 37 % of the long-run variance, and with the
    four lags of 150 blocks (15 s of 0.1 s blocks) about 80 %.  Bartlett weights keep the meat positive
    semi-definite."""
    m = g.shape[0]
    count = max(1, m // block)
    G = g[: count * block].reshape(count, block, -1).sum(axis=1)
    meat = G.T @ G
    lag = min(default_lag(count), count - 1) if lags else 0
    for k, w in enumerate(bartlett_weights(lag), start=1):
        cross = G[k:].T @ G[:-k]
        meat += w * (cross + cross.T)
    return meat * (m / (count * block))


def predict(
    X: NDArray[np.float64], x: NDArray[np.float64], C: NDArray[np.float64] | None, beta
) -> NDArray[np.float64]:
    out = np.einsum("mnk,k->mn", X, x)
    if C is not None and C.shape[2]:
        out += np.einsum("mnk,k->mn", C, beta)
    return out


def losses(
    r: NDArray[np.float64], sigma: NDArray[np.float64], mask: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Per-sample loss ``sum_j mask_j r_j^2 / sigma_j^2`` (in noise variances)."""
    return np.sum(mask * (r / sigma[None, :]) ** 2, axis=1)


def mse(r: NDArray[np.float64], mask: NDArray[np.float64]) -> NDArray[np.float64]:
    """Mean squared residual per joint over the samples the mask keeps, (n,)."""
    return np.sum(mask * r**2, axis=0) / np.maximum(np.sum(mask, axis=0), 1.0)
