"""Is anything left that the state predicts?  A cross-fitted flexible model of the held-out residual.

The excess test (:func:`dynid.diagnosis.baseline.excess_over_floor`) weighs the held-out residual against
the noise floor, and so rests on the floor.  This test does not: it asks whether a flexible model of the
state (gradient-boosted trees on the angles, velocities and accelerations of every joint) predicts the
residual of held-out data it was not fitted on.  What no state model predicts on data it has not seen is
noise or drift; what one does predict is an effect the model lacks.

Per contiguous held-out fold ``k`` (the cross-fitted footing's folds, :class:`~dynid.diagnosis.crossfold.CrossFold`):

1. the model (the baseline and any accepted effects) refitted on the training data and the other folds
   gives its residual on every training and held-out row;
2. per joint, the trees are fitted to that residual on the training rows and on the other folds' rows,
   leaving out those within ``GUARD_SECONDS`` of fold ``k`` (the torque noise is correlated over a tenth
   of a second or so, and the filter spreads it further); training rows too, when the two runs are parts
   of one recording on one clock (a recording split in time);
3. they predict fold ``k``'s residual.

Nothing fitted for fold ``k`` has seen its rows, so on noise alone the prediction is independent of what
it predicts and can only add to the loss: the test is one-sided and conservative.  A Diebold-Mariano test
on the per-sample loss difference (block means, Newey-West) per joint, Holm-corrected across the joints,
says whether the residual is predictable.  The noise floor scales both losses alike and cancels from it.

Power (simulated UR5, 20 s aperiodic held-out run, coloured noise): coupled wrist friction outside the
catalogue that leaves 18.7 noise variances on joint 6 after the cross-fitted baseline is found (the
trees predict 37 % of that joint's residual, adjusted p 0.02); at 2.8 noise variances it is not (25 %,
adjusted p 0.17).  The test confirms an excess; it is not as sensitive as the excess test itself.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynid.diagnosis import stats as st
from dynid.diagnosis.crossfold import CrossFold

__all__ = ["Remainder", "predictable_remainder"]

GUARD_SECONDS = 0.5
"""Held-out rows this close in time to the predicted fold are left out of the trees' fit."""
TRAINING_STRIDE = 4
"""Every this many training rows join the trees' fit (neighbouring rows say nearly the same)."""
HELDOUT_STRIDE = 2
"""Every this many held-out rows of the other folds join the trees' fit."""
ITERATIONS = 40
"""Boosting iterations: trees of at most 8 leaves of at least 100 rows, learning rate 0.1."""
MIN_ROWS = 200
"""Fewer rows to fit on than this, and a fold's prediction on the joint is zero."""


@dataclass(frozen=True, eq=False)
class Remainder:
    """What a flexible state model predicts of the held-out residual, per joint.

    Attributes
    ----------
    p_joint : ndarray, shape (n,)
        Holm-adjusted one-sided p-values of "the prediction lowers the joint's held-out loss".
    share : ndarray, shape (n,)
        Fraction of the residual's mean square over the moving rows that the prediction removes (negative
        when it adds to it).
    gain : ndarray, shape (n,)
        The same in noise variances per sample.
    alpha : float
        The level the predictable joints are judged at.
    """

    p_joint: NDArray[np.float64]
    share: NDArray[np.float64]
    gain: NDArray[np.float64]
    alpha: float

    @property
    def predictable(self) -> NDArray[np.bool_]:
        """Joints whose residual the state predicts (adjusted p below ``alpha``)."""
        return self.p_joint < self.alpha

    def to_dict(self) -> dict[str, Any]:
        return {
            "p_joint": self.p_joint,
            "share": self.share,
            "gain": self.gain,
            "predictable_joint": self.predictable,
            "model": (
                f"gradient-boosted trees on q, dq, ddq of every joint ({ITERATIONS} trees of at most 8 leaves), "
                "fitted per held-out fold on the training run and the other folds"
            ),
        }


