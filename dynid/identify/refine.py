"""The three layers fitted together: link parameters, friction and mixture experts in one least squares.

Fitted one after the other (METHOD.md section 4), the layers pass their errors down: layer 1 fits the
link parameters with a linear friction only, so whatever it cannot express (the nonlinear friction,
a smooth position-dependent torque) leaks into the link parameters wherever it correlates with their
columns along the training motion, and layers 2 and 3 then learn a residual that belongs to that
motion.  On a simulated UR5 (60 s at 1 kHz, the paper's friction, a 0.3 N m position ripple per joint)
the link part alone was off by 0.3 N m RMS on a held-out motion: the whole model did hardly better
than OLS (0.885 of its held-out RMS; the paper reports 0.64).

:func:`refine` therefore alternates, for a few rounds:

1. the friction model of each joint (its shape parameter, e.g. the seed model's threshold, by the
   search of :mod:`dynid.identify.friction`) on ``tau - link - correction``;
2. the mixture of each joint (:class:`dynid.identify.gmr.GMRCorrection`) on ``tau - link -
   friction``; it fixes the gates.  In the first round the size of each joint's mixture, and whether
   it has one at all, is chosen by validation of the joint fit (:func:`_select_mixtures`); in the later
   rounds a correction of the joint's own angle must also pass a direction check (fitted on the samples
   moving one way, it must predict those moving the other way);
3. one least squares over the link parameters, the friction coefficients that enter linearly (at
   the shape of step 1) and the local linear experts of the mixtures (at the gates of step 2).
   Per joint the friction and expert columns are eliminated (``I - N (N^T N + L)^-1 N^T``, with a
   ridge ``L`` of 1e-3 on the unit-norm expert columns only: where a smooth function of ``q_j`` and a
   link column coincide, as ``g cos q_2`` does, the link parameter takes it), then the link
   parameters solve the stacked projected system, each joint weighted by the inverse of its layer-1
   residual variance (OLS: all alike; the cross-joint correlation GLS and IRLS use is left out here);
   then friction (within its bounds) and experts per joint with the link parameters fixed.

Every column is treated like the torque: evaluated on the states at full rate, low-pass filtered,
taken at the kept samples (parallel filtering, DIAGNOSIS.md section 3), so the model predicts the
filtered torque as it is compared.  The physically consistent method projects the refined link
parameters onto the consistent set at the end (Mahalanobis metric of the refined fit) and refits
friction and experts for them.

The covariance of the refined link parameters is the sandwich of :mod:`dynid.identify.estimators`
on the projected system, with each joint's residual long-run variance factor.

Where the correction and a link column nearly coincide over the angles the training motion covered
(gravity ``cos q_2`` over a short range is nearly linear, so are the local experts), the fit splits
them in a way the data cannot check: right over those angles, wrong beyond them, where the correction
holds its edge value and the link part goes on (30 N m off on a UR5 shoulder 2 rad beyond 12 s of
training data).  Predictions are for the workspace the robot was identified in;
:meth:`dynid.identify.model.IdentifiedModel.predict` warns when a motion leaves it.  (A guard that
compared the link torque with and without corrections on random states switched off genuine
corrections as often as harmful ones, and was dropped.)
"""

from __future__ import annotations

import copy
import hashlib
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

from dynid._threads import single_blas_thread
from dynid.identify._qr import q_factor, r_factor
from dynid.identify.estimators import bounded_triangular, long_run_factor
from dynid.identify.friction import FrictionLayer, bounded_lsq
from dynid.identify.gmr import GMRCorrection, validation_mask
from dynid.identify.linear_system import LinearSystem

__all__ = ["RIDGE", "Refinement", "refine"]

RIDGE = 1e-3
"""Ridge on the unit-norm expert columns in the joint least squares."""
_TINY = 1e-10  # ridge on the friction columns (numerical safety only)
_MIN_IMPROVEMENT = 0.1  # relative drop of a joint's validation RMS needed to keep its correction


