"""Screening of the candidate effects: each tuned on the training data and scored on the held-out data.

* :func:`tune`: the variant of a candidate (its hyper-parameters) with the lowest training RSS once
  refitted with the baseline; never tuned on held-out data.
* :func:`score`: the reduction of the held-out loss ``sum_j r_j^2 / sigma_j^2`` on the joints the
  candidate acts on, its closure of their gap, and a one-sided Diebold-Mariano test
  (:class:`~dynid.diagnosis.result.RankedCandidate`), on two footings: *training* (the candidate fitted
  with the current model on the training data, the test widened by the chance gain the refit's
  parameter error allows) and *cross-fitted* (:func:`cross_fitted`: both refitted on the training data
  and the other held-out folds, as the excess test judges the baseline).  A candidate passes on either:
  the smaller p-value, doubled (Bonferroni over the two footings), and the gain, closure and losses of
  the footing that gave it, which ``refit["footing"]`` records.  The current model a round scores on
  is a :class:`Current`; a scored candidate, with its columns and each footing's losses, a :class:`Scored`.
* :func:`parsimonious`: among acceptable candidates on the same joints, the simplest one the best does
  not beat significantly; candidates are compared with one another on the training footing
  (:func:`on_training`).
* :func:`confounding`: principal angles between the leading candidates once the baseline is projected
  out; :func:`confound_note` says which are not separable and what motion would separate them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from dynid.diagnosis import stats as st
from dynid.diagnosis.baseline import Side, StateNoise
from dynid.diagnosis.candidates import Candidate, excitation_hint
from dynid.diagnosis.crossfold import CrossFold
from dynid.diagnosis.fitting import WeightedFit, losses, mse, predict
from dynid.diagnosis.result import RankedCandidate
from dynid.exceptions import UsageError

__all__ = [
    "CROSS",
    "GAIN_CAP",
    "TRAINING",
    "Context",
    "CrossFitted",
    "Current",
    "Scored",
    "confound_note",
    "confounding",
    "cross_fitted",
    "on_training",
    "parsimonious",
    "score",
    "state_gain",
    "tune",
]

TRAINING = "training"
"""Footing name: the candidate fitted with the current model on the training data alone."""
CROSS = "cross-fitted"
"""Footing name: the candidate and the current model fitted on the training data and the other held-out folds."""
GAIN_CAP = 20.0
"""Cap of a block mean of a cross-fitted gain in its test (noise variances), as the excess test's."""


@dataclass(frozen=True, eq=False)
class Context:
    """What every candidate is scored against.

    Attributes
    ----------
    tr, ho : Side
        Training and held-out data with the baseline refit's torque.
    sigma : ndarray, shape (n,)
        Held-out noise floor per joint (N m).
    block : int
        Rows per block of the tests and covariances.
    mask : ndarray, shape (m, n)
        Held-out rows and joints that count (the joint moves).
    min_delay : float
        Shortest delay (s) told apart from the state estimation's phase error (one held-out sample).
    state : StateNoise or None
        Draws of the quantised angles' error through the held-out preparation
        (:func:`dynid.diagnosis.baseline.state_noise`): the gain a candidate makes on them is taken off its
        gain before it is tested (:func:`state_gain`); None for angles that are not quantised.
    alpha : float
        The tests' level: a candidate whose p-value is not below it without the state estimation's share
        is not measured for that share (it can only raise the p-value).
    """

    tr: Side
    ho: Side
    sigma: NDArray[np.float64]
    block: int
    mask: NDArray[np.float64]
    min_delay: float = 0.0
    state: StateNoise | None = None
    alpha: float = 0.05


def tune(ctx: Context, fit: WeightedFit, group: list[Candidate]) -> tuple[Candidate, NDArray[np.float64]]:
    """The variant of a candidate with the lowest training RSS (hyper-parameters tuned on training only)."""
    if not group:
        raise UsageError(
            "tune needs a group of at least one candidate variant; got none: give a non-empty group."
        )
    if group[0].effect == "cogging":
        group = _cogging_prescreen(ctx, fit, group)
    best: tuple[float, Candidate, NDArray[np.float64]] | None = None
    for cand in group:
        C = ctx.tr.columns(cand)
        rss = float(np.sum(fit.varpro_residual(C) ** 2))
        if best is None or rss < best[0]:
            best = (rss, cand, C)
    if best is None:  # the cogging prescreen keeps three variants: never empty
        raise UsageError(f"no variant of {group[0].label} to tune; give a group of at least one candidate.")
    return best[1], best[2]


