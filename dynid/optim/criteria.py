"""Excitation criteria: the exact figures of a stacked regressor, and the smooth criterion IPOPT minimises.

``seed`` (the paper's weighted condition numbers), ``cond`` and ``logdet`` (D-optimality), exact from an
SVD for every figure reported (:func:`exact_figures`), and smooth for the optimisation
(:class:`SmoothCriterion`: log-sum-exp bounds of the extreme eigenvalues of the information matrix,
:func:`soft_log_cond2`), wrapped as a CasADi node with an analytic Jacobian (:class:`CriterionCallback`).
The method and its measurements are in :mod:`dynid.optim.excitation`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

__all__ = [
    "CRITERIA",
    "CV_MEAN_FLOOR",
    "CriterionCallback",
    "CriterionData",
    "CriterionJacobian",
    "SmoothCriterion",
    "criterion_data",
    "exact_figures",
    "information",
    "soft_log_cond2",
]

CRITERIA = ("seed", "cond", "logdet")
"""Names of the excitation criteria."""

CV_MEAN_FLOOR = 1e-3
"""Floor of ``|mean|`` relative to the RMS of a column in the coefficient-of-variation weights (ours)."""


# ---------------------------------------------------------------------------- criteria, exact
@dataclass(frozen=True, eq=False)
class CriterionData:
    """Fixed numbers of a criterion for one design: seed weights (w_H, w_h1, w_h2), column scaling."""

    weights: np.ndarray  # (3,)
    scale: np.ndarray  # (n_b,) column scaling of logdet (1 / RMS over the random pool)
    column_weights: np.ndarray  # (n_b,) w_ci


def criterion_data(H_pool: np.ndarray, gravity: np.ndarray) -> CriterionData:
    """Coefficient-of-variation weights and column scaling from pooled random trajectories.

    The paper does not say on which H* the weights are computed (ours): on the pool of random
    feasible trajectories, once per design, so that every try minimises the same function and
    their objectives can be compared.  Some columns have a mean that vanishes over any period
    (the column of ``Izz1`` is ``ddq_1``, whose integral over a period is zero): their CV is
    1e17 and would take all the weight, so (ours) ``|mean|`` is floored at ``CV_MEAN_FLOOR`` times
    the column's RMS, which caps a CV at 1 / CV_MEAN_FLOOR.
    """
    mean = np.abs(H_pool.mean(axis=0))
    std = H_pool.std(axis=0)
    rms = np.sqrt(np.mean(H_pool**2, axis=0))
    cv = std / np.maximum(mean, np.maximum(CV_MEAN_FLOOR * rms, 1e-300))
    w = cv / cv.sum()
    w1 = float(w[gravity].sum())
    w2 = float(w[~gravity].sum())
    return CriterionData(
        weights=np.array([w1 + w2, w1, w2]),
        scale=1.0 / np.maximum(rms, 1e-300),
        column_weights=w,
    )


def exact_figures(H: np.ndarray, criterion: str, data: CriterionData, gravity: np.ndarray) -> dict[str, float]:
    """Exact condition numbers (SVD) and the criterion's exact value for a stacked H*."""
    cond = float(np.linalg.cond(H))
    cond1 = float(np.linalg.cond(H[:, gravity])) if gravity.any() else 0.0
    cond2 = float(np.linalg.cond(H[:, ~gravity])) if (~gravity).any() else 0.0
    if criterion == "seed":
        w = data.weights
        objective = w[0] * cond + w[1] * cond1 + w[2] * cond2
    elif criterion == "cond":
        objective = cond
    else:
        Hs = H * data.scale
        sign, logdet = np.linalg.slogdet(Hs.T @ Hs / H.shape[0])
        objective = -logdet / H.shape[1] if sign > 0 else math.inf
    if not math.isfinite(cond):
        objective = math.inf
    return {"cond": cond, "cond_gravity": cond1, "cond_motion": cond2, "objective": float(objective)}


# ---------------------------------------------------------------------------- criteria, smooth
def soft_log_cond2(S: np.ndarray, p: float) -> tuple[float, np.ndarray]:
    """Smooth upper bound of log cond(S) for a symmetric positive definite S, and its gradient dL/dS.

    ``L = (1/p) log sum lambda^p + (1/p) log sum lambda^-p`` (p = inf: the exact extreme eigenvalues).
    """
    lam, V = np.linalg.eigh(0.5 * (S + S.T))
    floor = max(lam[-1], 1e-300) * 1e-15
    lam = np.maximum(lam, floor)
    ll = np.log(lam)
    if math.isinf(p):
        hi_w = np.zeros_like(lam)
        lo_w = np.zeros_like(lam)
        hi_w[-1] = lo_w[0] = 1.0
        value = ll[-1] - ll[0]
    else:
        z = p * ll
        zmax = z.max()
        e = np.exp(z - zmax)
        hi = (zmax + math.log(e.sum())) / p
        hi_w = e / e.sum()
        z2 = -p * ll
        z2max = z2.max()
        e2 = np.exp(z2 - z2max)
        lo = -(z2max + math.log(e2.sum())) / p
        lo_w = e2 / e2.sum()
        value = hi - lo
    grad = (V * ((hi_w - lo_w) / lam)) @ V.T
    return float(value), grad


