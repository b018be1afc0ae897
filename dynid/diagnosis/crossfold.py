"""Cross-fitted held-out predictions: the baseline (and a candidate beside it) refitted on the training
data and the other held-out folds, each contiguous held-out fold predicted by the fit that did not see it.

An aperiodic held-out motion that leaves the training states shows the baseline's parameter error at many
times the noise floor; refitted with the rest of the held-out run, the baseline's own parameters predict
that error, and what is left is what no parameter of the baseline predicts on data it was not fitted on.
:class:`CrossFold` factors the baseline once per fold (the training rows as the triangular factor of
``[A | b]``, stacked on the other folds' rows), so that a candidate's columns are fitted beside it per fold
from small cross moments: the excess test (:func:`dynid.diagnosis.baseline.crossfit_residual`) and the
candidates' scores (:func:`dynid.diagnosis.screening.score`) stand on the same footing.
"""

from __future__ import annotations

import itertools

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

__all__ = ["CrossFold"]

_RCOND = 1e-9  # relative singular-value cut of the per-fold baseline factor (scaled columns)


def _r_factor(A: NDArray[np.float64]) -> NDArray[np.float64]:
    """The top ``min(m, k)`` rows of R in ``A = Q R`` (Q is never formed)."""
    R = scipy.linalg.qr(A, mode="r", overwrite_a=True, check_finite=False)[0]
    return R[: min(A.shape)]


