"""Forward selection of the effects that explain the gap.

Each round screens every candidate not yet accepted on top of the current model (:mod:`.screening`),
on two footings: fitted with the current model on the training data, and cross-fitted with it on the
training data and the other held-out folds (the excess test's footing); a candidate passes on either,
its p-value the smaller one doubled.  The round refines the leading nonlinear candidates
(:mod:`.refinement`), corrects the p-values for the candidates tested (Holm across all, and Holm across
the ``screen_top`` that the training data alone rank first, each at half the level), and accepts, among the significant candidates that
close at least ``min_closure`` of the gap on their joint(s), the one that lowers the held-out loss of
the whole arm most (all compared on the training footing, whichever footing decided each; a simpler
candidate on the same joints that it does not beat significantly there is preferred); the accepted
candidate is refined and joins the model.  Rounds stop when none is acceptable or ``max_effects`` are accepted.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from dynid.diagnosis import stats as st
from dynid.diagnosis.baseline import FOLDS, Baseline, HeldOutBaseline
from dynid.diagnosis.candidates import Candidate
from dynid.diagnosis.fitting import WeightedFit, losses, mse, predict
from dynid.diagnosis.refinement import KEPT, fitted_delay, refine, refine_leaders
from dynid.diagnosis.result import RankedCandidate
from dynid.diagnosis.screening import (
    Context,
    CrossFitted,
    confounding,
    cross_fitted,
    on_training,
    parsimonious,
    score,
    tune,
)
from dynid.diagnosis.settings import DiagnosisSettings

__all__ = ["Selection", "select"]


@dataclass(frozen=True, eq=False)
class Selection:
    """What the forward selection found.

    Attributes
    ----------
    accepted : list of RankedCandidate
        The accepted effects, in the order they were selected.
    ranking : list of RankedCandidate
        Every candidate scored on the baseline (round 0), best first.
    residual : ndarray, shape (m, n)
        Held-out residual with the accepted effects (N m); the baseline's when none was accepted.
    loss : ndarray, shape (m,)
        Its per-sample loss (noise variances).
    mse : ndarray, shape (n,)
        Its mean square per joint (N^2 m^2).
    tuned : dict of int to (Candidate, ndarray)
        Per candidate group, the tuned variant and its training columns (m, n, c).
    notes : list of str
        Remarks (delays too short to be told apart from the state estimation).
    cross : CrossFitted
        The final model (the baseline and the accepted effects) cross-fitted on the held-out folds.
    """

    accepted: list[RankedCandidate]
    ranking: list[RankedCandidate]
    residual: NDArray[np.float64]
    loss: NDArray[np.float64]
    mse: NDArray[np.float64]
    tuned: dict[int, tuple[Candidate, NDArray[np.float64]]]
    notes: list[str]
    cross: CrossFitted


def select(
    ctx: Context,
    base: Baseline,
    held: HeldOutBaseline,
    groups: list[list[Candidate]],
    settings: DiagnosisSettings,
    significant_joint: NDArray[np.bool_],
    *,
    folds: int = FOLDS,
    cross0: CrossFitted | None = None,
) -> Selection:
    """Screen, test and accept candidate effects round by round (see the module docstring).

    Parameters
    ----------
    ctx : Context
        The data, noise floor and blocks.
    base : Baseline
        The baseline refit on the training data.
    held : HeldOutBaseline
        The baseline on the held-out data.
    groups : list of list of Candidate
        The candidates, one group of variants (hyper-parameters) per effect and joint(s).
    settings : DiagnosisSettings
    significant_joint : ndarray of bool, shape (n,)
        Joints whose excess over the noise floor is significant.
    folds : int
        Contiguous held-out folds of the cross-fitted footing (those of the excess test).
    cross0 : CrossFitted, optional
        The baseline already cross-fitted on those folds (the excess test's): the first round's footing.
    """
    tr, ho = ctx.tr, ctx.ho
    n = tr.y.shape[1]
    fit, W = base.fit, base.weights
    alpha, min_gain, min_closure, max_effects = (
        settings.alpha,
        settings.min_gain,
        settings.min_closure,
        settings.max_effects,
    )
    accepted: list[RankedCandidate] = []
    acc_tr = np.zeros((tr.y.shape[0], n, 0))
    acc_ho = np.zeros((ho.y.shape[0], n, 0))
    current_fit: WeightedFit = fit
    r_cur, L_cur, mse_cur = held.residual, held.loss, held.mse
    ranking0: list[RankedCandidate] = []
    notes: list[str] = []
    tuned: dict[int, tuple[Candidate, NDArray[np.float64]]] = {}
    for rnd in range(max_effects + 1):
        if rnd == 0 and cross0 is not None:
            cross = cross0
        else:
            cross = cross_fitted(
                ctx,
                current_fit,
                np.concatenate([tr.X0, acc_tr], axis=2),
                np.concatenate([ho.X0, acc_ho], axis=2),
                folds,
            )
        scored = []
        for gi, group in enumerate(groups):
            if any(
                a.candidate.effect == group[0].effect and a.candidate.joints == group[0].joints
                for a in accepted
            ):
                continue
            if gi not in tuned:
                tuned[gi] = tune(ctx, current_fit, group)
            cand, C_tr = tuned[gi]
            C_ho = ho.columns(cand)
            feet: dict[str, NDArray[np.float64]] = {}
            rc = score(ctx, current_fit, acc_tr, acc_ho, C_tr, C_ho, cand, r_cur, mse_cur, rnd, cross, feet)
            scored.append((gi, rc, C_tr, C_ho, feet))
        if not scored:
            break
        # Two families at half the level each: all candidates, and those the training data alone rank
        # first.  Their evidence is taken on the columns tuned on training data, before the leaders (chosen
        # by their held-out gain) are refined: it must not touch the held-out noise the p-values come from.
        evidence_of = {s[0]: s[1].training_evidence for s in scored}
        if settings.refit and rnd < max_effects:
            scored = refine_leaders(ctx, current_fit, acc_tr, acc_ho, scored, r_cur, mse_cur, rnd, cross)
        evidence = np.array([evidence_of[s[0]] for s in scored])
        p_adj = st.screened_holm([s[1].p_value for s in scored], evidence, settings.screen_top)
        rank = np.empty(len(scored), dtype=int)
        rank[np.argsort(evidence, kind="stable")] = np.arange(1, len(scored) + 1)
        scored = [
            (
                gi,
                replace(
                    rc,
                    p_holm=float(pa),
                    significant=bool(pa < alpha and rc.gain >= min_gain),
                    training_rank=int(rk),
                ),
                C_tr,
                C_ho,
                feet,
            )
            for (gi, rc, C_tr, C_ho, feet), pa, rk in zip(scored, p_adj, rank, strict=True)
        ]
        scored.sort(key=lambda s: -s[1].gain)
        if rnd == 0:
            scored = confounding(current_fit, scored, settings.confound_deg)
            ranking0 = [s[1] for s in scored]
        if rnd >= max_effects:
            break
        # A candidate must close at least min_closure of the gap on its joints, and half of it where
        # those joints show no significant excess (the background state estimation leaves there).
        ok = [
            s
            for s in scored
            if s[1].significant
            and s[1].closure
            >= (
                min_closure
                if significant_joint[list(s[1].candidate.scored or range(n))].any()
                else max(min_closure, 0.5)
            )
        ]
        resolved = []
        for x in ok:
            d = fitted_delay(ctx, current_fit, x) if x[1].candidate.effect == "delay" else None
            if d is None or abs(d) >= ctx.min_delay:
                resolved.append(x)
                continue
            note = (
                f"{x[1].candidate.label}: a timing mismatch of {1000 * d:.2g} ms, shorter than one sample "
                f"({1000 * ctx.min_delay:.2g} ms), is not told apart from the state estimation's phase error "
                "and not taken as a delay."
            )
            if note not in notes:
                notes.append(note)
        ok = resolved
        if not ok:
            break
        # Among the acceptable ones, the candidate that mends the whole arm most: a gain error on one joint
        # leaks through the shared base parameters onto its neighbours, where a same-shaped candidate on
        # the neighbour scores nearly as well on its own joint alone.  All are measured on the training
        # footing (on_training): one footing, whichever decided each.
        ok.sort(key=lambda s: -on_training(s[1], "gain_all"))
        best = parsimonious(ok, alpha, ctx.block, min_gain)
        gi, chosen, C_tr, C_ho, _ = best
        rc, replaced = chosen, False
        if settings.refit and "method" not in chosen.refit:
            cand, C_tr2, C_ho2, info = refine(ctx, current_fit, chosen.candidate, C_tr)
            rc2 = score(ctx, current_fit, acc_tr, acc_ho, C_tr2, C_ho2, cand, r_cur, mse_cur, rnd, cross)
            if on_training(rc2, "gain") >= on_training(chosen, "gain"):
                rc = replace(
                    rc2,
                    p_holm=chosen.p_holm,
                    significant=chosen.significant,
                    training_evidence=chosen.training_evidence,
                    training_rank=chosen.training_rank,
                    refit={**rc2.refit, **info},
                    confounded_with=chosen.confounded_with,
                    angle_deg=chosen.angle_deg,
                )
                C_tr, C_ho, replaced = C_tr2, C_ho2, True
            else:
                rc = replace(chosen, refit={**chosen.refit, **info, "kept": KEPT})
        rc = replace(rc, accepted=True)
        accepted.append(rc)
        # The ranking shows it accepted: as chosen (with its refit note) unless a refit replaced it, and
        # any entry of the same effect and joint(s).
        ranking0 = [
            rc
            if r0 is chosen and not replaced
            else (replace(r0, accepted=True) if r0.candidate.key == rc.candidate.key else r0)
            for r0 in ranking0
        ]
        acc_tr = np.concatenate([acc_tr, C_tr], axis=2)
        acc_ho = np.concatenate([acc_ho, C_ho], axis=2)
        xa, ba, _ = fit.solve(acc_tr)
        r_cur = ho.y - predict(ho.X0, xa, acc_ho, ba)
        L_cur = losses(r_cur, ctx.sigma, ctx.mask)
        mse_cur = mse(r_cur, ctx.mask)
        current_fit = WeightedFit(np.concatenate([tr.X0, acc_tr], axis=2), tr.y, W)
    return Selection(
        accepted=accepted,
        ranking=ranking0,
        residual=r_cur,
        loss=L_cur,
        mse=mse_cur,
        tuned=tuned,
        notes=notes,
        cross=cross,
    )