@dataclass(eq=False)
class Refinement:
    """What :func:`refine` returns.

    Attributes
    ----------
    params : ndarray, shape (p,)
        Identified parameters (the refined ones where ``mask``; layer 1's elsewhere).
    cov : ndarray, shape (p, p)
        Their covariance.
    mask : ndarray of bool, shape (p,)
        Parameters refined (link parameters, armature, and linear friction when it is layer 1's).
    friction : FrictionLayer or None
        The refitted friction layer (None for ``none`` or ``linear``).
    gmr : GMRCorrection or None
        The mixture with jointly fitted experts.
    residual : ndarray, shape (m, n)
        Filtered torque minus the whole model at the kept samples (N m).
    rms_layers : dict
        RMS per joint after the link part, after friction, after the correction (N m).
    info : dict
        Rounds, RMS per round, weights, correlation factors, consistent-projection figures.
    """

    params: NDArray[np.float64]
    cov: NDArray[np.float64]
    mask: NDArray[np.bool_]
    friction: FrictionLayer | None
    gmr: GMRCorrection | None
    residual: NDArray[np.float64]
    rms_layers: dict[str, list[float]]
    info: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True, eq=False)
class _LinkSolution:
    """The link step's least squares: the refined parameters and the factors of their projected system.

    ``R`` (p_sel, p_sel) is the triangular factor of the stacked, weighted, projected system; ``blocks``
    holds per joint the indices of its parameters and the triangular factor of its own weighted,
    projected rows, which the covariance sandwich needs.
    """

    x: NDArray[np.float64]
    R: NDArray[np.float64]
    blocks: list[tuple[NDArray[np.intp], NDArray[np.float64]]]


def _rms(r: NDArray[np.float64]) -> list[float]:
    return [float(v) for v in np.sqrt(np.mean(r**2, axis=0))]


def _per_joint(func: Callable[[int], Any], n: int) -> list[Any]:
    """``[func(0), ..., func(n - 1)]``, one joint after the other.

    Two threads, one joint each, were tried: the joints' steps are many small array operations, and the
    two threads mostly waited for each other's interpreter lock.  On the three real arms' default
    identifications (single BLAS thread, 2 cores) they cost 0.7-1.1 s more CPU and 0-0.7 s more wall
    time than this loop; the large filters, where threads do pay, keep them
    (:func:`dynid.identify.linear_system.build_system`).
    """
    return [func(j) for j in range(n)]


def _filtered(prep, designs: list[NDArray[np.float64]]) -> list[NDArray[np.float64]]:
    """Each full-rate design filtered like the torque, at the kept rows (empty designs just taken there)."""
    rows = prep.rows
    return _per_joint(
        lambda j: prep.filter(designs[j])[rows] if designs[j].shape[1] else designs[j][rows], len(designs)
    )


