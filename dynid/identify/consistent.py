"""Physically consistent identification of the link parameters.

Every link's standard parameters must describe a real body: mass > 0 and the pseudo-inertia

    J = [[Sigma, h], [h^T, m]],   Sigma = tr(I)/2 * 1 - I,   h = m c   (about the joint frame)

positive definite, which implies the triangle inequalities of the inertia.  dynid asks for a margin,
``J >= eps I`` (eps = 1e-6 in SI units by default: a body whose second moments all lie below 1e-6
kg m^2 is a point, not a link; lowered per link to half the smallest eigenvalue of its URDF body when
that is smaller, so the URDF always qualifies).

Objective: the weighted least squares of layer 1, written with its triangular factor (no data left
in the problem, p x p numbers):

    || R (x(phi) - x_hat) ||^2 / sigma^2  +  w * sum_l D(J_l || J_l,ref)

with ``x = P phi`` the identified parameters of the physical vector ``phi = [pi, ia, fc, fv, fo]``,
``x_hat`` the unconstrained estimate, ``R`` its whitened factor and ``sigma^2`` its residual
variance: the first term is the Mahalanobis distance from the unconstrained estimate (it differs
from the residual sum of squares by a constant, so the minimiser is the weighted least-squares one).
The optional second term pulls toward the URDF (CAD) bodies with the log-det divergence
``D(J || J_ref) = tr(J_ref^-1 J) - log det(J_ref^-1 J) - 4``, unit-free and zero only at ``J_ref``.
Armature, Coulomb and viscous friction are kept non-negative; offsets are free.

How it is solved
----------------
The problem is convex: a quadratic (plus the convex divergence) over the affine preimage of
positive semidefinite cones.  The variables are ``y = R (x - x_hat) / sigma`` (so the data term is
``||y||^2``) and ``w``, coordinates of the standard-parameter directions the data cannot see (the null
space of ``P``); ``phi`` is affine in ``(y, w)``.  A pull ``1e-6 ||w - w_start||^2`` (1e-6 of the data
term's unit curvature) picks, among the bodies with the same identified parameters, the one nearest
the start (the vector closest to the URDF bodies), so the solution is unique.  A primal log-barrier
method (Boyd & Vandenberghe, ch. 11) minimises ``f - mu sum log det(J_l - eps_l I) - mu sum log(bounds)``
by Newton steps with a backtracking line search from a strictly feasible start, dividing ``mu`` by 10
until the duality gap ``nu mu`` falls below ``tol`` times the objective: typically 100-200 Newton steps
of a few milliseconds each.

An earlier version searched over log-Cholesky factors of each ``J`` with IPOPT.  That parametrisation
is not convex, and where the closest consistent body lies on the boundary (an inconsistent
unconstrained estimate) the factor's diagonal drifts to -inf; IPOPT stopped at its 1000-iteration limit
on 8 of 10 such UR5 problems (2 s each) with its own objective still 1e-6 to 1e-3 above the optimum.
When the unconstrained estimate already has an eps-consistent standard vector, it is returned as it is.

:func:`consistent_solution` runs in four phases: the start (:func:`_search_start`), the problem in the
variables ``(y, w)`` with a strictly feasible point (:func:`_barrier_problem`), the barrier iterations
(:func:`_central_path`), and the answer (the links held at the bound, then the bodies nearest the
description).  The pseudo-inertia algebra and :func:`described_bodies` live in
:mod:`dynid.identify.bodies`; their names stay importable from here.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

from dynid.data.preparation import Preprocessing
from dynid.exceptions import IdentificationWarning, UsageError
from dynid.identify.bodies import (
    EPS,
    add_link_terms,
    clip_eigenvalues,
    described_bodies,
    is_consistent,
    link_inertials,
    log_cholesky,
    neg_logdet_terms,
    newton_direction,
    physical_scale,
    pseudo_inertia,
    reference_bodies,
    standard_from_pseudo_inertia,
    trace_gradient,
)
from dynid.identify.columns import EXTRA_KINDS, ColumnSet
from dynid.identify.estimators import ESTIMATORS, LinkEstimator
from dynid.identify.linear_system import LinearSystem

_RHO = 1e-6  # weight of the vanishing pull toward the starting bodies (fixes the directions data do not see)
_MU_FACTOR = 0.1  # barrier weight decrease per centring
# multiplier (squared std per relative loosening) above which a link is held at the bound: measured 6-2000 on
# UR5 links the data push against the bound, at most 5e-4 where only the pull of the unseen directions does
_BOUND_FORCE = 0.05
__all__ = [
    "EPS",
    "ConsistentLS",
    "consistent_projection",
    "consistent_solution",
    "described_bodies",
    "is_consistent",
    "link_inertials",
    "log_cholesky",
    "pseudo_inertia",
    "standard_from_pseudo_inertia",
]


class ConsistentLS(LinkEstimator):
    """Weighted least squares over physically consistent links (a log-barrier method over the
    pseudo-inertias' cones, see the module docstring).

    Parameters
    ----------
    robot : RobotModel
        The robot that recorded the data.
    weighting : {"ols", "wls", "gls", "irls"}
        Layer-1 estimator whose weighting (and unconstrained estimate) the fit uses.
    friction : bool
        Identify linear friction with the link parameters (Coulomb and viscous kept >= 0).
    armature : bool
        Identify the armature (kept >= 0).
    preprocessing : Preprocessing, optional
        Filtering and differentiation of a dataset.
    reference_weight : float
        Weight ``w`` of the pull toward the URDF bodies (0: none; the standard parameters are then one
        consistent set among many with the same base parameters).
    eps : float
        Margin of consistency: every pseudo-inertia keeps ``J >= eps I`` (SI units, kg m^2 for its
        inertial block; default 1e-6).  For a link whose URDF body is itself closer to the boundary,
        half its smallest eigenvalue is used instead, so the URDF body always qualifies.
    tol : float
        Stop when the barrier's duality gap is below ``tol`` times the objective.
    max_iter : int
        Most Newton steps.

    Attributes
    ----------
    params_ : ndarray, shape (p,)
        Consistent identified parameters (base parameters, armature, friction).
    standard_ : ndarray, shape (10 n,)
        Standard parameters of every link (consistent).
    extras_ : ndarray, shape (4 n,)
        Armature, Coulomb, viscous, offset per joint (zero where not identified).
    pseudo_inertias_ : ndarray, shape (n, 4, 4)
        Pseudo-inertia of every link.
    min_eigenvalues_ : ndarray, shape (n,)
        Smallest eigenvalue of each pseudo-inertia (>= eps: consistent with the margin).
    unconstrained_ : LinkEstimator
        The layer-1 fit it started from; ``cov_``, ``std_`` and ``std_percent_`` are its figures
        (valid where no constraint is active).
    distance_ : dict
        How far the consistent estimate is from the unconstrained one: ``relative``
        (``||x - x_hat|| / ||x_hat||``), ``mahalanobis`` (in standard deviations), ``rms_change``
        (N m per joint) and ``rms_ratio``.
    solver_ : dict
        The solver's status, Newton steps and time (0 steps: the unconstrained estimate was already
        consistent and is returned unchanged).
    """

    method = "consistent"

    def __init__(
        self,
        *,
        robot,
        weighting: str = "irls",
        friction: bool = True,
        armature: bool = True,
        preprocessing: Preprocessing | None = None,
        reference_weight: float = 0.0,
        eps: float = EPS,
        tol: float = 1e-8,
        max_iter: int = 1000,
    ) -> None:
        super().__init__(robot=robot, friction=friction, armature=armature, preprocessing=preprocessing)
        self.weighting = weighting
        self.reference_weight = reference_weight
        self.eps = eps
        self.tol = tol
        self.max_iter = max_iter

    def _fit_system(self, system: LinearSystem) -> None:
        if self.weighting not in ESTIMATORS:
            raise UsageError(f"weighting is {self.weighting!r}; choose one of {', '.join(ESTIMATORS)}")
        if not self.reference_weight >= 0:
            raise UsageError(f"reference_weight is {self.reference_weight!r}; give a number >= 0")
        if not self.eps >= 0:
            raise UsageError(
                f"eps is {self.eps!r}; give the smallest pseudo-inertia eigenvalue, >= 0 (kg m^2)"
            )
        unc = ESTIMATORS[self.weighting](
            robot=self.robot, friction=self.friction, armature=self.armature, preprocessing=self.preprocessing
        )
        unc._fit_system(system)
        cols = system.columns
        n, p = cols.n, cols.p
        sol = unc.solution_
        R, x_hat = sol.R, unc.params_
        sigma2 = sol.rss / max(system.m * n - p, 1)
        power = (float(sol.rhs @ sol.rhs) + sol.rss) / (system.m * n)
        phi_opt, solver = consistent_solution(
            self.robot,
            cols,
            x_hat,
            R,
            max(sigma2, 1e-8 * power, 1e-300),
            reference_weight=self.reference_weight,
            eps=self.eps,
            tol=self.tol,
            max_iter=self.max_iter,
        )
        self._finish(system, unc, phi_opt, x_hat, sigma2, R, solver, exact=solver["iterations"] == 0)

    def _finish(self, system, unc, phi_opt, x_hat, sigma2, R, solver, *, exact: bool = False) -> None:
        cols = system.columns
        n = cols.n
        x_c = x_hat.copy() if exact else cols.P @ phi_opt

        # figures
        J_all = pseudo_inertia(phi_opt[: 10 * n].reshape(n, 10))
        rms_c = system.rms(x_c)
        maha = float(np.linalg.norm(R @ (x_c - x_hat)) / np.sqrt(max(sigma2, 1e-300)))
        self.unconstrained_ = unc
        for name in (
            "cov_",
            "std_",
            "std_percent_",
            "cond_",
            "omega_",
            "sigma2_",
            "whitener_",
            "solution_",
            "R_",
            "rhs_",
            "rss_",
        ):
            setattr(self, name, getattr(unc, name))
        self.params_ = x_c
        self.names_ = cols.names
        self.expressions_ = cols.expressions
        self.rms_ = rms_c
        self.n_samples_ = system.m
        self.notes_ = cols.notes
        self.columns_ = cols
        self.preprocessing_ = system.prepared.settings
        self.standard_ = phi_opt[: 10 * n]
        self.extras_ = phi_opt[10 * n :]
        self.pseudo_inertias_ = J_all
        self.min_eigenvalues_ = np.array([np.linalg.eigvalsh(J).min() for J in J_all])
        self.distance_ = {
            "relative": float(np.linalg.norm(x_c - x_hat) / max(np.linalg.norm(x_hat), 1e-300)),
            "mahalanobis": maha,
            "rms_change": rms_c - unc.rms_,
            "rms_ratio": rms_c / np.where(unc.rms_ > 0, unc.rms_, 1.0),
        }
        self.solver_ = solver

    def summary(self) -> list[dict[str, Any]]:
        """One row per parameter (value consistent; std from the unconstrained fit)."""
        return super().summary()


def consistent_solution(
    robot,
    cols: ColumnSet,
    x_hat: NDArray[np.float64],
    R: NDArray[np.float64],
    scale2: float,
    *,
    mask: NDArray[np.bool_] | None = None,
    reference_weight: float = 0.0,
    eps: float = EPS,
    tol: float = 1e-8,
    max_iter: int = 1000,
    describe: bool = True,
) -> tuple[NDArray[np.float64], dict[str, Any]]:
    """The physical vector closest to an unconstrained estimate among eps-consistent ones.

    Minimises ``|| R (P phi - x_hat) ||^2 / scale2 + w sum_l D(J_l || J_l,ref)`` (plus a vanishing
    pull of the unidentifiable directions toward the start) over physical vectors
    ``phi = [pi, ia, fc, fv, fo]`` with ``J_l >= eps_l I`` and armature, Coulomb and viscous friction
    ``>= 0``: a convex problem, solved by a primal log-barrier method with Newton steps (see
    :class:`ConsistentLS`).

    Parameters
    ----------
    robot : RobotModel
        The robot (its URDF bodies start the search and define the reference).
    cols : ColumnSet
        The identified parameters.
    x_hat : ndarray, shape (p,)
        Unconstrained estimate of the identified parameters.
    R : ndarray, shape (k, k)
        Upper-triangular factor of its weighted least-squares problem over the ``k`` parameters in
        ``mask`` (``|| R (x - x_hat) ||^2`` is the increase of the weighted residual sum of squares).
    scale2 : float
        Residual variance the distance is divided by (a Mahalanobis distance when ``R`` is whitened).
    mask : ndarray of bool, shape (p,), optional
        Identified parameters the estimate and ``R`` cover (default all).  Extras held by none of
        them are zero.
    reference_weight : float
        Weight ``w`` of the log-det pull toward the URDF bodies.
    eps : float
        Smallest eigenvalue each pseudo-inertia keeps (SI units: kg m^2 for the inertial block),
        lowered for a link to half the smallest eigenvalue of its URDF body if that is smaller.
    tol : float
        Duality-gap tolerance of the barrier method, relative to the objective (at least 1).
    max_iter : int
        Most Newton steps in all.
    describe : bool
        Among the bodies with the found identified parameters, return those nearest the description
        (:func:`described_bodies`; default).  False skips that step (the identified parameters are
        the same; a cross-validation that needs only them saves its time).

    Returns
    -------
    phi : ndarray, shape (14 n,)
        The physical vector found.
    solver : dict
        ``status`` ("converged", "max_iter", or "unconstrained estimate is consistent"),
        ``iterations`` (Newton steps; 0: the estimate itself was eps-consistent and is returned as
        it is), ``time_s``, ``eps`` (the margin used per link, kg m^2) and ``at_bound`` (1-based links
        whose consistency constraint holds the fit away from the unconstrained estimate).
    """
    started = time.perf_counter()
    start = _search_start(robot, cols, x_hat, mask, eps)
    if start.consistent and reference_weight == 0:
        # x_hat has an eps-consistent standard vector: it is the (weighted least-squares) answer itself;
        # the description decides the bodies in the directions it leaves open.
        status = "unconstrained estimate is consistent"
        return _answer(robot, cols, start, start.phi0, status, 0, [], describe=describe, started=started)
    problem = _barrier_problem(start, R, scale2, reference_weight)
    path = _central_path(problem, tol=tol, max_iter=max_iter)
    if path.status != "converged":
        warnings.warn(
            f"the consistent fit stopped after {path.steps} Newton steps before its tolerance; the result is "
            "consistent but may not be the closest one: raise max_iter or tol",
            IdentificationWarning,
            stacklevel=4,
        )
    phi_opt = np.zeros(14 * start.n)
    phi_opt[problem.act] = problem.c0 + problem.G @ path.v
    e = 10 * start.n + start.e_idx
    phi_opt[e] = np.maximum(phi_opt[e], start.lb_e)
    at_bound = _links_at_bound(problem, start, path)
    return _answer(
        robot, cols, start, phi_opt, path.status, path.steps, at_bound, describe=describe, started=started
    )


@dataclass(frozen=True)
class _SearchStart:
    """Phase 1 of :func:`consistent_solution`: where the search starts, and the margins it keeps.

    ``phi0`` is the vector with ``x = x_hat`` closest to the URDF in a per-parameter scale ``D``
    (masses move relative to the mass, inertias relative to the inertia, friction in N m).
    """

    n: int
    mask: NDArray[np.bool_]  # identified parameters the estimate covers
    P: NDArray[np.float64]  # their rows of the map from the physical vector
    xm: NDArray[np.float64]  # the estimate of them
    D: NDArray[np.float64]  # (14 n,) scale of each physical parameter
    phi0: NDArray[np.float64]  # (14 n,) the start
    J_ref: NDArray[np.float64]  # (n, 4, 4) the URDF's pseudo-inertias
    eps_l: NDArray[np.float64]  # (n,) margin per link
    J_ref_pd: NDArray[np.float64]  # (n, 4, 4) the described pseudo-inertias, safely positive definite
    e_idx: NDArray[np.intp]  # extras in play, indices into the 4 n extras
    lb_e: NDArray[np.float64]  # their lower bounds (0, or -inf for an offset)
    e_scale: NDArray[np.float64]  # their scale

    @property
    def consistent(self) -> bool:
        """Every start body is inside its margin and every extra at or above its bound."""
        n = self.n
        return all(
            np.linalg.eigvalsh(pseudo_inertia(self.phi0[10 * k : 10 * k + 10])).min() > self.eps_l[k]
            for k in range(n)
        ) and np.all(self.phi0[10 * n + self.e_idx] >= self.lb_e)


def _search_start(robot, cols: ColumnSet, x_hat, mask, eps) -> _SearchStart:
    """Phase 1: the start closest to the URDF among the vectors with the estimated parameters."""
    n = cols.n
    mask = np.ones(cols.p, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    P = cols.P[mask]
    xm = np.asarray(x_hat, dtype=np.float64)[mask]
    # extras in play: enabled ones that some parameter of the mask holds
    enabled = cols.enabled_extras & np.any(P[:, 10 * n :] != 0, axis=0)
    phi_ref = np.concatenate([robot.params, robot.armature * enabled[:n], np.zeros(3 * n)])
    D = physical_scale(phi_ref, n)
    phi0 = phi_ref + D * np.linalg.lstsq(P * D, xm - P @ phi_ref, rcond=None)[0]
    eps_l, J_ref_pd = reference_bodies(robot.params, eps)
    e_idx = np.flatnonzero(enabled)
    kinds = [EXTRA_KINDS[e // n] for e in e_idx]
    lb_e = np.array([-np.inf if k == "offset" else 0.0 for k in kinds])
    e0 = np.maximum(phi0[10 * n + e_idx], lb_e)
    e_scale = np.maximum(np.abs(e0), max(1e-2 * float(np.abs(e0).max(initial=0.0)), 1e-6))
    return _SearchStart(
        n=n,
        mask=mask,
        P=P,
        xm=xm,
        D=D,
        phi0=phi0,
        J_ref=pseudo_inertia(robot.params.reshape(n, 10)),
        eps_l=eps_l,
        J_ref_pd=J_ref_pd,
        e_idx=e_idx,
        lb_e=lb_e,
        e_scale=e_scale,
    )


@dataclass(frozen=True)
class _BarrierProblem:
    """Phase 2 of :func:`consistent_solution`: the convex problem in the variables ``v = (y, w)``.

    ``y = R (x - x_hat) / sigma`` is the whitened change of the identified parameters (the data term is
    ``||y||^2``), ``w`` the coordinates of the directions ``P`` does not see (its null space, in the
    per-parameter scale); the physical parameters in play are ``phi[act] = c0 + G v``.
    """

    act: NDArray[np.intp]  # physical parameters in play: every link's, then the extras in play
    c0: NDArray[np.float64]
    G: NDArray[np.float64]
    v0: NDArray[np.float64]  # a strictly feasible start
    weight: NDArray[np.float64]  # of (v - centre)^2: 1 for y, _RHO for w
    centre: NDArray[np.float64]
    lower: NDArray[np.bool_]  # extras in play with a finite lower bound
    Ge: NDArray[np.float64]  # their rows of G
    lbe: NDArray[np.float64]  # their bounds
    se: NDArray[np.float64]  # their scale
    shift: NDArray[np.float64]  # (n, 4, 4): eps_l I
    reference_weight: float
    Jr_inv: NDArray[np.float64]  # (n, 4, 4): inverses of the described pseudo-inertias
    logdet_ref: NDArray[np.float64]
    prior_grad: NDArray[np.float64]  # the gradient of the pull's trace term (constant)

    @property
    def nu(self) -> int:
        """The barrier parameter: 4 per pseudo-inertia, 1 per bound."""
        return 4 * len(self.shift) + int(self.lower.sum())

    def distance(self, v):
        """The data term and the vanishing pull: ``sum weight (v - centre)^2``."""
        return float(np.sum(self.weight * (v - self.centre) ** 2))

    def bodies(self, v):
        """The pseudo-inertias at ``v`` and the slack of the bounded extras."""
        n = len(self.shift)
        pa = self.c0 + self.G @ v
        return pseudo_inertia(pa[: 10 * n].reshape(n, 10)), pa[10 * n :][self.lower] - self.lbe

    def value(self, v, mu):
        """The barrier objective at ``v`` (inf outside the feasible set)."""
        Js, slack = self.bodies(v)
        if np.any(slack <= 0):
            return np.inf
        out = self.distance(v) - mu * float(np.sum(np.log(slack / self.se)))
        try:
            L = np.linalg.cholesky(Js - self.shift)
        except np.linalg.LinAlgError:
            return np.inf
        out -= 2 * mu * float(np.log(np.diagonal(L, axis1=1, axis2=2)).sum())
        if self.reference_weight > 0:
            sign, logdet = np.linalg.slogdet(Js)
            if np.any(sign <= 0):
                return np.inf
            out += self.reference_weight * float(
                np.sum(np.einsum("lab,lba->l", self.Jr_inv, Js) - logdet + self.logdet_ref - 4)
            )
        return out

    def newton_step(self, v, mu):
        """The Newton step at ``v`` and its decrement."""
        Js, slack = self.bodies(v)
        grad = 2 * self.weight * (v - self.centre) + self.prior_grad
        hess = np.diag(2 * self.weight)
        g, H = neg_logdet_terms(Js - self.shift)  # the barrier's and the pull's, mapped to v together
        g, H = mu * g, mu * H
        if self.reference_weight > 0:
            g_ref, H_ref = neg_logdet_terms(Js)
            g += self.reference_weight * g_ref
            H += self.reference_weight * H_ref
        add_link_terms(self.G, g, H, grad, hess)
        grad -= mu * (self.Ge.T @ (1.0 / slack))
        hess += mu * (self.Ge.T / slack**2) @ self.Ge
        step = newton_direction(hess, grad)
        return step, float(-grad @ step)


def _barrier_problem(start: _SearchStart, R, scale2: float, reference_weight: float) -> _BarrierProblem:
    """Phase 2: the variables, the map to the physical vector, and a strictly feasible start."""
    n, e_idx = start.n, start.e_idx
    act = np.concatenate([np.arange(10 * n), 10 * n + e_idx])
    D_a = start.D[act]
    Uk, sk, Vkt = np.linalg.svd(start.P[:, act] * D_a, full_matrices=True)
    rank = int(np.sum(sk > 1e-12 * sk[0]))
    to_psi = (Vkt[:rank].T / sk[:rank]) @ Uk[:, :rank].T  # minimum-norm psi = phi / D of an x
    V2 = Vkt[rank:].T
    sigma = float(np.sqrt(scale2))
    Rinv = scipy.linalg.solve_triangular(R, np.eye(len(R)), check_finite=False)
    G = np.hstack([D_a[:, None] * (to_psi @ (sigma * Rinv)), D_a[:, None] * V2])  # phi_a = c0 + G v
    ny, nv = len(start.xm), G.shape[1]
    lower = np.isfinite(start.lb_e)
    phi_f = _interior_point(start, lower)
    Jr_inv = np.linalg.inv(start.J_ref_pd)
    return _BarrierProblem(
        act=act,
        c0=D_a * (to_psi @ start.xm),
        G=G,
        v0=np.concatenate([R @ (start.P[:, act] @ phi_f[act] - start.xm) / sigma, V2.T @ (phi_f[act] / D_a)]),
        weight=np.concatenate([np.ones(ny), np.full(nv - ny, _RHO)]),
        centre=np.concatenate([np.zeros(ny), V2.T @ (start.phi0[act] / D_a)]),
        lower=lower,
        Ge=G[10 * n :][lower],
        lbe=start.lb_e[lower],
        se=start.e_scale[lower],
        shift=start.eps_l[:, None, None] * np.eye(4),
        reference_weight=reference_weight,
        Jr_inv=Jr_inv,
        logdet_ref=np.linalg.slogdet(start.J_ref_pd)[1],
        prior_grad=(
            reference_weight * trace_gradient(Jr_inv, G)
            if reference_weight > 0
            else np.zeros(nv)
        ),
    )


def _interior_point(start: _SearchStart, lower: NDArray[np.bool_]) -> NDArray[np.float64]:
    """A strictly feasible physical vector: the start bodies pushed inside by 1 % of their size, extras too."""
    n, e_idx = start.n, start.e_idx
    phi_f = start.phi0.copy()
    for link in range(n):
        margin = start.eps_l[link] + 1e-2 * max(float(np.linalg.eigvalsh(start.J_ref[link]).max()), 1e-6)
        Jf = clip_eigenvalues(pseudo_inertia(phi_f[10 * link : 10 * link + 10]), margin)
        phi_f[10 * link : 10 * link + 10] = standard_from_pseudo_inertia(Jf)
    floor = np.where(lower, start.lb_e + 1e-2 * start.e_scale, -np.inf)
    phi_f[10 * n + e_idx] = np.maximum(phi_f[10 * n + e_idx], floor)
    return phi_f


@dataclass(frozen=True)
class _CentralPath:
    """Phase 3 of :func:`consistent_solution`: where the barrier method stopped."""

    v: NDArray[np.float64]
    mu: float  # the last barrier weight
    steps: int  # Newton steps in all
    status: str  # "converged" or "max_iter"


def _central_path(problem: _BarrierProblem, *, tol: float, max_iter: int) -> _CentralPath:
    """Phase 3: centring by damped Newton steps, dividing the barrier weight until the gap is closed."""
    v, nu = problem.v0, problem.nu
    mu = max(problem.distance(v) / nu, 1e-6)
    steps, status = 0, "converged"
    while True:
        while steps < max_iter:  # centring: damped Newton with a backtracking line search
            step, decrement = problem.newton_step(v, mu)
            steps += 1
            f0, t = problem.value(v, mu), 1.0
            if decrement <= 1e-9 * max(1.0, abs(f0)):
                break
            while problem.value(v + t * step, mu) > f0 - 0.25 * t * decrement:
                t *= 0.5
                if t < 1e-10:  # no descent left at rounding level: centred as well as it can be
                    break
            if t < 1e-10:
                break
            v = v + t * step
        if steps >= max_iter:
            status = "max_iter"
            break
        if nu * mu <= float(tol) * max(1.0, problem.distance(v)):
            break
        mu *= _MU_FACTOR
    return _CentralPath(v=v, mu=mu, steps=steps, status=status)


def _links_at_bound(problem: _BarrierProblem, start: _SearchStart, path: _CentralPath) -> list[int]:
    """Phase 4: the 1-based links whose consistency constraint holds the fit.

    A link is held at the bound when its constraint carries a multiplier the data feel: the barrier's
    multiplier mu (J - eps I)^-1, times the body's size, is the fall of the distance (in squared standard
    deviations) per relative loosening of the bound.  The vanishing pull of the unseen directions toward
    the start leaves multipliers of order _RHO; the data's are of order one.
    """
    at_bound = []
    Js, _ = problem.bodies(path.v)
    for link, J in enumerate(Js):
        size = max(float(np.linalg.eigvalsh(start.J_ref_pd[link]).max()), 1e-6)
        # (with a pull toward the description, whose log-det keeps every body off the bound, none is)
        lam = path.mu * float(np.linalg.eigvalsh(np.linalg.inv(J - start.eps_l[link] * np.eye(4))).max())
        if lam * size > _BOUND_FORCE:
            at_bound.append(link + 1)
    return at_bound


def _answer(
    robot,
    cols: ColumnSet,
    start: _SearchStart,
    phi: NDArray[np.float64],
    status: str,
    iterations: int,
    at_bound: list[int],
    *,
    describe: bool,
    started: float,
) -> tuple[NDArray[np.float64], dict[str, Any]]:
    """Phase 4: the bodies nearest the description (unless ``describe`` is False) and the solver's record.

    ``started`` is the :func:`time.perf_counter` reading when the solution began.
    """
    prior = {}
    if describe:
        phi, prior = described_bodies(robot, cols, phi, mask=start.mask, eps=start.eps_l)
    return phi, {
        "status": status,
        "iterations": iterations,
        "time_s": time.perf_counter() - started,
        "eps": start.eps_l.tolist(),
        "at_bound": at_bound,
        "prior": prior,
    }


def consistent_projection(
    robot,
    cols: ColumnSet,
    x_hat: NDArray[np.float64],
    R: NDArray[np.float64],
    scale2: float,
    *,
    mask: NDArray[np.bool_] | None = None,
    **options: Any,
) -> tuple[NDArray[np.float64], NDArray[np.float64], dict[str, Any]]:
    """The identified parameters closest to an estimate whose links are physically consistent.

    :func:`consistent_solution` on the parameters that belong to the physical vector; the others in
    ``mask`` (effect terms, which no body holds) are eliminated first (their Schur complement gives the
    metric of the rest) and refitted afterwards given the projected ones, so the distance is the
    weighted least-squares one over all of them.

    Parameters
    ----------
    robot : RobotModel
        The robot.
    cols : ColumnSet
        The identified parameters.
    x_hat : ndarray, shape (p,)
        Unconstrained estimate.
    R : ndarray, shape (k, k)
        Upper-triangular factor of the weighted least-squares problem over the ``k`` parameters in
        ``mask``, in the order of ``x_hat``.
    scale2 : float
        Residual variance the distance is divided by.
    mask : ndarray of bool, shape (p,), optional
        Parameters the estimate and ``R`` cover (default all).
    **options
        Keywords of :func:`consistent_solution` (``reference_weight``, ``eps``, ``tol``, ``max_iter``, ``describe``).

    Returns
    -------
    x : ndarray, shape (p,)
        The projected estimate (``x_hat`` itself where its links are consistent already).
    phi : ndarray, shape (14 n,)
        The consistent physical vector (standard parameters of every link, then the extras).
    solver : dict
        As :func:`consistent_solution` returns it.
    """
    x_hat = np.asarray(x_hat, dtype=np.float64)
    mask = np.ones(cols.p, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    idx = np.flatnonzero(mask)
    free = ~np.any(cols.P[idx] != 0, axis=1)  # in mask order: parameters no body or extra holds
    x = x_hat.copy()
    if not free.any():
        phi, solver = consistent_solution(robot, cols, x_hat, R, scale2, mask=mask, **options)
        if solver["iterations"]:
            x[mask] = cols.P[mask] @ phi
        return x, phi, solver
    H = R.T @ R
    s, e = ~free, free
    Hee_inv_Hes = np.linalg.lstsq(H[np.ix_(e, e)], H[np.ix_(e, s)], rcond=None)[0]
    schur = H[np.ix_(s, s)] - H[np.ix_(s, e)] @ Hee_inv_Hes
    w, V = np.linalg.eigh(0.5 * (schur + schur.T))
    root = np.sqrt(np.maximum(w, 1e-14 * max(float(w.max(initial=0.0)), 1e-300)))[:, None] * V.T
    R_s = np.linalg.qr(root, mode="r")  # upper triangular with R_s^T R_s = schur
    mask_s = np.zeros(cols.p, dtype=bool)
    mask_s[idx[s]] = True
    phi, solver = consistent_solution(robot, cols, x_hat, R_s, scale2, mask=mask_s, **options)
    if solver["iterations"]:
        xs = cols.P[mask_s] @ phi
        x[idx[e]] = x_hat[idx[e]] - Hee_inv_Hes @ (xs - x_hat[idx[s]])
        x[idx[s]] = xs
    return x, phi, solver