def _cogging_prescreen(ctx: Context, fit: WeightedFit, group: list[Candidate]) -> list[Candidate]:
    """Gear ratios from the angle-domain spectrum of the training residual of the joint (fast scan)."""
    j = group[0].joint
    m, n = fit.shape
    r = fit.r0.reshape(m, n)[:, j]
    q = ctx.tr.src.q[ctx.tr.rows, j]
    ratios = np.arange(20.0, 241.0, 1.0)
    power = np.array([abs(np.mean(r * np.exp(-1j * N * q))) ** 2 for N in ratios])
    top = ratios[np.argsort(power)[::-1][:3]]
    return [replace(group[0], hyper={"N": float(N)}) for N in top]


@dataclass(frozen=True, eq=False)
class CrossFitted:
    """The current model cross-fitted on the held-out folds: what candidates are scored against there.

    Attributes
    ----------
    fold : CrossFold
        The current model (baseline and accepted effects) factored per held-out fold.
    residual : ndarray, shape (m, n)
        Its cross-fitted held-out residual (N m).
    mse : ndarray, shape (n,)
        Its mean square per joint over the moving rows (N^2 m^2).
    """

    fold: CrossFold
    residual: NDArray[np.float64]
    mse: NDArray[np.float64]


def cross_fitted(ctx: Context, fit: WeightedFit, X_tr, X_ho, folds: int) -> CrossFitted:
    """The current model cross-fitted per held-out fold.

    Parameters
    ----------
    ctx : Context
    fit : WeightedFit
        The current training fit (its weights are used).
    X_tr : ndarray, shape (m_tr, n, k)
        Training columns of the current model (baseline and accepted effects).
    X_ho : ndarray, shape (m, n, k)
        The same on the held-out rows.
    folds : int
        Contiguous held-out folds.
    """
    cf = CrossFold(X_tr, ctx.tr.y, fit.w, X_ho, ctx.ho.y, ctx.mask / ctx.sigma[None, :], folds)
    r = cf.residual()
    return CrossFitted(fold=cf, residual=r, mse=mse(r, ctx.mask))


@dataclass(frozen=True, eq=False)
class Current:
    """The model a round's candidates are scored on top of: the baseline and the effects accepted so far.

    Attributes
    ----------
    fit : WeightedFit
        Its training fit (the accepted effects' columns in its baseline).
    acc_tr, acc_ho : ndarray, shape (m_tr, n, a) and (m, n, a)
        The accepted effects' columns on the training and the held-out rows (``a = 0`` before any).
    residual : ndarray, shape (m, n)
        Its held-out residual (N m).
    loss : ndarray, shape (m,)
        Its per-sample held-out loss (noise variances).
    mse : ndarray, shape (n,)
        Its held-out mean square per joint (N^2 m^2).
    round : int
        The selection round (0: the baseline alone).
    cross : CrossFitted or None
        The same model cross-fitted on the held-out folds (:func:`cross_fitted`); None scores candidates on
        the training footing alone.
    """

    fit: WeightedFit
    acc_tr: NDArray[np.float64]
    acc_ho: NDArray[np.float64]
    residual: NDArray[np.float64]
    loss: NDArray[np.float64]
    mse: NDArray[np.float64]
    round: int = 0
    cross: CrossFitted | None = None


@dataclass(frozen=True, eq=False)
class Scored:
    """A scored candidate with what its score stands on.

    Attributes
    ----------
    ranked : RankedCandidate
        The score (on the footing that decided it).
    C_tr, C_ho : ndarray, shape (m_tr, n, c) and (m, n, c)
        Its columns on the training and the held-out rows.
    losses : dict of str to ndarray
        Per footing it was scored on, by name (:data:`TRAINING`, :data:`CROSS`): its per-sample held-out
        loss, shape (m, n), in noise variances.
    """

    ranked: RankedCandidate
    C_tr: NDArray[np.float64]
    C_ho: NDArray[np.float64]
    losses: dict[str, NDArray[np.float64]]