class _Columns:
    """Per joint, the refined parameters' columns at the kept rows: (indices into the mask, (m, k))."""

    def __init__(self, system: LinearSystem, mask: NDArray[np.bool_]) -> None:
        Z = system.data_matrix()  # the kept rows
        self.sel = np.flatnonzero(mask)
        where = -np.ones(system.p, dtype=np.intp)
        where[self.sel] = np.arange(len(self.sel))
        self.idx, self.W, self.tau = [], [], []
        for j in range(system.n):
            cols = np.flatnonzero((system.z_joint == j) & (system.z_param >= 0))
            cols = cols[mask[system.z_param[cols]]]
            self.idx.append(where[system.z_param[cols]])
            self.W.append(np.ascontiguousarray(Z[:, cols]))
            t = np.flatnonzero((system.z_joint == j) & (system.z_param < 0))[0]
            self.tau.append(np.ascontiguousarray(Z[:, t]))

    def torque(self, x_sel: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.column_stack([W @ x_sel[i] for W, i in zip(self.W, self.idx, strict=True)])

    def take(self, rows: NDArray[np.intp]) -> _Columns:
        """The same columns at ``rows`` of the kept samples only (copies)."""
        out = object.__new__(_Columns)
        out.sel, out.idx = self.sel, self.idx
        out.W = [W[rows] for W in self.W]
        out.tau = [t[rows] for t in self.tau]
        return out


@dataclass(frozen=True, eq=False)
class _Split:
    """The training and validation rows of :func:`_select_mixtures`, taken once for all its trials."""

    train: _Columns
    val: _Columns
    tau_train: NDArray[np.float64]
    tau_val: NDArray[np.float64]
    F_train: list[NDArray[np.float64]]
    F_val: list[NDArray[np.float64]]
    rows: tuple[NDArray[np.intp], NDArray[np.intp]]

    @classmethod
    def of(cls, C: _Columns, tau, Fb, train, val) -> _Split:
        return cls(
            C.take(train),
            C.take(val),
            tau[train],
            tau[val],
            [F[train] for F in Fb],
            [F[val] for F in Fb],
            (train, val),
        )


def _ridge_rows(
    N: NDArray[np.float64], ridge: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``[N / norms; diag(sqrt(ridge))]`` and the column norms (zero columns kept at norm 1).

    Ridge least squares on the unit-norm columns of N is plain least squares on these rows, with the
    target padded by one zero per column; the coefficients of N are the solution divided by ``norms``.
    """
    norms = np.linalg.norm(N, axis=0)
    norms[norms == 0] = 1.0
    return np.vstack([N / norms, np.diag(np.sqrt(ridge))]), norms


def _eliminator(N: NDArray[np.float64], ridge: NDArray[np.float64]):
    """Projection ``v - N (N^T N + L)^-1 N^T v`` (unit-norm columns, ridge L) as a function.

    ``proj(v, out=None)``: the projection of v (m,) or (m, k), written into ``out`` when given.
    """
    if N.shape[1] == 0:
        return lambda v, out=None: v if out is None else np.copyto(out, v) or out
    norms = np.linalg.norm(N, axis=0)
    norms[norms == 0] = 1.0
    m, k = N.shape
    A = np.empty((m + k, k), order="F")  # _ridge_rows(N, ridge)[0], built in the QR's layout
    np.divide(N, norms, out=A[:m])
    A[m:] = np.diag(np.sqrt(ridge))
    Q = q_factor(A)[:m]
    return lambda v, out=None: np.subtract(v, Q @ (Q.T @ v), out=out)


def _nuisance(
    N: NDArray[np.float64],
    target: NDArray[np.float64],
    ridge: NDArray[np.float64],
    lower: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Ridge least squares of ``target`` on the columns N, coefficients >= 0 where ``lower`` is finite."""
    if N.shape[1] == 0:
        return np.zeros(0)
    A, norms = _ridge_rows(N, ridge)
    b = np.concatenate([target, np.zeros(N.shape[1])])
    # the bounds are 0 or -inf, unchanged by the column scaling
    c, _ = bounded_lsq(A, b, tuple(float(v) for v in np.where(np.isfinite(lower), 0.0, -np.inf)))
    return c / norms


def refine(
    system: LinearSystem,
    x0: NDArray[np.float64],
    omega: NDArray[np.float64],
    *,
    friction: str,
    gmm: str | int,
    gmm_mode: str = "position",
    rounds: int = 2,
    weighting: str = "per-joint",
    consistent: dict[str, Any] | None = None,
    random_state: int = 0,
    lower: NDArray[np.float64] | None = None,
) -> Refinement:
    """Refit link parameters, friction and mixture experts together (see the module docstring).

    Parameters
    ----------
    system : LinearSystem
        The identification system, with its data matrix (``keep_samples=True``).
    x0 : ndarray, shape (p,)
        The layer-1 estimate to start from.
    omega : ndarray, shape (n, n)
        Layer-1 joint-noise covariance (its diagonal weighs the joints).
    friction : str
        Friction model, a name of :data:`~dynid.identify.registry.FRICTION_MODELS`; ``linear`` is the
        layer-1 friction, refined with the link parameters.
    gmm : "off" or "auto" or int
        Layer 3: off, size by validation, or a fixed number of components.
    gmm_mode : str
        Inputs of the mixtures (:class:`GMRCorrection` ``mode``).
    rounds : int
        Rounds of the alternation (at least 1).
    weighting : {"per-joint", "none"}
        Weigh each joint by the inverse of its layer-1 residual variance, or not (OLS).
    consistent : dict, optional
        Project the link parameters onto physically consistent ones at the end: the keyword arguments
        of :func:`dynid.identify.consistent.consistent_solution` (``reference_weight``, ``eps``, ...).
    random_state : int
        Seed of the mixtures' EM.
    lower : ndarray, shape (p,), optional
        Lower bound of each parameter (-inf: none), e.g.
        :func:`dynid.identify.estimators.physical_lower_bounds`; the link step then solves its least
        squares within them (bounded-variable least squares on its triangular factor).

    Returns
    -------
    Refinement
    """
    with single_blas_thread():
        return _refine(
            system, x0, omega, friction, gmm, gmm_mode, rounds, weighting, consistent, random_state, lower
        )


def _refine(
    system, x0, omega, friction, gmm, gmm_mode, rounds, weighting, consistent, random_state, lower=None
):
    cols = system.columns
    prep = system.prepared
    rows = prep.rows
    n, m = system.n, system.m
    layer2 = friction not in ("none", "linear")
    mask = cols.link_mask | (cols.friction_mask if friction == "linear" else False)
    key = ("refine-columns", mask.tobytes())
    C = system.derived.get(key)
    if C is None:  # the two refinements of a default identification take the same columns
        C = system.derived[key] = _Columns(system, mask)
    low = None if lower is None else np.asarray(lower, dtype=np.float64)[C.sel]
    tau = np.column_stack(C.tau)
    x_sel = np.asarray(x0, dtype=np.float64)[C.sel].copy()
    weights = 1.0 / np.maximum(np.diag(omega), 1e-300) if weighting == "per-joint" else np.ones(n)
    weights = weights / weights.mean()
    u_full = np.hstack([prep.q, prep.dq])
    u_kept = u_full[rows]
    layer: FrictionLayer | None = None
    gmr: GMRCorrection | None = None
    corr = np.zeros_like(tau)
    fric = np.zeros_like(tau)
    history = []
    Fb = [np.zeros((m, 0))] * n
    Gb = [np.zeros((m, 0))] * n
    link = C.torque(x_sel)  # the link torque of x_sel, kept up to date with it
    for _ in range(max(1, int(rounds))):
        if layer2:
            layer, Fb = _friction_step(system, friction, prep, tau - link - corr, layer)
            fric = np.column_stack([B @ mdl.linear_coef() for B, mdl in zip(Fb, layer.models_, strict=True)])
        if gmm != "off":
            r3 = tau - link - fric
            if gmr is None:  # first round: sizes and the guard, by validation of the joint fit
                gmr = _select_mixtures(
                    C, tau, Fb, u_kept, u_full, r3, gmm, gmm_mode, random_state, prep, weights
                )
                Gb = _filtered(prep, gmr.design(u_full))
            else:  # later rounds: the gates again, on the new residual, same sizes and joints
                gmr, Gb = _refit_mixtures(gmr, u_kept, u_full, r3, prep)
        step = _link_step(C, tau, Fb, Gb, weights, lower=low)
        x_sel = step.x
        link = C.torque(x_sel)
        fric, corr = _nuisance_step(C, tau, x_sel, Fb, Gb, layer, gmr, link)
        history.append(float(np.sqrt(np.mean((tau - link - fric - corr) ** 2))))

    info: dict[str, Any] = {"rounds": len(history), "rms_per_round": history, "weighting": weighting}
    if consistent is not None:
        resid = tau - link - fric - corr
        kappa, _ = long_run_factor(resid, prep.noise_correlation)
        scale2 = float(np.sum(weights * kappa * np.mean(resid**2, axis=0)) / n)
        x_sel, info["consistency"] = _consistent_step(system, C, x_sel, step.R, scale2, consistent, x0)
        info["consistency"]["rms_unprojected"] = _rms(resid)  # the training RMS before the projection
        link = C.torque(x_sel)
        fric, corr = _nuisance_step(C, tau, x_sel, Fb, Gb, layer, gmr, link)
        info["consistency"]["rms_projected"] = _rms(tau - link - fric - corr)
    resid = tau - link - fric - corr
    cov_sel, kappa = _covariance(step, resid, weights, prep.noise_correlation, Fb, Gb)
    info["correlation"] = [float(k) for k in kappa]
    x = np.asarray(x0, dtype=np.float64).copy()
    x[C.sel] = x_sel
    cov = np.zeros((cols.p, cols.p))
    cov[np.ix_(C.sel, C.sel)] = cov_sel
    return Refinement(
        params=x,
        cov=cov,
        mask=mask,
        friction=layer,
        gmr=gmr,
        residual=resid,
        rms_layers={"link": _rms(tau - link), "friction": _rms(tau - link - fric), "gmm": _rms(resid)},
        info=info,
    )


def _friction_step(system: LinearSystem, friction: str, prep, F, around: FrictionLayer | None):
    """Friction fitted on ``F`` (with a search near ``around``), and its filtered columns at the kept rows.

    A first round (no ``around``) is remembered per system and residual: the default identification
    refines twice from the same layer-1 estimate (with and without the mixtures, see
    :class:`dynid.identify.model.ThreeLayerModel`), and both first rounds fit the same friction to the
    same residual; the second one takes a copy of the first's result (a quarter of the friction
    searches of a default identification).
    """
    key = None
    if around is None:  # kept with the system's other derived arrays, until it is released
        key = ("first-friction", friction, hashlib.sha256(np.ascontiguousarray(F).tobytes()).digest())
        if key in system.derived:
            layer, Fb = system.derived[key]
            return copy.deepcopy(layer), Fb
    layer = FrictionLayer(model=friction).fit(prep.dq, F, prepared=prep, around=around)
    Fb = layer.filtered_basis(prep)  # the fit filtered them already
    if key is not None:
        system.derived[key] = (copy.deepcopy(layer), Fb)
    return layer, Fb


_SELECT_SAMPLES = 20_000  # training rows of the per-joint regressions that choose the mixture sizes
_SIZES = (1, 2, 3, 4, 6, 8)  # mixture sizes tried by gmm="auto"
_EM_SAMPLES = 4000  # samples (evenly strided) of each EM fit of the gates


def _joint_validation(split: _Split, Gb, weights) -> NDArray[np.float64]:
    """Per joint, the validation RMS of the joint fit (link, friction, experts) made on the training rows."""
    train, val = split.rows
    G_train, G_val = [G[train] for G in Gb], [G[val] for G in Gb]
    x_sel = _link_step(split.train, split.tau_train, split.F_train, G_train, weights).x

    def joint(j: int) -> float:
        idx = split.train.idx[j]
        target = split.tau_train[:, j] - split.train.W[j] @ x_sel[idx]
        ridges = _ridges(split.F_train[j], G_train[j])
        c = _nuisance_free(np.hstack([split.F_train[j], G_train[j]]), target, ridges)
        pred = split.val.W[j] @ x_sel[idx] + np.hstack([split.F_val[j], G_val[j]]) @ c
        return float(np.sqrt(np.mean((split.tau_val[:, j] - pred) ** 2)))

    return np.array(_per_joint(joint, len(split.train.W)), dtype=np.float64)


def _nuisance_free(N, target, ridge):
    """Ridge least squares of ``target`` on the columns N (no bounds)."""
    if N.shape[1] == 0:
        return np.zeros(0)
    A, norms = _ridge_rows(N, ridge)
    b = np.concatenate([target, np.zeros(N.shape[1])])
    return scipy.linalg.lstsq(A, b, cond=1e-12, check_finite=False)[0] / norms


def _select_mixtures(C, tau, Fb, u_kept, u_full, r3, gmm, mode, random_state, prep, weights) -> GMRCorrection:
    """Per joint, the mixture size (or none) whose experts, fitted jointly with the link parameters and
    friction on the training samples, predict that joint's validation samples best.

    The validation samples are phase windows of periodic data, else time blocks
    (:func:`dynid.identify.gmr.validation_mask`).  A joint keeps a correction only if it lowers its
    validation RMS by 10 % against the joint fit without any correction (with 2 %, a correction of
    up to 24 experts that fitted coloured noise on 10 s of simulated data passed, and tripled the
    held-out error of the UR5's shoulder joint).
    """
    n = len(C.W)
    val, how = validation_mask(u_kept, 20, 0.25)
    stride = max(1, -(-int((~val).sum()) // _SELECT_SAMPLES))
    train = np.flatnonzero(~val)[::stride]
    vrows = np.flatnonzero(val)[::stride]
    sizes = list(_SIZES) if gmm == "auto" else [int(gmm)]
    empty = [np.zeros((len(tau), 0))] * n
    split = _Split.of(C, tau, Fb, train, vrows)
    none = _joint_validation(split, empty, weights)
    best = np.full(n, np.inf)
    best_K = np.ones(n, dtype=int)
    stale = 0
    scores: list[list[tuple[int, float]]] = [[] for _ in range(n)]
    for K in sizes:
        # no range fade on the trials: the validation rows are inside the final mixture's states
        trial = GMRCorrection(
            mode=mode, random_state=random_state, max_samples=_EM_SAMPLES, range_margin=np.inf
        ).fit_mixtures(u_kept[train], r3[train], [K] * _mixtures(mode, n))
        G = _filtered(prep, trial.design(u_full))
        score = _joint_validation(split, G, weights)
        better = score < best
        for j in range(n):
            scores[j].append((K, float(score[j])))
        best_K[better], best[better] = K, score[better]
        stale = 0 if better.any() else stale + 1
        if stale >= 2:
            break
    active = best <= (1.0 - _MIN_IMPROVEMENT) * none
    sizes_final = [int(K) for K in best_K]
    if mode == "vector":
        sizes_final = [max(sizes_final)]
    gmr = GMRCorrection(mode=mode, random_state=random_state, max_samples=_EM_SAMPLES).fit_mixtures(
        u_kept, r3, sizes_final, active
    )
    gmr.scores_ = scores
    gmr.validation_rms_ = np.vstack([none, np.where(active, best, none)])
    gmr.validation_ = how
    gmr.direction_ratio_ = np.full(n, np.nan)
    if not active.all():
        off = [str(j + 1) for j in np.flatnonzero(~active)]
        gmr.fallback_ = (
            f"no correction for joint{'s' if len(off) > 1 else ''} {', '.join(off)}: on the validation samples "
            f"({how}) it did not lower the RMS of the joint fit by {100 * _MIN_IMPROVEMENT:g} %"
        )
    return gmr


def _direction_check(G, r, dq) -> float:
    """RMS ratio (with / without) of experts fitted on one direction of motion, tested on the other."""
    moving = np.abs(dq) > 1e-3 * np.abs(dq).max(initial=0.0)
    halves = [np.flatnonzero(moving & (dq > 0)), np.flatnonzero(moving & (dq < 0))]
    if min(len(h) for h in halves) < 10 * max(G.shape[1], 1):
        return 1.0
    err, ref = 0.0, 0.0
    for a, b in ((0, 1), (1, 0)):
        c = _nuisance_free(G[halves[a]], r[halves[a]], np.full(G.shape[1], RIDGE))
        err += float(np.sum((r[halves[b]] - G[halves[b]] @ c) ** 2))
        ref += float(np.sum(r[halves[b]] ** 2))
    return float(np.sqrt(err / ref)) if ref > 0 else 1.0


def _refit_mixtures(old: GMRCorrection, u_kept, u_full, r3, prep) -> tuple[GMRCorrection, list]:
    """The same sizes and joints, gates fitted again on a new residual; the direction check.

    Returns the mixture and its filtered design at the kept rows (:func:`_filtered` of ``design``):
    the direction check filters the active joints' designs, which the joint fit then takes as they are.

    A correction of ``position`` mode is a function of ``q_j`` alone, so it must hold whichever way the
    joint moves: experts fitted on the samples moving one way must predict those moving the other way
    (:func:`_direction_check`).  A joint whose residual fails that (an effect of velocity and position
    together, which no position-only correction can carry to another motion) loses its correction.
    The check needs the link parameters of a joint fit (the first round's): on the layer-1 residual,
    whose link parameters absorbed part of the effect along the training motion, true position
    effects failed it too.
    """
    new = GMRCorrection(mode=old.mode, random_state=old.random_state, max_samples=_EM_SAMPLES).fit_mixtures(
        u_kept, r3, list(old.n_components_), old.active_
    )
    for name in ("scores_", "validation_rms_", "validation_", "fallback_", "direction_ratio_"):
        setattr(new, name, getattr(old, name))
    design = new.design(u_full)
    Gb = _filtered(prep, design)
    if old.mode == "position":
        n = r3.shape[1]
        off = []
        for j in np.flatnonzero(new.active_):
            ratio = _direction_check(Gb[j], r3[:, j], u_kept[:, n + j])
            new.direction_ratio_[j] = ratio
            if ratio > 1.0 - _MIN_IMPROVEMENT:
                new.active_[j] = False
                Gb[j] = design[j][:, :0][prep.rows]  # no correction: what design() now gives, taken there
                off.append(str(j + 1))
        if off:
            note = (
                f"no correction for joint{'s' if len(off) > 1 else ''} {', '.join(off)}: fitted on one direction "
                "of motion it did not predict the other (the residual depends on the velocity too)"
            )
            new.fallback_ = note if new.fallback_ is None else f"{new.fallback_}; {note}"
    return new, Gb


def _mixtures(mode: str, n: int) -> int:
    return 1 if mode == "vector" else n


def _ridges(Fb: NDArray[np.float64], Gb: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.concatenate([np.full(Fb.shape[1], _TINY), np.full(Gb.shape[1], RIDGE)])


def _link_step(C: _Columns, tau, Fb, Gb, weights, rows=None, lower=None) -> _LinkSolution:
    """Link parameters of the stacked system with friction and experts eliminated per joint.

    ``rows``: fit on these samples only (the validation of :func:`_select_mixtures`); ``lower``: lower
    bounds of the refined parameters (bounded-variable least squares on the stacked factor).
    """
    p_sel = len(C.sel)
    if rows is not None:
        tau, Fb, Gb = tau[rows], [F[rows] for F in Fb], [G[rows] for G in Gb]

    def joint(j: int):
        N = np.hstack([Fb[j], Gb[j]])
        proj = _eliminator(N, _ridges(Fb[j], Gb[j]))
        k = len(C.idx[j])
        Ab = np.empty((len(tau), k + 1), order="F")  # the weighted, projected [W tau], in the QR's layout
        proj(C.W[j] if rows is None else C.W[j][rows], out=Ab[:, :k])
        proj(tau[:, j], out=Ab[:, k])
        Ab *= np.sqrt(weights[j])
        Rj = r_factor(Ab, overwrite=True)
        full = np.zeros((len(Rj), p_sel + 1))
        full[:, C.idx[j]] = Rj[:, :k]
        full[:, p_sel] = Rj[:, k]
        return full, (C.idx[j], Rj[:k, :k] if Rj.shape[0] >= k else Rj[:, :k])

    blocks, projected = zip(*_per_joint(joint, len(C.W)), strict=True)
    projected = list(projected)
    R = r_factor(np.vstack(blocks), overwrite=True)[:p_sel]
    if lower is None:
        x_sel = scipy.linalg.lstsq(R[:, :p_sel], R[:, p_sel], cond=1e-13, check_finite=False)[0]
    else:
        x_sel = bounded_triangular(R[:, :p_sel], R[:, p_sel], lower)
    return _LinkSolution(x=x_sel, R=R[:, :p_sel], blocks=projected)


def _nuisance_step(C: _Columns, tau, x_sel, Fb, Gb, layer, gmr, link=None):
    """Friction (within bounds) and experts per joint for fixed link parameters; their torques.

    ``link``: ``C.torque(x_sel)`` when the caller has it already.
    """
    n = len(C.W)
    fric = np.zeros_like(tau)
    corr = np.zeros_like(tau)
    f_coefs, g_coefs, noise = [], [], np.zeros(n)
    if link is None:
        link = C.torque(x_sel)

    def joint(j: int) -> NDArray[np.float64]:
        N = np.hstack([Fb[j], Gb[j]])
        lower = np.concatenate(
            [
                layer.models_[j].linear_bounds if layer is not None else np.zeros(0),
                np.full(Gb[j].shape[1], -np.inf),
            ]
        )
        return _nuisance(N, tau[:, j] - link[:, j], _ridges(Fb[j], Gb[j]), lower)

    for j, c in enumerate(_per_joint(joint, n)):
        kf = Fb[j].shape[1]
        f_coefs.append(c[:kf])
        g_coefs.append(c[kf:])
        fric[:, j] = Fb[j] @ c[:kf]
        corr[:, j] = Gb[j] @ c[kf:]
        noise[j] = float(np.mean((tau[:, j] - link[:, j] - fric[:, j] - corr[:, j]) ** 2))
    if layer is not None:
        layer.set_linear(f_coefs)
    if gmr is not None:
        gmr.set_experts(g_coefs, noise)
    return fric, corr


def _covariance(step: _LinkSolution, resid, weights, floor, Fb, Gb):
    """Sandwich covariance of the refined link parameters (see the module docstring)."""
    R, per_joint = step.R, step.blocks
    p_sel = R.shape[1]
    kappa, _ = long_run_factor(resid, floor)
    m = len(resid)
    middle = np.zeros((p_sel, p_sel))
    for j, (idx, Rj) in enumerate(per_joint):
        dof = max(m - Fb[j].shape[1] - Gb[j].shape[1] - len(idx), 1)
        s2 = float(resid[:, j] @ resid[:, j]) / dof
        block = np.zeros((Rj.shape[0], p_sel))
        block[:, idx] = Rj
        middle += weights[j] * kappa[j] * s2 * (block.T @ block)
    Rinv = scipy.linalg.pinv(R)
    cov = Rinv @ (Rinv.T @ middle @ Rinv) @ Rinv.T
    return 0.5 * (cov + cov.T), kappa


def _consistent_step(system, C: _Columns, x_sel, R, scale2, options, x0):
    """Project the refined link parameters onto physically consistent ones (Mahalanobis metric)."""
    from dynid.identify.consistent import consistent_projection

    cols = system.columns
    x_full = np.asarray(x0, dtype=np.float64).copy()
    x_full[C.sel] = x_sel
    mask = np.zeros(cols.p, dtype=bool)
    mask[C.sel] = True
    x_proj, phi, solver = consistent_projection(
        cols.robot, cols, x_full, R, max(scale2, 1e-300), mask=mask, **options
    )
    x_c = x_proj[mask]
    info = {
        "mahalanobis": float(np.linalg.norm(R @ (x_c - x_sel)) / np.sqrt(max(scale2, 1e-300))),
        "relative_distance": float(np.linalg.norm(x_c - x_sel) / max(np.linalg.norm(x_sel), 1e-300)),
        "standard_params": [float(v) for v in phi[: 10 * cols.n]],
        "solver": solver,
    }
    return x_c, info
