"""Do the training and the held-out run agree on the baseline's parameters?  A test that needs no floor.

The cross-fitted excess test (:func:`dynid.diagnosis.baseline.crossfit_residual`) lets the baseline refit
its parameters with the other held-out folds, so that a parameter the training run leaves uncertain is not
taken for an effect.  An unmodelled effect is absorbed too: on a simulated Panda with coupled wrist friction
outside the catalogue, the refit left 13.8 noise variances on joint 7 of the held-out run, the cross-fitted
baseline 2.9, and the excess test found nothing.

The two cases differ on the training run.  A parameter the training run leaves uncertain can move at
little cost to the training fit; parameters moved to absorb an effect on other motions fit the training
run worse (that Panda: by 5.1 noise variances on joint 7, against at most 0.07 on its effect-free twin).
This is a test of parameter constancy across two samples (Chow 1960), on the training side:

* the statistic, per joint, is the training loss of the cross-fitted coefficients (each fold's, averaged)
  minus that of the training refit, over the training residual's own variance;
* its null distribution is drawn by a sieve bootstrap (Buhlmann 1997): an autoregressive model of the
  training run's noise, per joint, draws noise for both runs; the fits are repeated on it (they are linear
  in the torque) and the statistic is computed again.  A moment-matched gamma gives the tail.

The noise model is fitted on the training run's deviation from its mean over its periods when it repeats
a period (:func:`dynid.validation.noise.periodic_deviation`): any effect of the state is periodic there and
drops out, and the noise in the motion's band, which is what moves the parameters, is kept.  Otherwise it
is fitted on the training refit's residual, which lacks the noise in the span of the columns (resampling
its blocks understated the null by about a third on a synthetic run; the autoregressive model smooths over
that) and holds an unmodelled effect too, which widens the null: the test is conservative then.  On the
simulated field runs (coloured noise with a 100 ms time constant; 40 effect-free tuning runs) the cost was
1.00 times the null's mean at the median with the periods' model, 1.23 with the residual's, and 6 runs
against 16 had a joint at adjusted p < 0.05.

The statistic is a ratio of losses, so no noise floor enters.

The coloured noise is what moves the parameters between two motions: on a simulated effect-free UR5
(four tuning seeds) the costs were 0.001-0.007 with white torque noise and exact angles, 0.01-0.10 with the
field's coloured noise and exact angles, and about the same with 18-bit angles besides (the state
estimation's error in the columns adds little).  Noise coloured on the motion's time scale leaves the
statistic few effective degrees of freedom, so the gamma tail is rough (6 of 40 effect-free runs had a
joint at adjusted p < 0.05, 2 expected), and the cost separated effect-free runs from unknown effects better
than the p-value did.  So a joint counts as a lead only where the cost also reaches :data:`LEAD_COST`.
Such a joint makes the verdict "unexplained" where no effect is accepted
(:func:`dynid.diagnosis.core.diagnose`).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from dynid.diagnosis import stats as st
from dynid.diagnosis.crossfold import CrossFold

__all__ = ["DRAWS", "LEAD_COST", "MEMORY_SECONDS", "Consistency", "parameter_consistency"]

DRAWS = 200
"""Bootstrap draws of the null distribution."""
MEMORY_SECONDS = 0.1
"""The autoregressive noise model reaches this far back (rows; the field noise has a 0.1 s time constant)."""
LEAD_COST = 0.2
"""A joint whose cost (training loss added, over the training residual's variance) reaches this, and whose
own bootstrap p-value is below ``alpha``, is a lead: the two runs disagree on its parameters.  The
bootstrap's tail is rough under noise coloured on the motion's time scale, and the cost itself separated
effect-free runs from unknown effects better than the p-value did, so the decision rests on both.  Set on
200 simulated effect-free field runs (the tuning seeds 1000-1099, UR5 and Panda, three training periods,
coloured noise, 18-bit angles): the largest cost per run reached 0.195 (UR5) and 0.153 (Panda) at the
99th percentile, and 0.2 once in 200 (0.209, UR5).
Coupled wrist friction outside the catalogue at 1x, on 40 tuning runs, left 0.12-0.66 on its joint, at or
above 0.2 in 32.

The threshold is set on the largest cost over a run's joints, so it bounds the chance that any joint of
an effect-free run reaches it (about 1 %) by itself: the p-value beside it only screens out a joint whose
own null is wide, and is taken per joint (``Consistency.p_raw``).  Corrected across the joints as well
(Holm), it counted the joints twice: on 26 tuning runs with the unknown effect at 1x (seeds 1000-1012),
three whose cost on the effect's joint reached 0.21-0.24 had Holm-adjusted p-values of 0.05-0.12 and
per-joint ones of 0.01-0.02, and were called "none"; no effect-free twin of them reached the cost."""


@dataclass(frozen=True, eq=False)
class Consistency:
    """The parameter-constancy test, per joint.

    Attributes
    ----------
    cost : ndarray, shape (n,)
        Training loss added by the cross-fitted coefficients, over the training residual's variance.
    null_mean : ndarray, shape (n,)
        The bootstrap's mean of the same under the null hypothesis (same unit).
    p_joint : ndarray, shape (n,)
        Holm-adjusted p-values (across the joints).
    p_raw : ndarray, shape (n,)
        The same per joint, unadjusted: what :meth:`leads` uses beside :data:`LEAD_COST`, whose calibration
        on the largest cost over a run's joints already allows for their number.
    noise_source : str
        What the bootstrap's noise model was fitted on: ``"training periods"`` (the training run's
        deviation from its mean over its periods) or ``"training residual"`` (the training refit's
        residual, when the training run does not repeat a period).
    """

    cost: NDArray[np.float64]
    null_mean: NDArray[np.float64]
    p_joint: NDArray[np.float64]
    p_raw: NDArray[np.float64]
    noise_source: str = "training residual"

    def leads(self, alpha: float) -> NDArray[np.bool_]:
        """Joints whose cost reaches :data:`LEAD_COST` with their own p-value below ``alpha``."""
        return (self.cost >= LEAD_COST) & (self.p_raw < alpha)

    def to_dict(self, alpha: float) -> dict:
        """JSON-ready figures, with the leads at ``alpha``."""
        return {
            "cost": self.cost.tolist(),
            "null_mean": self.null_mean.tolist(),
            "p_joint": self.p_joint.tolist(),
            "p_raw": self.p_raw.tolist(),
            "lead_joint": self.leads(alpha).tolist(),
            "lead_cost": LEAD_COST,
            "noise_source": self.noise_source,
        }


def _solve(Rp: NDArray[np.float64], g: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(R^T R)^+ g`` from the pseudo-inverse of the triangular factor."""
    return Rp @ (Rp.T @ g)