@dataclass(frozen=True, eq=False)
class _Footing:
    """One footing's figures for a candidate (see :func:`score`)."""

    name: str
    gain: float
    p_value: float
    closure: float
    gain_all: float
    mse_joint: NDArray[np.float64]
    loss: NDArray[np.float64]  # (m, n)
    quantised: float = 0.0  # the state estimation's share of the gain, taken off (noise variances)

    def summary(self) -> dict[str, float]:
        return {
            "gain": self.gain,
            "closure": self.closure,
            "p_value": self.p_value,
            "gain_all": self.gain_all,
            "state_estimation_gain": self.quantised,
        }


def _figures(ctx, name, r, r_cur, mse_cur, js, gain, p_value, quantised=(0.0, 0.0)) -> _Footing:
    mse_j = mse(r, ctx.mask)
    noise_var = ctx.sigma**2
    # In noise variances, as the loss: in N^2 m^2 a heavy joint's small background excess would outweigh
    # a light joint's large one (a coupled wrist: joint 5's 0.2x hid joint 6's 5.7x, closure 0.36).
    # What the candidate gains by cancelling the state estimation's error (``quantised``) is no effect's:
    # it is taken off the gain it closes as it is off the gain it is tested on.
    gap = float(np.sum((mse_cur[js] - noise_var[js]) / noise_var[js]))
    closed = float(np.sum((mse_cur[js] - mse_j[js]) / noise_var[js])) - quantised[1]
    closure = closed / gap if gap > 0 else float("nan")
    loss_joint = ctx.mask * (r / ctx.sigma[None, :]) ** 2
    gain_all = float(np.mean(losses(r_cur, ctx.sigma, ctx.mask) - np.sum(loss_joint, axis=1))) - quantised[0]
    return _Footing(name, float(gain), float(p_value), closure, gain_all, mse_j, loss_joint, quantised[0])


def score(
    ctx: Context, current: Current, cand: Candidate, C_tr: NDArray[np.float64], C_ho: NDArray[np.float64]
) -> Scored:
    """Held-out score of a candidate refitted with the current model: loss on the joints it acts on.

    On the training footing, the candidate is fitted with the current model on the training data, and
    the gain, closure and test are taken against ``current.residual`` (the current model's held-out
    residual on that fit).  With ``current.cross``, also on the cross-fitted footing (the candidate and
    the current model fitted on the training data and the other held-out folds, each fold predicted by
    the fit that did not see it, the gain taken against ``current.cross.residual``), and the candidate
    passes on either: its p-value is the smaller of the two doubled (Bonferroni), and its gain, closure,
    per-sample loss and ``gain_all`` are those of the footing that gave it.  ``refit["footing"]``
    records both footings' figures and which one decided; :attr:`Scored.losses` holds both footings'
    per-sample losses.

    The training footing is blind where the held-out motion leaves the training states: there the
    refit's parameter error, fixed over the run, hides an effect of the size of the noise.  The
    cross-fitted footing learns that error from the other folds, but on a short held-out run the
    baseline refitted on them can also take up an effect with its own parameters (a coupled friction
    with per-joint friction, on 3 s of a real TX40 wrist); neither footing sees all that the other does.
    """
    js = list(cand.scored) if cand.scored else list(range(len(ctx.sigma)))

    def footings(quantised: tuple[float, float]) -> tuple[list[_Footing], float]:
        training, evidence = _training_footing(ctx, current, js, C_tr, C_ho, quantised)
        feet = [training]
        if current.cross is not None:
            feet.append(_cross_footing(ctx, current.cross, js, C_tr, C_ho, quantised))
        return feet, evidence

    feet, evidence = footings((0.0, 0.0))
    # The state estimation's share only raises a p-value: it is measured where the test could pass.
    if ctx.state is not None and len(feet) * min(f.p_value for f in feet) < ctx.alpha:
        X_ho = np.concatenate([ctx.ho.X0, current.acc_ho], axis=2) if current.acc_ho.shape[2] else ctx.ho.X0
        feet, evidence = footings(state_gain(ctx, current.fit, cand, js, X_ho, C_tr, C_ho))
    ranked = _decided(feet, cand, current.round, int(C_tr.shape[2]), evidence)
    return Scored(ranked=ranked, C_tr=C_tr, C_ho=C_ho, losses={f.name: f.loss for f in feet})


