"""Screening of the candidate effects: each tuned on the training data and scored on the held-out data.

* :func:`tune`: the variant of a candidate (its hyper-parameters) with the lowest training RSS once
  refitted with the baseline; never tuned on held-out data.
* :func:`score`: the reduction of the held-out loss ``sum_j r_j^2 / sigma_j^2`` on the joints the
  candidate acts on, its closure of their gap, and a one-sided Diebold-Mariano test widened by the chance
  gain the refit's parameter error allows (:class:`~dynid.diagnosis.result.RankedCandidate`).
* :func:`parsimonious`: among acceptable candidates on the same joints, the simplest one the best does
  not beat significantly.
* :func:`confounding`: principal angles between the leading candidates once the baseline is projected
  out; :func:`confound_note` says which are not separable and what motion would separate them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from dynid.diagnosis import stats as st
from dynid.diagnosis.baseline import Side
from dynid.diagnosis.candidates import Candidate, excitation_hint
from dynid.diagnosis.fitting import WeightedFit, losses, mse, predict
from dynid.diagnosis.result import RankedCandidate
from dynid.exceptions import UsageError

__all__ = ["Context", "confound_note", "confounding", "parsimonious", "score", "tune"]


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
    """

    tr: Side
    ho: Side
    sigma: NDArray[np.float64]
    block: int
    mask: NDArray[np.float64]
    min_delay: float = 0.0


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


def score(ctx, fit: WeightedFit, acc_tr, acc_ho, C_tr, C_ho, cand, r_cur, mse_cur, rnd) -> RankedCandidate:
    """Held-out score of a candidate refitted with the current model: loss on the joints it acts on."""
    # ``fit`` already holds the accepted columns in its baseline; solve with the candidate alone.
    x, beta, _ = fit.solve(C_tr)
    X_ho = np.concatenate([ctx.ho.X0, acc_ho], axis=2) if acc_ho.shape[2] else ctx.ho.X0
    r = ctx.ho.y - predict(X_ho, x, C_ho, beta)
    js = list(cand.scored) if cand.scored else list(range(len(ctx.sigma)))
    # The refit moves every joint's prediction a little (shared base parameters); scoring the joints the
    # candidate acts on keeps that variance out of the test.
    L = losses(r[:, js], ctx.sigma[js], ctx.mask[:, js])
    L_cur = losses(r_cur[:, js], ctx.sigma[js], ctx.mask[:, js])
    # The refit's parameter error, fixed over the whole held-out run, lets any column that moves the
    # baseline mend (or spoil) the held-out prediction by chance: the gain's variance gets that term,
    # 4 tr(V_beta G C G^T), with G the held-out cross moment of the candidate's net prediction change and
    # the baseline columns, C and V_beta the block covariances of the baseline and of the candidate's
    # coefficients (independent: the candidate is fitted on the baseline's training residual).
    net = C_ho - np.einsum("mnk,kc->mnc", X_ho, fit.regress(C_tr))
    w = ctx.mask[:, js] / ctx.sigma[js][None, :] ** 2
    G = np.einsum("mjc,mj,mjk->ck", net[:, js], w, X_ho[:, js]) / X_ho.shape[0]
    cov = np.nan_to_num(fit.covariance(ctx.block))
    chance_var = 4.0 * float(np.trace(fit.projected_covariance(C_tr, ctx.block) @ G @ cov @ G.T))
    dm = st.diebold_mariano(L_cur, L, block=ctx.block, extra_variance=max(chance_var, 0.0))
    mse_j = mse(r, ctx.mask)
    noise_var = ctx.sigma**2
    # In noise variances, as the loss: in N^2 m^2 a heavy joint's small background excess would outweigh
    # a light joint's large one (a coupled wrist: joint 5's 0.2x hid joint 6's 5.7x, closure 0.36).
    gap = float(np.sum((mse_cur[js] - noise_var[js]) / noise_var[js]))
    closure = float(np.sum((mse_cur[js] - mse_j[js]) / noise_var[js]) / gap) if gap > 0 else float("nan")
    loss_joint = ctx.mask * (r / ctx.sigma[None, :]) ** 2
    gain_all = float(np.mean(losses(r_cur, ctx.sigma, ctx.mask) - np.sum(loss_joint, axis=1)))
    return RankedCandidate(
        candidate=cand,
        gain=dm.mean,
        closure=closure,
        p_value=dm.p_value,
        round=rnd,
        mse_joint=mse_j,
        gain_all=gain_all,
        loss=loss_joint,
        n_columns=int(C_tr.shape[2]),
    )


def parsimonious(ok: list, alpha: float, block: int, min_gain: float):
    """The best acceptable candidate, or the simplest one on the same joints that it does not beat
    significantly (held-out loss on the joints either scores).

    A richer candidate whose columns contain a simpler one's must also beat it by ``min_gain`` noise
    variances per sample: an armature is nested in the spring and dead-zone candidates (their
    motor-inertia column), which edged it out by 0.05 with a DM p of 0.002."""
    best = ok[0]
    rb = best[1]
    simpler = sorted(
        (s for s in ok[1:] if s[1].candidate.joints == rb.candidate.joints and s[1].n_columns < rb.n_columns),
        key=lambda s: s[1].n_columns,
    )
    n = rb.loss.shape[1]
    for s in simpler:
        js = sorted(set(s[1].candidate.scored or range(n)) | set(rb.candidate.scored or range(n)))
        dm = st.diebold_mariano(s[1].loss[:, js].sum(axis=1), rb.loss[:, js].sum(axis=1), block=block)
        if dm.p_value > alpha or (dm.mean < min_gain and _nested(s[2], best[2])):
            return s
    return best


def _nested(C_small: NDArray[np.float64], C_big: NDArray[np.float64], tol: float = 1e-6) -> bool:
    """Whether the columns C_small (m, n, a) lie in the span of C_big (m, n, b)."""
    A = C_big.reshape(-1, C_big.shape[2])
    B = C_small.reshape(-1, C_small.shape[2])
    coef, *_ = np.linalg.lstsq(A, B, rcond=None)
    return bool(np.linalg.norm(B - A @ coef) <= tol * max(float(np.linalg.norm(B)), 1e-300))


def confounding(fit: WeightedFit, scored: list, confound_deg: float) -> list:
    """The scored candidates with, for the leading ones, their principal angle to the nearest other once
    the baseline is projected out, and the candidates they are not separable from (angle below
    ``confound_deg``, gain at least half their own).

    Parameters
    ----------
    fit : WeightedFit
        The current fit (its columns are projected out).
    scored : list of (int, RankedCandidate, ndarray, ndarray)
        Group index, score, training and held-out columns; best first.
    confound_deg : float
        Angle (degrees) below which two candidates are not separable.
    """
    top = [i for i, s in enumerate(scored[:8]) if s[1].gain > 0]
    proj = [(scored[i][1], fit.projected(scored[i][2])) for i in top]
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
        gi, _, C_tr, C_ho = out[i]
        out[i] = (gi, replace(ri, confounded_with=confounded, angle_deg=best), C_tr, C_ho)
    return out


def confound_note(r: RankedCandidate) -> str:
    c = r.candidate
    others = ", ".join(r.confounded_with)
    return (
        f"{c.label} is not separable with this excitation from {others} (principal angle {r.angle_deg:.1f} deg "
        f"once the base regressor is projected out); to separate them, record {excitation_hint(c)}, and "
        "separately the motion that excites the other."
    )