def parameter_consistency(
    cf: CrossFold,
    order: int,
    *,
    noise: NDArray[np.float64] | None = None,
    draws: int = DRAWS,
    seed: int = 0,
) -> Consistency:
    """Test per joint whether the cross-fitted coefficients fit the training run worse than noise explains.

    Parameters
    ----------
    cf : CrossFold
        The baseline cross-fitted on the held-out folds (its training and fold factors are reused).
    order : int
        Order of the autoregressive model of the noise (rows in ``MEMORY_SECONDS``).
    noise : ndarray, shape (L, n), optional
        The training run's deviation from its mean over its periods
        (:func:`dynid.validation.noise.periodic_deviation`) at the rows' rate (torque units, filtered like
        the torque); without it, the training refit's residual.
    draws : int
        Bootstrap draws.
    seed : int
        Seed of the bootstrap (the result is reproducible).

    Returns
    -------
    Consistency
    """
    A, n, used, scale = cf.A_tr, cf.n, cf.used, cf.scale
    m_tr = cf.X_tr.shape[0]
    w_tr = cf.w_tr
    Rp_tr = cf.Rpinv_tr
    folds = cf.folds

    def costs(e_tr: NDArray[np.float64], e_fold: list[NDArray[np.float64]]) -> NDArray[np.float64]:
        """Per draw (columns of the inputs) and joint: the cross-fitted coefficients' added training loss
        over the training residual's mean square.  ``e_tr``: (m_tr * n, d) weighted torque; ``e_fold``:
        per fold, (rows * n, d)."""
        g_tr = A.T @ e_tr
        g_f = [Af.T @ ef for Af, ef in zip(cf.A_fold, e_fold, strict=True)]
        g_all = g_tr + sum(g_f)
        z_T = _solve(Rp_tr, g_tr)
        r_T = (e_tr - A @ z_T).reshape(m_tr, n, -1)
        base = np.einsum("mnd,mnd->nd", r_T, r_T)
        added = np.zeros_like(base)
        for f in range(folds):
            z_f = _solve(cf.Rpinv[f], g_all - g_f[f])
            d = (A @ (z_f - z_T)).reshape(m_tr, n, -1)
            added += np.einsum("mnd,mnd->nd", d, d) - 2.0 * np.einsum("mnd,mnd->nd", r_T, d)
        return added / folds / np.maximum(base, 1e-300)

    b_fold = [bf[:, None] for bf in cf.b_fold]
    observed = costs(cf.b_tr[:, None], b_fold)[:, 0]

    m_ho = cf.y_ho.shape[0]
    if noise is None:
        # The noise proxy: the training refit's residual (torque units) on the rows where the joint moves.
        x_T = np.zeros(cf.k)
        x_T[used] = _solve(Rp_tr, A.T @ cf.b_tr) / scale[used]
        noise = cf.y_tr - np.einsum("mnk,k->mn", cf.X_tr, x_T)
        moving = w_tr > 0
        ar = [st.ar_model(noise[moving[:, j], j], order) for j in range(n)]
        source = "training residual"
    else:
        ar = [st.ar_model(noise[:, j], order) for j in range(n)]
        source = "training periods"
    rng = np.random.default_rng(seed)
    gain_cache: dict[int, NDArray[np.complex128]] = {}

    def drawn_costs(d: int) -> NDArray[np.float64]:
        """The costs (n, d) of ``d`` draws of the noise of both runs."""
        e_t = st.ar_noise(ar, m_tr, d, rng, gain_cache)  # (d, m_tr, n)
        e_h = st.ar_noise(ar, m_ho, d, rng, gain_cache)
        e_tr = (e_t * w_tr[None]).reshape(d, -1).T
        e_fold = [
            (e_h[:, a:b] * cf.w_ho[None, a:b]).reshape(d, -1).T for a, b in itertools.pairwise(cf.edges)
        ]
        return costs(e_tr, e_fold)

    null = st.bootstrap_null(drawn_costs, draws)  # (n, draws)
    mean = null.mean(axis=1)
    p = st.gamma_tail(observed, null)
    return Consistency(
        cost=observed,
        null_mean=mean,
        p_joint=st.holm(p),
        p_raw=p,
        noise_source=source,
    )