def state_gain(
    ctx: Context, fit: WeightedFit, cand: Candidate, js: list[int], X_ho, C_tr, C_ho
) -> tuple[float, float]:
    """What a candidate gains on held-out data by cancelling the state estimation's error, with no effect
    behind it: per sample in noise variances (the test's unit), and summed over its joints' mean squares
    (the closure's unit).

    Angles differentiated twice leave an error ``s`` in the baseline's prediction, and so in the held-out
    residual, and an error ``c`` in every column built from the states (errors in the variables).  A
    candidate whose columns move with ``s`` fits part of it, on the training data as on the held-out data:
    refitted, it lowers the held-out loss by ``m^T G^-1 m`` (population least squares), with ``m`` the
    weighted cross moment of ``s`` and its net columns' error ``c - dX R`` (R: what the baseline absorbs of
    its columns) and ``G`` the moment matrix of its net held-out columns.  Both come from draws of the
    angles' error (:class:`~dynid.diagnosis.baseline.StateNoise`); the largest over the draws is taken,
    for the gain varies from one realisation of the error to the next more than within one run.  On an
    effect-free simulated UR5 with 16-bit angles, elasticity and backlash on joint 4 gained 0.93-0.95
    noise variances this way (none with exact angles), significant at adjusted p 1e-37 while closing a
    third of a gap that the excess test counts as noise; the angles' true error gave 0.91 by this formula,
    three draws 0.72-0.81 (a requantisation of the true angles on a shifted grid 1.1).

    Returns
    -------
    (per_sample, closure_units) : tuple of float
        Zeros without draws (angles not quantised).
    """
    state = ctx.state
    if state is None:
        return 0.0, 0.0
    R = fit.regress(C_tr)  # (k, c): the baseline's (and the accepted effects') share of the columns
    k0 = ctx.ho.X0.shape[2]
    net = C_ho - np.einsum("mnk,kc->mnc", X_ho, R)
    x0 = fit.solve()[0][:k0]
    w = ctx.mask[:, js] / ctx.sigma[js][None, :] ** 2
    scales = (np.full(len(js), 1.0 / w.shape[0]), 1.0 / np.maximum(np.sum(ctx.mask[:, js], axis=0), 1.0))
    best = (0.0, 0.0)
    for moved, dX in zip(state.sides, state.dX, strict=True):
        dnet = (moved.columns(cand) - C_ho) - np.einsum("mnk,kc->mnc", dX, R[:k0])
        s = np.einsum("mnk,k->mn", dX, x0)  # the baseline prediction's share of the draw (N m)
        out = []
        for scale in scales:
            ws = w * scale[None, :]
            m = np.einsum("mjc,mj,mj->c", dnet[:, js], ws, s[:, js])
            G = np.einsum("mjc,mj,mjd->cd", net[:, js], ws, net[:, js])
            out.append(max(float(m @ np.linalg.pinv(0.5 * (G + G.T), rcond=1e-10, hermitian=True) @ m), 0.0))
        if out[0] > best[0]:
            best = (out[0], out[1])
    return best


def _training_footing(
    ctx: Context, current: Current, js: list[int], C_tr, C_ho, quantised: tuple[float, float] = (0.0, 0.0)
) -> tuple[_Footing, float]:
    """The training footing's figures, and how strongly the training data alone point at the candidate:
    the log p-value of the Wald test of its coefficients, fitted on the training residual (the held-out
    data play no part).  ``quantised``: the gain and the closure's share that the state estimation's error
    gives the candidate (:func:`state_gain`), taken off."""
    fit = current.fit
    # ``fit`` already holds the accepted columns in its baseline; solve with the candidate alone.
    x, beta, _ = fit.solve(C_tr)
    X_ho = np.concatenate([ctx.ho.X0, current.acc_ho], axis=2) if current.acc_ho.shape[2] else ctx.ho.X0
    r = ctx.ho.y - predict(X_ho, x, C_ho, beta)
    # The refit moves every joint's prediction a little (shared base parameters); scoring the joints the
    # candidate acts on keeps that variance out of the test.
    L = losses(r[:, js], ctx.sigma[js], ctx.mask[:, js])
    L_cur = losses(current.residual[:, js], ctx.sigma[js], ctx.mask[:, js])
    chance_var, V_beta = _chance_variance(ctx, fit, js, X_ho, C_tr, C_ho)
    dm = st.diebold_mariano(L_cur - quantised[0], L, block=ctx.block, extra_variance=max(chance_var, 0.0))
    footing = _figures(ctx, TRAINING, r, current.residual, current.mse, js, dm.mean, dm.p_value, quantised)
    return footing, st.wald_logp(beta, V_beta)