class SmoothCriterion:
    """The smooth criterion f(A, w, s) of the information matrix A = H*^T H* and its gradient."""

    def __init__(self, criterion: str, gravity: np.ndarray, sharpness: float) -> None:
        self.criterion = criterion
        self.gravity = np.asarray(gravity, dtype=bool)
        self.sharpness = sharpness
        self._last: tuple[bytes, tuple] | None = None

    def __call__(self, A: np.ndarray, w: np.ndarray, s: np.ndarray):
        key = A.tobytes() + w.tobytes() + s.tobytes()
        if self._last is not None and self._last[0] == key:
            return self._last[1]
        out = self._evaluate(A, w, s)
        self._last = (key, out)
        return out

    def _evaluate(self, A: np.ndarray, w: np.ndarray, s: np.ndarray):
        nb = A.shape[0]
        p = self.sharpness
        if self.criterion == "logdet":
            # -(1/n_b) log det(D A D), D = diag(s): eigenvalues of the scaled matrix (better conditioned);
            # the gradient D (D A D)^-1 D is A^-1 whatever the scaling, which only shifts the value.
            S = A * np.outer(s, s)
            lam, V = np.linalg.eigh(0.5 * (S + S.T))
            lam = np.maximum(lam, max(lam[-1], 1e-300) * 1e-15)
            value = -float(np.sum(np.log(lam))) / nb
            dA = -((V / lam) @ V.T) * np.outer(s, s) / nb
            return value, dA, np.zeros(3), -2.0 / (nb * s)
        value_all, g_all = soft_log_cond2(A, p)
        if self.criterion == "cond":
            return 0.5 * value_all, 0.5 * g_all, np.zeros(3), np.zeros(nb)
        # seed: log(w_H c + w_1 c_1 + w_2 c_2) with c = exp(L / 2) the smooth condition numbers
        terms = [(w[0], value_all, g_all, None)]
        for weight, mask in ((w[1], self.gravity), (w[2], ~self.gravity)):
            if mask.any() and weight > 0:
                idx = np.flatnonzero(mask)
                v, g = soft_log_cond2(A[np.ix_(idx, idx)], p)
                terms.append((weight, v, g, idx))
            else:
                terms.append((0.0, 0.0, None, None))
        conds = np.array([math.exp(0.5 * t[1]) if t[2] is not None else 0.0 for t in terms])
        weights = np.array([t[0] for t in terms])
        total = float(weights @ conds)
        dA = np.zeros_like(A)
        for (weight, _, g, idx), c in zip(terms, conds, strict=True):
            if g is None or weight == 0:
                continue
            block = weight * c * 0.5 * g / total
            if idx is None:
                dA += block
            else:
                dA[np.ix_(idx, idx)] += block
        return math.log(total), dA, conds / total, np.zeros(nb)


class CriterionCallback(ca.Callback):
    """CasADi node ``f(A, w, s)`` of the smooth criterion, with its analytic Jacobian."""

    def __init__(self, name: str, fn: SmoothCriterion, nb: int) -> None:
        ca.Callback.__init__(self)
        self._fn = fn
        self._nb = nb
        self._jac: CriterionJacobian | None = None
        self.construct(name, {"enable_fd": False})

    def get_n_in(self) -> int:
        return 3

    def get_n_out(self) -> int:
        return 1

    def get_name_in(self, i: int) -> str:
        return ("A", "w", "s")[i]

    def get_name_out(self, i: int) -> str:
        return "f"

    def get_sparsity_in(self, i: int) -> ca.Sparsity:
        return (ca.Sparsity.dense(self._nb, self._nb), ca.Sparsity.dense(3, 1), ca.Sparsity.dense(self._nb, 1))[i]

    def get_sparsity_out(self, i: int) -> ca.Sparsity:
        return ca.Sparsity.dense(1, 1)

    def eval(self, arg):
        A, w, s = (np.asarray(v.full() if hasattr(v, "full") else v, dtype=float) for v in arg)
        value = self._fn(A, w.ravel(), s.ravel())[0]
        return [value]

    def has_jacobian(self) -> bool:
        return True

    def get_jacobian(self, name, inames, onames, opts):
        self._jac = CriterionJacobian(name, self._fn, self._nb, inames, onames, opts)
        return self._jac


class CriterionJacobian(ca.Callback):
    """Jacobian of :class:`CriterionCallback`: inputs (A, w, s, f), outputs df/dA, df/dw, df/ds (rows)."""

    def __init__(self, name, fn: SmoothCriterion, nb: int, inames, onames, opts) -> None:
        ca.Callback.__init__(self)
        self._fn = fn
        self._nb = nb
        self._inames = list(inames)
        self._onames = list(onames)
        self.construct(name, dict(opts, enable_fd=False))

    def get_n_in(self) -> int:
        return 4

    def get_n_out(self) -> int:
        return 3

    def get_name_in(self, i: int) -> str:
        return self._inames[i]

    def get_name_out(self, i: int) -> str:
        return self._onames[i]

    def get_sparsity_in(self, i: int) -> ca.Sparsity:
        nb = self._nb
        return (ca.Sparsity.dense(nb, nb), ca.Sparsity.dense(3, 1), ca.Sparsity.dense(nb, 1), ca.Sparsity.dense(1, 1))[i]

    def get_sparsity_out(self, i: int) -> ca.Sparsity:
        return (ca.Sparsity.dense(1, self._nb**2), ca.Sparsity.dense(1, 3), ca.Sparsity.dense(1, self._nb))[i]

    def eval(self, arg):
        A, w, s = (np.asarray(v.full() if hasattr(v, "full") else v, dtype=float) for v in arg[:3])
        _, dA, dw, ds = self._fn(A, w.ravel(), s.ravel())
        return [dA.reshape(1, -1, order="F"), dw.reshape(1, -1), ds.reshape(1, -1)]


def information(H: np.ndarray) -> np.ndarray:
    """The information matrix ``H^T H`` (n_b, n_b) of stacked regressor rows H (m, n_b)."""
    return H.T @ H
