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

A round, step by step: the current model (:class:`~dynid.diagnosis.screening.Current`) is cross-fitted;
``_screen`` scores every open candidate group (:class:`~dynid.diagnosis.screening.Scored`: the score, the
columns, each footing's losses); ``_tested`` refines the leaders and corrects the p-values;
``_acceptable`` keeps the candidates that pass and close enough of their gap; ``_choose`` picks one;
``_refit_chosen`` refines it; ``_with_accepted`` makes the next round's current model.
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
    Current,
    Scored,
    confounding,
    cross_fitted,
    on_training,
    parsimonious,
    score,
    tune,
)
from dynid.diagnosis.settings import DiagnosisSettings

__all__ = ["Selection", "select"]

Tuned = tuple[Candidate, NDArray[np.float64]]
"""A candidate group's tuned variant and its training columns (m, n, c)."""


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
    fit : WeightedFit
        The final model's training fit: the baseline's columns, then the accepted effects' (the
        baseline's own fit when none was accepted).
    """

    accepted: list[RankedCandidate]
    ranking: list[RankedCandidate]
    residual: NDArray[np.float64]
    loss: NDArray[np.float64]
    mse: NDArray[np.float64]
    tuned: dict[int, Tuned]
    notes: list[str]
    cross: CrossFitted
    fit: WeightedFit


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
    current = _baseline(ctx, base, held)
    accepted: list[RankedCandidate] = []
    ranking0: list[RankedCandidate] = []
    notes: list[str] = []
    tuned: dict[int, Tuned] = {}
    for rnd in range(settings.max_effects + 1):
        cross = cross0 if rnd == 0 and cross0 is not None else _cross_fitted(ctx, current, folds)
        current = replace(current, round=rnd, cross=cross)
        scored, new = _screen(ctx, current, groups, accepted, tuned)
        tuned.update(new)
        if not scored:
            break
        scored = _tested(ctx, current, scored, settings)
        if rnd == 0:
            scored = confounding(current.fit, scored, settings.confound_deg)
            ranking0 = [s.ranked for s in scored]
        if rnd >= settings.max_effects:
            break
        ok, found = _acceptable(ctx, current, scored, settings, significant_joint)
        notes = list(dict.fromkeys([*notes, *found]))  # each note once, in the order first given
        if not ok:
            break
        chosen = _choose(ctx, ok, settings)
        taken, replaced = _refit_chosen(ctx, current, chosen, settings)
        accepted.append(rc := replace(taken.ranked, accepted=True))
        ranking0 = _shown_accepted(ranking0, chosen.ranked, rc, replaced)
        current = _with_accepted(ctx, base, current, taken)
    return Selection(accepted, ranking0, current.residual, current.loss, current.mse, tuned, notes, cross, current.fit)


def _baseline(ctx: Context, base: Baseline, held: HeldOutBaseline) -> Current:
    """The first round's current model: the baseline, no effect accepted."""
    n = ctx.tr.y.shape[1]
    empty_tr, empty_ho = np.zeros((ctx.tr.y.shape[0], n, 0)), np.zeros((ctx.ho.y.shape[0], n, 0))
    return Current(base.fit, empty_tr, empty_ho, held.residual, held.loss, held.mse)


def _cross_fitted(ctx: Context, current: Current, folds: int) -> CrossFitted:
    """The current model (the baseline and the accepted effects) cross-fitted on the held-out folds."""
    X_tr = np.concatenate([ctx.tr.X0, current.acc_tr], axis=2)
    X_ho = np.concatenate([ctx.ho.X0, current.acc_ho], axis=2)
    return cross_fitted(ctx, current.fit, X_tr, X_ho, folds)


def _screen(
    ctx: Context,
    current: Current,
    groups: list[list[Candidate]],
    accepted: list[RankedCandidate],
    tuned: dict[int, Tuned],
) -> tuple[list[Scored], dict[int, Tuned]]:
    """Every candidate group not yet accepted, scored on top of the current model in its tuned variant
    (``tuned``: the groups tuned in earlier rounds); and the groups tuned here."""
    scored: list[Scored] = []
    new: dict[int, Tuned] = {}
    for gi, group in enumerate(groups):
        if any(
            a.candidate.effect == group[0].effect and a.candidate.joints == group[0].joints for a in accepted
        ):
            continue
        if gi not in tuned:
            new[gi] = tune(ctx, current.fit, group)
        cand, C_tr = tuned[gi] if gi in tuned else new[gi]
        scored.append(score(ctx, current, cand, C_tr, ctx.ho.columns(cand)))
    return scored, new


def _tested(
    ctx: Context, current: Current, scored: list[Scored], settings: DiagnosisSettings
) -> list[Scored]:
    """The round's candidates, the leading nonlinear ones refined, with their p-values corrected for the
    candidates tested, their significance and their rank by the training data's evidence; largest gain
    first."""
    # Two families at half the level each: all candidates, and those the training data alone rank
    # first.  Their evidence is taken on the columns tuned on training data, before the leaders (chosen
    # by their held-out gain) are refined: it must not touch the held-out noise the p-values come from.
    # (Refining keeps the list's order.)
    evidence = np.array([s.ranked.training_evidence for s in scored])
    if settings.refit and current.round < settings.max_effects:
        scored = refine_leaders(ctx, current, scored)
    p_adj = st.screened_holm([s.ranked.p_value for s in scored], evidence, settings.screen_top)
    rank = np.empty(len(scored), dtype=int)
    rank[np.argsort(evidence, kind="stable")] = np.arange(1, len(scored) + 1)
    tested = [
        replace(
            s,
            ranked=replace(
                s.ranked,
                p_holm=float(pa),
                significant=bool(pa < settings.alpha and s.ranked.gain >= settings.min_gain),
                training_rank=int(rk),
            ),
        )
        for s, pa, rk in zip(scored, p_adj, rank, strict=True)
    ]
    tested.sort(key=lambda s: -s.ranked.gain)
    return tested