def _chance_variance(
    ctx: Context, fit: WeightedFit, js: list[int], X_ho, C_tr, C_ho
) -> tuple[float, NDArray[np.float64]]:
    """The variance the refit's parameter error adds to the training footing's gain, and the block
    covariance of the candidate's coefficients.

    The refit's parameter error, fixed over the whole held-out run, lets any column that moves the
    baseline mend (or spoil) the held-out prediction by chance: the gain's variance gets that term,
    4 tr(V_beta G C G^T), with G the held-out cross moment of the candidate's net prediction change and
    the baseline columns, C and V_beta the block covariances of the baseline and of the candidate's
    coefficients (independent: the candidate is fitted on the baseline's training residual).
    """
    net = C_ho - np.einsum("mnk,kc->mnc", X_ho, fit.regress(C_tr))
    w = ctx.mask[:, js] / ctx.sigma[js][None, :] ** 2
    G = np.einsum("mjc,mj,mjk->ck", net[:, js], w, X_ho[:, js]) / X_ho.shape[0]
    cov = np.nan_to_num(fit.covariance(ctx.block))
    V_beta = fit.projected_covariance(C_tr, ctx.block)
    return 4.0 * float(np.trace(V_beta @ G @ cov @ G.T)), V_beta


def _cross_footing(
    ctx: Context, cross: CrossFitted, js: list[int], C_tr, C_ho, quantised: tuple[float, float] = (0.0, 0.0)
) -> _Footing:
    """The cross-fitted footing's figures: the candidate and the current model refitted per held-out fold
    (``quantised`` as in :func:`_training_footing`)."""
    r_cf = cross.fold.residual(C_tr, C_ho)
    L_cf = losses(r_cf[:, js], ctx.sigma[js], ctx.mask[:, js])
    L_cf_cur = losses(cross.residual[:, js], ctx.sigma[js], ctx.mask[:, js])
    # The fold fits leave no fixed parameter error to widen the test with (each fold's own estimation
    # error enters its losses, serially correlated within the fold: the blocks).  An aperiodic run
    # shows an effect on a few moves, so block means of the gain are capped from above as the excess
    # test's are (the test stays valid; a few large blocks no longer swamp its variance).
    dm_cf = st.diebold_mariano(L_cf_cur - quantised[0], L_cf, block=ctx.block, cap=GAIN_CAP)
    gain_cf = float(np.mean(L_cf_cur - L_cf)) - quantised[0]
    return _figures(ctx, CROSS, r_cf, cross.residual, cross.mse, js, gain_cf, dm_cf.p_value, quantised)


def _decided(
    feet: list[_Footing], cand: Candidate, rnd: int, n_columns: int, evidence: float
) -> RankedCandidate:
    """The candidate's score on the footing with the smaller p-value (doubled when there are two)."""
    # Ties go to the training footing (listed first): it is the one the model's own refit stands on.
    by = min(feet, key=lambda f: f.p_value if math.isfinite(f.p_value) else 1.0)
    refit: dict = {}
    if len(feet) > 1:
        refit = {
            "footing": {"decided_by": by.name, "tests": len(feet), **{f.name: f.summary() for f in feet}}
        }
    return RankedCandidate(
        candidate=cand,
        gain=by.gain,
        closure=by.closure,
        p_value=min(1.0, len(feet) * by.p_value),
        round=rnd,
        mse_joint=by.mse_joint,
        gain_all=by.gain_all,
        loss=by.loss,
        n_columns=n_columns,
        refit=refit,
        training_evidence=evidence,
    )