class CrossFold:
    """The baseline refitted per held-out fold on the training rows and the other folds.

    Parameters
    ----------
    X_tr : ndarray, shape (m_tr, n, k)
        Training columns (filtered), baseline and accepted effects.
    y_tr : ndarray, shape (m_tr, n)
        Filtered training torque (N m).
    w_tr : ndarray, shape (m_tr, n)
        Training weights (1 / N m): the refit's.
    X_ho : ndarray, shape (m, n, k)
        Held-out columns (filtered).
    y_ho : ndarray, shape (m, n)
        Filtered held-out torque (N m).
    w_ho : ndarray, shape (m, n)
        Held-out weights (1 / N m): the moving mask over the noise floor.
    folds : int
        Contiguous held-out folds (at least 2).
    """

    def __init__(self, X_tr, y_tr, w_tr, X_ho, y_ho, w_ho, folds: int) -> None:
        m_tr, n, k = X_tr.shape
        m = X_ho.shape[0]
        A_tr = (X_tr * w_tr[:, :, None]).reshape(m_tr * n, k)
        b_tr = (y_tr * w_tr).reshape(m_tr * n)
        A_ho = X_ho * w_ho[:, :, None]
        scale = np.sqrt(np.sum(A_tr**2, axis=0) + np.sum(A_ho.reshape(m * n, k) ** 2, axis=0))
        used = scale > 1e-12 * max(float(scale.max(initial=0.0)), 1e-300)
        scale = np.where(used, scale, 1.0)
        self.k, self.n, self.used, self.scale = k, n, used, scale
        self.w_tr, self.w_ho = w_tr, w_ho
        self.X_ho, self.y_ho = X_ho, y_ho
        self.X_tr, self.y_tr = X_tr, y_tr
        self.A_tr = A_tr[:, used] / scale[used]
        self.b_tr = b_tr
        ku = int(used.sum())
        # The training rows once, as the triangular factor of [A | b]: R and Q^T b, without Q.
        Rb = _r_factor(np.column_stack([self.A_tr, b_tr]))
        R_tr, qb_tr = Rb[:ku, :ku], Rb[:ku, ku]
        # The training rows alone: pseudo-inverse of their factor (the training refit, in scaled columns).
        self.Rpinv_tr = np.linalg.pinv(R_tr, rcond=_RCOND)
        self.edges = np.linspace(0, m, max(2, int(folds)) + 1).astype(int)
        self.A_fold = [
            A_ho[a:b][:, :, used].reshape(-1, ku) / scale[used] for a, b in itertools.pairwise(self.edges)
        ]
        self.b_fold = [(y_ho[a:b] * w_ho[a:b]).reshape(-1) for a, b in itertools.pairwise(self.edges)]
        self.Rpinv: list[NDArray[np.float64]] = []  # per fold: pseudo-inverse of the stacked factor
        self.u: list[NDArray[np.float64]] = []  # per fold: Q_f^T b
        for f in range(len(self.A_fold)):
            others = [g for g in range(len(self.A_fold)) if g != f]
            Rf = _r_factor(
                np.column_stack(
                    [
                        np.vstack([R_tr, *(self.A_fold[g] for g in others)]),
                        np.concatenate([qb_tr, *(self.b_fold[g] for g in others)]),
                    ]
                )
            )
            self.Rpinv.append(np.linalg.pinv(Rf[:ku, :ku], rcond=_RCOND))
            self.u.append(Rf[:ku, ku])

    @property
    def folds(self) -> int:
        """Number of held-out folds."""
        return len(self.A_fold)

    def _coefficients(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        x = np.zeros(self.k)
        x[self.used] = z / self.scale[self.used]
        return x

    def coefficients(self, fold: int) -> NDArray[np.float64]:
        """The baseline's coefficients fitted without held-out fold ``fold`` (k,)."""
        return self._coefficients(self.Rpinv[fold] @ self.u[fold])

    def residual(
        self, C_tr: NDArray[np.float64] | None = None, C_ho: NDArray[np.float64] | None = None
    ) -> NDArray[np.float64]:
        """Cross-fitted held-out residual of the baseline, with candidate columns beside it when given.

        Parameters
        ----------
        C_tr : ndarray, shape (m_tr, n, c), optional
            The candidate's filtered training columns.
        C_ho : ndarray, shape (m, n, c), optional
            The same on the held-out rows.

        Returns
        -------
        ndarray, shape (m, n)
            Held-out torque minus the prediction of the fit that did not see its fold (N m).
        """
        out = np.empty_like(self.y_ho)
        if C_tr is None or C_tr.shape[2] == 0:
            for f, (a, b) in enumerate(itertools.pairwise(self.edges)):
                x = self._coefficients(self.Rpinv[f] @ self.u[f])
                out[a:b] = self.y_ho[a:b] - np.einsum("mnk,k->mn", self.X_ho[a:b], x)
            return out
        m_tr, n, c = C_tr.shape
        Cw_tr = (C_tr * self.w_tr[:, :, None]).reshape(m_tr * n, c)
        Cw = [(C_ho[a:b] * self.w_ho[a:b, :, None]).reshape(-1, c) for a, b in itertools.pairwise(self.edges)]
        cscale = np.sqrt(np.sum(Cw_tr**2, axis=0) + sum(np.sum(C**2, axis=0) for C in Cw))
        cscale = np.where(cscale > 0, cscale, 1.0)
        Cw_tr = Cw_tr / cscale
        Cw = [C / cscale for C in Cw]
        # Cross moments per part: A^T C, C^T C, C^T b (training, then each fold).
        P = [self.A_tr.T @ Cw_tr] + [A.T @ C for A, C in zip(self.A_fold, Cw, strict=True)]
        S = [Cw_tr.T @ Cw_tr] + [C.T @ C for C in Cw]
        s = [Cw_tr.T @ self.b_tr] + [C.T @ bf for C, bf in zip(Cw, self.b_fold, strict=True)]
        P_all, S_all, s_all = sum(P), sum(S), sum(s)
        for f, (a, b) in enumerate(itertools.pairwise(self.edges)):
            Pf, Sf, sf = P_all - P[f + 1], S_all - S[f + 1], s_all - s[f + 1]
            # Block elimination of the baseline through its fold factor: the candidate's coefficients solve
            # the Schur complement (its columns with the baseline projected out).
            W = self.Rpinv[f].T @ Pf
            schur = Sf - W.T @ W
            beta = np.linalg.pinv(0.5 * (schur + schur.T), rcond=1e-10, hermitian=True) @ (
                sf - W.T @ self.u[f]
            )
            z = self.Rpinv[f] @ (self.u[f] - W @ beta)
            x = self._coefficients(z)
            pred = np.einsum("mnk,k->mn", self.X_ho[a:b], x) + np.einsum(
                "mnc,c->mn", C_ho[a:b], beta / cscale
            )
            out[a:b] = self.y_ho[a:b] - pred
        return out