def _acceptable(
    ctx: Context,
    current: Current,
    scored: list[Scored],
    settings: DiagnosisSettings,
    significant_joint: NDArray[np.bool_],
) -> tuple[list[Scored], list[str]]:
    """The significant candidates that close enough of their joints' gap, in the order given, and the
    notes on the timing mismatches too short to be taken as a delay."""
    n = ctx.tr.y.shape[1]
    # A candidate must close at least min_closure of the gap on its joints, and half of it where
    # those joints show no significant excess (the background state estimation leaves there).
    ok = [
        s
        for s in scored
        if s.ranked.significant
        and s.ranked.closure
        >= (
            settings.min_closure
            if significant_joint[list(s.ranked.candidate.scored or range(n))].any()
            else max(settings.min_closure, 0.5)
        )
    ]
    resolved, notes = [], []
    for s in ok:
        rc = s.ranked
        d = fitted_delay(ctx, current.fit, rc, s.C_tr) if rc.candidate.effect == "delay" else None
        if d is None or abs(d) >= ctx.min_delay:
            resolved.append(s)
            continue
        notes.append(
            f"{rc.candidate.label}: a timing mismatch of {1000 * d:.2g} ms, shorter than one sample "
            f"({1000 * ctx.min_delay:.2g} ms), is not told apart from the state estimation's phase error "
            "and not taken as a delay."
        )
    return resolved, notes


def _choose(ctx: Context, ok: list[Scored], settings: DiagnosisSettings) -> Scored:
    """Among the acceptable candidates, the one that mends the whole arm most, or a simpler one on the
    same joints that it does not beat significantly (:func:`~dynid.diagnosis.screening.parsimonious`)."""
    # A gain error on one joint leaks through the shared base parameters onto its neighbours, where a
    # same-shaped candidate on the neighbour scores nearly as well on its own joint alone.  All are
    # measured on the training footing (on_training): one footing, whichever decided each.
    ok = sorted(ok, key=lambda s: -on_training(s.ranked, "gain_all"))
    return parsimonious(ok, settings.alpha, ctx.block, settings.min_gain)


def _refit_chosen(
    ctx: Context, current: Current, chosen: Scored, settings: DiagnosisSettings
) -> tuple[Scored, bool]:
    """The chosen candidate refined (unless refining is off or it was refined as a leader), and whether
    the refit's columns replaced the screen's: they do when they gain at least as much on the training
    footing, the choice's figures (adjusted p-value, significance, evidence, confounding) kept."""
    rc = chosen.ranked
    if not settings.refit or "method" in rc.refit:
        return chosen, False
    cand, C_tr2, C_ho2, info = refine(ctx, current.fit, rc.candidate, chosen.C_tr)
    refit = score(ctx, current, cand, C_tr2, C_ho2)
    rc2 = refit.ranked
    if on_training(rc2, "gain") >= on_training(rc, "gain"):
        kept = replace(
            rc2,
            p_holm=rc.p_holm,
            significant=rc.significant,
            training_evidence=rc.training_evidence,
            training_rank=rc.training_rank,
            refit={**rc2.refit, **info},
            confounded_with=rc.confounded_with,
            angle_deg=rc.angle_deg,
        )
        return replace(refit, ranked=kept), True
    return replace(chosen, ranked=replace(rc, refit={**rc.refit, **info, "kept": KEPT})), False


def _shown_accepted(
    ranking: list[RankedCandidate], chosen: RankedCandidate, accepted: RankedCandidate, replaced: bool
) -> list[RankedCandidate]:
    """The ranking showing a candidate accepted: as chosen (with its refit note) unless a refit replaced
    it, and any entry of the same effect and joint(s)."""
    return [
        accepted
        if r0 is chosen and not replaced
        else (replace(r0, accepted=True) if r0.candidate.key == accepted.candidate.key else r0)
        for r0 in ranking
    ]


def _with_accepted(ctx: Context, base: Baseline, current: Current, taken: Scored) -> Current:
    """The current model with an accepted candidate's columns: the baseline refitted with every accepted
    effect, its held-out residual, loss and mean square (scored on no footing yet)."""
    acc_tr = np.concatenate([current.acc_tr, taken.C_tr], axis=2)
    acc_ho = np.concatenate([current.acc_ho, taken.C_ho], axis=2)
    xa, ba, _ = base.fit.solve(acc_tr)
    r = ctx.ho.y - predict(ctx.ho.X0, xa, acc_ho, ba)
    return Current(
        fit=WeightedFit(np.concatenate([ctx.tr.X0, acc_tr], axis=2), ctx.tr.y, base.weights),
        acc_tr=acc_tr,
        acc_ho=acc_ho,
        residual=r,
        loss=losses(r, ctx.sigma, ctx.mask),
        mse=mse(r, ctx.mask),
    )