def on_training(rc: RankedCandidate, key: str) -> float:
    """A scored candidate's ``gain``, ``closure`` or ``gain_all`` on the training footing.

    Candidates are compared with one another on that one footing (the choice among the acceptable ones,
    the simpler-candidate test, a refit against the screen's columns): gains on the cross-fitted
    footing are taken against a smaller residual, so a candidate decided there would otherwise lose to
    one decided on the training footing that mends less on both (a UR5's nonlinear viscous friction at
    1x went to Stribeck, which gained less on either footing).  Its own figure when no footing is
    recorded (scored on the training footing alone).
    """
    return float(rc.refit.get("footing", {}).get(TRAINING, {}).get(key, getattr(rc, key)))


def parsimonious(ok: list[Scored], alpha: float, block: int, min_gain: float) -> Scored:
    """The best acceptable candidate, or the simplest one on the same joints that it does not beat
    significantly (held-out loss on the joints either scores).

    ``ok`` holds the acceptable candidates, best first; two are compared on their training footing's
    per-sample losses (:attr:`Scored.losses`), the footing every candidate is compared on
    (:func:`on_training`).

    A richer candidate whose columns contain a simpler one's must also beat it by ``min_gain`` noise
    variances per sample: an armature is nested in the spring and dead-zone candidates (their
    motor-inertia column), which edged it out by 0.05 with a DM p of 0.002."""
    best = ok[0]
    rb = best.ranked
    simpler = sorted(
        (
            s
            for s in ok[1:]
            if s.ranked.candidate.joints == rb.candidate.joints and s.ranked.n_columns < rb.n_columns
        ),
        key=lambda s: s.ranked.n_columns,
    )
    n = rb.loss.shape[1]
    lb = best.losses.get(TRAINING, rb.loss)
    for s in simpler:
        js = sorted(set(s.ranked.candidate.scored or range(n)) | set(rb.candidate.scored or range(n)))
        ls = s.losses.get(TRAINING, s.ranked.loss)
        dm = st.diebold_mariano(ls[:, js].sum(axis=1), lb[:, js].sum(axis=1), block=block)
        if dm.p_value > alpha or (dm.mean < min_gain and _nested(s.C_tr, best.C_tr)):
            return s
    return best


def _nested(C_small: NDArray[np.float64], C_big: NDArray[np.float64], tol: float = 1e-6) -> bool:
    """Whether the columns C_small (m, n, a) lie in the span of C_big (m, n, b)."""
    A = C_big.reshape(-1, C_big.shape[2])
    B = C_small.reshape(-1, C_small.shape[2])
    coef, *_ = np.linalg.lstsq(A, B, rcond=None)
    return bool(np.linalg.norm(B - A @ coef) <= tol * max(float(np.linalg.norm(B)), 1e-300))


def confounding(fit: WeightedFit, scored: list[Scored], confound_deg: float) -> list[Scored]:
    """The scored candidates with, for the leading ones, their principal angle to the nearest other once
    the baseline is projected out, and the candidates they are not separable from (angle below
    ``confound_deg``, gain at least half their own).

    Parameters
    ----------
    fit : WeightedFit
        The current fit (its columns are projected out).
    scored : list of Scored
        The scored candidates, best first.
    confound_deg : float
        Angle (degrees) below which two candidates are not separable.
    """
    top = [i for i, s in enumerate(scored[:8]) if s.ranked.gain > 0]
    proj = [(scored[i].ranked, fit.projected(scored[i].C_tr)) for i in top]
    out = list(scored)
    for i, (ri, Pi) in zip(top, proj, strict=True):
        best = None
        confounded = list(ri.confounded_with)
        for rk, Pk in proj:
            if rk is ri or (
                rk.candidate.effect == ri.candidate.effect and rk.candidate.joints == ri.candidate.joints
            ):
                continue
            ang = math.degrees(float(st.principal_angles(Pi, Pk)[0]))
            if best is None or ang < best:
                best = ang
            if ang < confound_deg and rk.gain >= 0.5 * ri.gain:
                confounded.append(rk.candidate.key)
        out[i] = replace(out[i], ranked=replace(ri, confounded_with=confounded, angle_deg=best))
    return out


def confound_note(r: RankedCandidate) -> str:
    c = r.candidate
    others = ", ".join(r.confounded_with)
    return (
        f"{c.label} is not separable with this excitation from {others} (principal angle {r.angle_deg:.1f} deg "
        f"once the base regressor is projected out); to separate them, record {excitation_hint(c)}, and "
        "separately the motion that excites the other."
    )