def predictable_remainder(
    cf: CrossFold,
    states_tr: tuple[NDArray[np.float64], ...],
    t_tr: NDArray[np.float64],
    mask_tr: NDArray[np.float64],
    states_ho: tuple[NDArray[np.float64], ...],
    t: NDArray[np.float64],
    mask: NDArray[np.float64],
    sigma: NDArray[np.float64],
    block: int,
    alpha: float,
    *,
    seed: int = 0,
) -> Remainder:
    """Test whether the state predicts the held-out residual of the cross-fitted model (module docstring).

    Parameters
    ----------
    cf : CrossFold
        The model (baseline and accepted effects) factored per held-out fold.
    states_tr : tuple of ndarray, each (m_tr, n)
        Training angles, velocities and accelerations at the rows used.
    t_tr : ndarray, shape (m_tr,)
        Their times (s): when the held-out run follows the training run on one clock (or precedes it),
        training rows near a fold are left out of its fit as held-out rows are.
    mask_tr : ndarray, shape (m_tr, n)
        Training rows that count per joint (moving).
    states_ho : tuple of ndarray, each (m, n)
        The same on the held-out rows.
    t : ndarray, shape (m,)
        Held-out times (s).
    mask : ndarray, shape (m, n)
        Held-out rows that count per joint (moving).
    sigma : ndarray, shape (n,)
        Noise floor (N m): it scales the loss only.
    block : int
        Rows per block of the test.
    alpha : float
        Level of the test.
    seed : int
        Seed of the trees (their fit is deterministic given it).

    Returns
    -------
    Remainder
    """
    from sklearn.ensemble import HistGradientBoostingRegressor
    from threadpoolctl import threadpool_limits

    m, n = cf.y_ho.shape
    Z_ho = np.column_stack(states_ho)
    Z_tr = np.column_stack(states_tr)
    pred = np.zeros((m, n))
    resid = np.zeros((m, n))
    one_clock = bool(t[0] >= t_tr[-1] or t_tr[0] >= t[-1])  # the two parts of one recording
    with threadpool_limits(limits=1, user_api="openmp"):  # small fits; a worker of a pool must not fan out
        for f, (a, b) in enumerate(itertools.pairwise(cf.edges)):
            x = cf.coefficients(f)
            R_ho = cf.y_ho - np.einsum("mnk,k->mn", cf.X_ho, x)
            R_tr = cf.y_tr - np.einsum("mnk,k->mn", cf.X_tr, x)
            resid[a:b] = R_ho[a:b]
            away = (t < t[a] - GUARD_SECONDS) | (t > t[b - 1] + GUARD_SECONDS)
            away_tr = (t_tr < t[a] - GUARD_SECONDS) | (t_tr > t[b - 1] + GUARD_SECONDS) if one_clock else True
            for j in range(n):
                rows_ho = np.flatnonzero(away & (mask[:, j] > 0))[::HELDOUT_STRIDE]
                rows_tr = np.flatnonzero(away_tr & (mask_tr[:, j] > 0))[::TRAINING_STRIDE]
                if rows_ho.size + rows_tr.size < MIN_ROWS:
                    continue
                trees = HistGradientBoostingRegressor(
                    max_iter=ITERATIONS,
                    learning_rate=0.1,
                    max_leaf_nodes=8,
                    min_samples_leaf=100,
                    l2_regularization=1.0,
                    early_stopping=False,
                    random_state=seed,
                )
                trees.fit(
                    np.vstack([Z_ho[rows_ho], Z_tr[rows_tr]]),
                    np.concatenate([R_ho[rows_ho, j], R_tr[rows_tr, j]]),
                )
                pred[a:b, j] = trees.predict(Z_ho[a:b])
    p = np.ones(n)
    share = np.zeros(n)
    gain = np.zeros(n)
    for j in range(n):
        w = mask[:, j]
        if w.sum() < 8 * block:
            continue
        l0 = w * (resid[:, j] / sigma[j]) ** 2
        l1 = w * ((resid[:, j] - pred[:, j]) / sigma[j]) ** 2
        p[j] = st.diebold_mariano(l0, l1, block=block).p_value
        gain[j] = float((l0.sum() - l1.sum()) / w.sum())
        share[j] = float((l0.sum() - l1.sum()) / max(float(l0.sum()), 1e-300))
    return Remainder(p_joint=st.holm(p), share=share, gain=gain, alpha=alpha)
