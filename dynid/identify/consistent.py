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
"""

from __future__ import annotations

import time
import warnings
from typing import Any

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from dynid.data.preparation import Preprocessing
from dynid.exceptions import IdentificationWarning, UsageError
from dynid.identify.columns import EXTRA_KINDS, ColumnSet
from dynid.identify.estimators import ESTIMATORS, LinkEstimator
from dynid.identify.linear_system import LinearSystem

_RHO = 1e-6  # weight of the vanishing pull toward the starting bodies (fixes the directions data do not see)
_MU_FACTOR = 0.1  # barrier weight decrease per centring
# multiplier (squared std per relative loosening) above which a link is held at the bound: measured 6-2000 on
# UR5 links the data push against the bound, at most 5e-4 where only the pull of the unseen directions does
_BOUND_FORCE = 0.05
# pull of the armature and friction toward their description, relative to the links' divergence: a base
# parameter that holds a link's inertia and an armature together (joint 1's axis) leaves the link at its
# description and the armature takes the rest
_EXTRA_PULL = 1e-3
EPS = 1e-6
"""Default smallest eigenvalue (SI, kg m^2) of a consistent pseudo-inertia (see :class:`ConsistentLS`)."""
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


def pseudo_inertia(params: ArrayLike) -> NDArray[np.float64]:
    """Pseudo-inertia matrices of standard parameters.

    Parameters
    ----------
    params : array_like, shape (10,) or (k, 10)
        ``[m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`` per link (kg, kg m, kg m^2).

    Returns
    -------
    ndarray, shape (4, 4) or (k, 4, 4)
    """
    p = np.asarray(params, dtype=np.float64)
    single = p.ndim == 1
    p = p.reshape(-1, 10)
    J = (p @ _E_FLAT).reshape(-1, 4, 4)  # J is linear in the parameters: sum_i params_i E_i
    return J[0] if single else J


def _basis() -> NDArray[np.float64]:
    """(10, 4, 4): the pseudo-inertia of each unit standard parameter."""
    E = np.zeros((10, 4, 4))
    for i, (a, b) in enumerate([(3, 3), (0, 3), (1, 3), (2, 3)]):
        E[i, a, b] = E[i, b, a] = 1.0
    # inertia entries [Ixx, Ixy, Iyy, Ixz, Iyz, Izz]: Sigma = tr(I)/2 * 1 - I
    for i, (a, b) in zip(range(4, 10), [(0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2)], strict=True):
        if a == b:
            E[i, :3, :3] = 0.5 * np.eye(3)
            E[i, a, a] -= 1.0
        else:
            E[i, a, b] = E[i, b, a] = -1.0
    return E


_E = _basis()  # (10, 4, 4): J = sum_i params_i _E[i]
_E_FLAT = _E.reshape(10, 16)


def standard_from_pseudo_inertia(J):
    """Standard parameters ``[m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`` of a pseudo-inertia.

    Works on numpy arrays of shape (4, 4) and on CasADi matrices alike.

    Parameters
    ----------
    J : ndarray or casadi.SX, shape (4, 4)
        Pseudo-inertia.
    """
    S = J[0:3, 0:3]
    tr = S[0, 0] + S[1, 1] + S[2, 2]
    return [
        J[3, 3],
        J[0, 3],
        J[1, 3],
        J[2, 3],
        tr - S[0, 0],
        -S[0, 1],
        tr - S[1, 1],
        -S[0, 2],
        -S[1, 2],
        tr - S[2, 2],
    ]


def log_cholesky(J: ArrayLike) -> NDArray[np.float64]:
    """The 10 log-Cholesky parameters of a positive definite pseudo-inertia (``J = U U^T``).

    Parameters
    ----------
    J : array_like, shape (4, 4)
        Positive definite pseudo-inertia.
    """
    J = np.asarray(J, dtype=np.float64)
    Lf = np.linalg.cholesky(J[::-1, ::-1])
    U = Lf[::-1, ::-1]
    return np.array(
        [
            np.log(U[0, 0]),
            U[0, 1],
            U[0, 2],
            U[0, 3],
            np.log(U[1, 1]),
            U[1, 2],
            U[1, 3],
            np.log(U[2, 2]),
            U[2, 3],
            np.log(U[3, 3]),
        ]
    )


def _project_pd(J: NDArray[np.float64], floor: float) -> NDArray[np.float64]:
    """Nearest matrix with eigenvalues >= floor (symmetric eigenvalue clipping)."""
    w, V = np.linalg.eigh(0.5 * (J + J.T))
    return (V * np.maximum(w, floor)) @ V.T


def _phi_scale(phi_ref: NDArray[np.float64], n: int) -> NDArray[np.float64]:
    """Typical size of each physical parameter (kg, kg m, kg m^2, N m...), for a scaled minimum norm."""
    out = np.ones(14 * n)
    for link in range(n):
        v = phi_ref[10 * link : 10 * link + 10]
        m = max(abs(v[0]), 1e-3)
        inertia = max(abs(v[4]) + abs(v[6]) + abs(v[9]), 1e-2 * m) / 3
        out[10 * link] = m
        out[10 * link + 1 : 10 * link + 4] = np.maximum(np.abs(v[1:4]), 0.05 * m)
        out[10 * link + 4 : 10 * link + 10] = np.maximum(np.abs(v[4:]), inertia)
    out[10 * n : 11 * n] = np.maximum(np.abs(phi_ref[10 * n : 11 * n]), 1e-2)
    return out


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
    n = cols.n
    mask = np.ones(cols.p, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    P = cols.P[mask]
    xm = np.asarray(x_hat, dtype=np.float64)[mask]

    # extras in play: enabled ones that some parameter of the mask holds
    enabled = cols.enabled_extras & np.any(P[:, 10 * n :] != 0, axis=0)
    phi_ref = np.concatenate([robot.params, robot.armature * enabled[:n], np.zeros(3 * n)])
    # start: the vector with x = x_hat closest to the URDF in a per-parameter scale (masses move
    # relative to the mass, inertias relative to the inertia, friction in N m)
    D = _phi_scale(phi_ref, n)
    phi0 = phi_ref + D * np.linalg.lstsq(P * D, xm - P @ phi_ref, rcond=None)[0]
    J_ref = pseudo_inertia(robot.params.reshape(n, 10))
    eps_l, J_ref_pd = _reference_bodies(robot.params, eps)
    e_idx = np.flatnonzero(enabled)
    kinds = [EXTRA_KINDS[e // n] for e in e_idx]
    lb_e = np.array([-np.inf if k == "offset" else 0.0 for k in kinds])
    e0 = np.maximum(phi0[10 * n + e_idx], lb_e)
    e_scale = np.maximum(np.abs(e0), max(1e-2 * float(np.abs(e0).max(initial=0.0)), 1e-6))

    start_ok = all(
        np.linalg.eigvalsh(pseudo_inertia(phi0[10 * k : 10 * k + 10])).min() > eps_l[k] for k in range(n)
    ) and np.all(phi0[10 * n + e_idx] >= lb_e)
    if start_ok and reference_weight == 0:
        # x_hat has an eps-consistent standard vector: it is the (weighted least-squares) answer itself;
        # the description decides the bodies in the directions it leaves open.
        prior = {}
        if describe:
            phi0, prior = described_bodies(robot, cols, phi0, mask=mask, eps=eps_l)
        return phi0, {
            "status": "unconstrained estimate is consistent",
            "iterations": 0,
            "time_s": time.perf_counter() - started,
            "eps": eps_l.tolist(),
            "at_bound": [],
            "prior": prior,
        }

    # Variables v = (y, w), the physical vector affine in them: y = R (x - x_hat) / sigma (whitened
    # change of the identified parameters, so the data term is ||y||^2) and w coordinates of the
    # directions P does not see (its null space, in the per-parameter scale D).
    act = np.concatenate([np.arange(10 * n), 10 * n + e_idx])
    D_a = D[act]
    Uk, sk, Vkt = np.linalg.svd(P[:, act] * D_a, full_matrices=True)
    rank = int(np.sum(sk > 1e-12 * sk[0]))
    to_psi = (Vkt[:rank].T / sk[:rank]) @ Uk[:, :rank].T  # minimum-norm psi = phi / D of an x
    V2 = Vkt[rank:].T
    sigma = float(np.sqrt(scale2))
    Rinv = scipy.linalg.solve_triangular(R, np.eye(len(R)), check_finite=False)
    c0 = D_a * (to_psi @ xm)
    G = np.hstack([D_a[:, None] * (to_psi @ (sigma * Rinv)), D_a[:, None] * V2])  # phi_a = c0 + G v
    ny, nv = len(xm), G.shape[1]
    weight = np.concatenate([np.ones(ny), np.full(nv - ny, _RHO)])
    centre = np.concatenate([np.zeros(ny), V2.T @ (phi0[act] / D_a)])
    B = [np.einsum("ik,iab->kab", G[10 * link : 10 * link + 10], _E) for link in range(n)]  # dJ_l / dv
    lower = np.isfinite(lb_e)
    Ge, lbe, se = G[10 * n :][lower], lb_e[lower], e_scale[lower]

    # a strictly feasible start: the start bodies pushed inside by 1 % of their size, extras too
    phi_f = phi0.copy()
    for link in range(n):
        margin = eps_l[link] + 1e-2 * max(float(np.linalg.eigvalsh(J_ref[link]).max()), 1e-6)
        Jf = _project_pd(pseudo_inertia(phi_f[10 * link : 10 * link + 10]), margin)
        phi_f[10 * link : 10 * link + 10] = standard_from_pseudo_inertia(Jf)
    phi_f[10 * n + e_idx] = np.maximum(phi_f[10 * n + e_idx], np.where(lower, lb_e + 1e-2 * e_scale, -np.inf))
    v = np.concatenate([R @ (P[:, act] @ phi_f[act] - xm) / sigma, V2.T @ (phi_f[act] / D_a)])

    shift = eps_l[:, None, None] * np.eye(4)  # (n, 4, 4)
    Jr_inv = np.linalg.inv(J_ref_pd)  # (n, 4, 4)
    logdet_ref = np.linalg.slogdet(J_ref_pd)[1]
    B_all = np.stack(B)  # (n, nv, 4, 4)
    prior_grad = (
        reference_weight * np.einsum("lab,lkba->k", Jr_inv, B_all) if reference_weight > 0 else np.zeros(nv)
    )

    def bodies(v):
        pa = c0 + G @ v
        return pseudo_inertia(pa[: 10 * n].reshape(n, 10)), pa[10 * n :][lower] - lbe

    def value(v, mu):
        Js, slack = bodies(v)
        if np.any(slack <= 0):
            return np.inf
        out = float(np.sum(weight * (v - centre) ** 2)) - mu * float(np.sum(np.log(slack / se)))
        try:
            L = np.linalg.cholesky(Js - shift)
        except np.linalg.LinAlgError:
            return np.inf
        out -= 2 * mu * float(np.log(np.diagonal(L, axis1=1, axis2=2)).sum())
        if reference_weight > 0:
            sign, logdet = np.linalg.slogdet(Js)
            if np.any(sign <= 0):
                return np.inf
            out += reference_weight * float(
                np.sum(np.einsum("lab,lba->l", Jr_inv, Js) - logdet + logdet_ref - 4)
            )
        return out

    def newton_step(v, mu):
        Js, slack = bodies(v)
        grad = 2 * weight * (v - centre) + prior_grad
        hess = np.diag(2 * weight)
        _add_neg_logdet(Js - shift, B_all, mu, grad, hess)
        if reference_weight > 0:
            _add_neg_logdet(Js, B_all, reference_weight, grad, hess)
        grad -= mu * (Ge.T @ (1.0 / slack))
        hess += mu * (Ge.T / slack**2) @ Ge
        step = _newton_direction(hess, grad)
        return step, float(-grad @ step)

    nu = 4 * n + int(lower.sum())  # barrier parameter: 4 per pseudo-inertia, 1 per bound
    mu = max(float(np.sum(weight * (v - centre) ** 2)) / nu, 1e-6)
    steps, status = 0, "converged"
    while True:
        while steps < max_iter:  # centring: damped Newton with a backtracking line search
            step, decrement = newton_step(v, mu)
            steps += 1
            f0, t = value(v, mu), 1.0
            if decrement <= 1e-9 * max(1.0, abs(f0)):
                break
            while value(v + t * step, mu) > f0 - 0.25 * t * decrement:
                t *= 0.5
                if t < 1e-10:  # no descent left at rounding level: centred as well as it can be
                    break
            if t < 1e-10:
                break
            v = v + t * step
        if steps >= max_iter:
            status = "max_iter"
            break
        if nu * mu <= float(tol) * max(1.0, float(np.sum(weight * (v - centre) ** 2))):
            break
        mu *= _MU_FACTOR
    if status != "converged":
        warnings.warn(
            f"the consistent fit stopped after {steps} Newton steps before its tolerance; the result is "
            "consistent but may not be the closest one: raise max_iter or tol",
            IdentificationWarning,
            stacklevel=4,
        )
    phi_opt = np.zeros(14 * n)
    phi_opt[act] = c0 + G @ v
    phi_opt[10 * n + e_idx] = np.maximum(phi_opt[10 * n + e_idx], lb_e)
    # A link is held at the bound when its constraint carries a multiplier the data feel: the barrier's
    # multiplier mu (J - eps I)^-1, times the body's size, is the fall of the distance (in squared standard
    # deviations) per relative loosening of the bound.  The vanishing pull of the unseen directions toward
    # the start leaves multipliers of order _RHO; the data's are of order one.
    at_bound = []
    Js, _ = bodies(v)
    for link, J in enumerate(Js):
        size = max(float(np.linalg.eigvalsh(J_ref_pd[link]).max()), 1e-6)
        # (with a pull toward the description, whose log-det keeps every body off the bound, none is)
        lam = mu * float(np.linalg.eigvalsh(np.linalg.inv(J - eps_l[link] * np.eye(4))).max())
        if lam * size > _BOUND_FORCE:
            at_bound.append(link + 1)
    prior = {}
    if describe:
        phi_opt, prior = described_bodies(robot, cols, phi_opt, mask=mask, eps=eps_l)
    return phi_opt, {
        "status": status,
        "iterations": steps,
        "time_s": time.perf_counter() - started,
        "eps": eps_l.tolist(),
        "at_bound": at_bound,
        "prior": prior,
    }


def _reference_bodies(
    ref_params: NDArray[np.float64], eps: float | ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Per-link margin and described pseudo-inertia, as the consistent fit and its bodies use them.

    The margin is ``eps``, lowered to half the smallest eigenvalue of a thinner URDF body; the described
    pseudo-inertia is the URDF's, lifted to at least twice that margin (and 1e-6 of its size).

    Returns
    -------
    eps_l : ndarray, shape (n,)
    J_ref_pd : ndarray, shape (n, 4, 4)
    """
    J_ref = pseudo_inertia(np.asarray(ref_params, dtype=np.float64).reshape(-1, 10))
    eps_in = np.broadcast_to(np.asarray(eps, dtype=np.float64), (len(J_ref),))
    eps_l = np.empty(len(J_ref))
    J_pd = np.empty_like(J_ref)
    for link, J in enumerate(J_ref):
        w = np.linalg.eigvalsh(J)
        eps_l[link] = min(float(eps_in[link]), 0.5 * float(w.min())) if w.min() > 0 else float(eps_in[link])
        J_pd[link] = _project_pd(J, max(1e-6 * max(float(w.max()), 1e-6), 2 * eps_l[link]))
    return eps_l, J_pd


def _add_neg_logdet(M, B_all, coef: float, grad, hess) -> None:
    """Add the derivatives of ``-coef sum_l log det M_l`` (``dM_l / dv_k = B_all[l, k]``) in place.

    Gradient ``-coef tr(M^-1 B_k)``, Hessian ``coef tr(M^-1 B_k M^-1 B_j)``, batched over the links.
    """
    n, nv = B_all.shape[:2]
    Li = np.linalg.inv(np.linalg.cholesky(M))  # (n, 4, 4), lower triangular
    T = (Li[:, None] @ B_all @ np.swapaxes(Li, 1, 2)[:, None]).reshape(n, nv, 16)
    grad -= coef * T[:, :, [0, 5, 10, 15]].sum(axis=(0, 2))
    Tm = np.ascontiguousarray(T.transpose(1, 0, 2)).reshape(nv, 16 * n)
    hess += coef * (Tm @ Tm.T)


def _newton_direction(hess, grad):
    """The Newton step ``-hess^-1 grad``, Jacobi-scaled (entries span many decades); least squares if singular."""
    d = 1.0 / np.sqrt(np.maximum(np.diag(hess), 1e-300))
    scaled = hess * np.outer(d, d)
    try:
        c = scipy.linalg.cho_factor(scaled, check_finite=False)
        step = -d * scipy.linalg.cho_solve(c, d * grad, check_finite=False)
        if not np.all(np.isfinite(step)):
            raise np.linalg.LinAlgError
    except (np.linalg.LinAlgError, ValueError):
        step = -d * np.linalg.lstsq(scaled, d * grad, rcond=1e-14)[0]
    return step


def described_bodies(
    robot,
    cols: ColumnSet,
    phi: ArrayLike,
    *,
    mask: NDArray[np.bool_] | None = None,
    eps: float | ArrayLike = EPS,
    max_iter: int = 200,
) -> tuple[NDArray[np.float64], dict[str, Any]]:
    """The bodies nearest the robot's description among those with the same identified parameters.

    Joint torques determine only combinations of the links' standard parameters (the base parameters):
    in every other direction any body is as good as another for the data, and a vanishing pull toward
    an arbitrary start used to decide, which could put 60 kg on a 0.65 kg link.  Here the description
    decides there: among the physical vectors ``phi`` with the same identified parameters (``P phi``
    fixed, so the prediction of every torque is unchanged to rounding) and ``J_l >= eps_l I``, the one
    that minimises the entropic divergence of every body from its description,

        sum_l  tr(J_l,ref^-1 J_l) - log det(J_l - eps_l I)     (Lee and Wensing's log-det divergence,
                                                                with the margin in the log-det)

    plus, for armature and friction in play, ``((e - e_ref) / e_scale)^2`` with a vanishing barrier at
    their lower bounds.  The divergence is unit-free and treats mass, first and second moments alike:
    a change of a base parameter that could go into a link's mass or its inertia goes where it is
    the smaller change relative to that body, and a direction the data do not see stays at the
    description.  A convex problem in the null-space coordinates, solved by damped Newton steps from
    the feasible ``phi``.

    Parameters
    ----------
    robot : RobotModel
        The robot; its URDF/DH bodies are the description.
    cols : ColumnSet
        The identified parameters.
    phi : array_like, shape (14 n,)
        A physical vector with ``J_l - eps_l I`` positive semidefinite.
    mask : ndarray of bool, shape (p,), optional
        Identified parameters held fixed (default all).
    eps : float or array_like
        Consistency margin per link (kg m^2).
    max_iter : int
        Most Newton steps.

    Returns
    -------
    phi : ndarray, shape (14 n,)
        The physical vector with the same identified parameters, nearest the description.
    info : dict
        ``iterations``, ``directions`` (how many directions the data leave to the description) and
        ``divergence`` (the summed divergence before and after).
    """
    phi = np.asarray(phi, dtype=np.float64).copy()
    n = cols.n
    mask = np.ones(cols.p, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    P = cols.P[mask]
    enabled = cols.enabled_extras & np.any(P[:, 10 * n :] != 0, axis=0)
    e_idx = np.flatnonzero(enabled)
    act = np.concatenate([np.arange(10 * n), 10 * n + e_idx])
    ref = np.concatenate([robot.params, robot.armature * enabled[:n], np.zeros(3 * n)])
    D = _phi_scale(ref, n)[act]
    Pa = P[:, act] * D
    if Pa.size:
        _, sk, Vkt = np.linalg.svd(Pa, full_matrices=True)
        rank = int(np.sum(sk > 1e-10 * sk[0])) if sk.size and sk[0] > 0 else 0
    else:
        Vkt, rank = np.eye(len(act)), 0
    N = D[:, None] * Vkt[rank:].T  # phi_a = phi_a,0 + N w keeps P phi
    info: dict[str, Any] = {"iterations": 0, "directions": int(N.shape[1])}
    if N.shape[1] == 0:
        return phi, info
    eps_l, J_ref_pd = _reference_bodies(robot.params, eps)
    A = np.linalg.inv(J_ref_pd)  # (n, 4, 4)
    shift = eps_l[:, None, None] * np.eye(4)
    kinds = [EXTRA_KINDS[e // n] for e in e_idx]
    lb = np.array([-np.inf if k == "offset" else 0.0 for k in kinds])
    e_ref = ref[10 * n + e_idx]
    e_scale = np.maximum(np.abs(phi[10 * n + e_idx]), 1e-6)
    e_scale = np.maximum(e_scale, 1e-2 * float(e_scale.max(initial=1e-6)))
    bounded = np.isfinite(lb)
    # the start must be strictly inside: nudge extras sitting on their bound
    e0 = phi[10 * n + e_idx]
    phi[10 * n + e_idx] = np.where(bounded & (e0 <= lb + 1e-9 * e_scale), lb + 1e-9 * e_scale, e0)
    base = phi[act].copy()
    B_all = np.stack([np.einsum("ik,iab->kab", N[10 * link : 10 * link + 10], _E) for link in range(n)])
    trace_grad = np.einsum("lab,lkba->k", A, B_all)  # the gradient of sum_l tr(A_l J_l): constant
    Ne = N[10 * n :]
    kappa = 1e-9  # barrier weight of the extras' bounds (relative to the unit pull)

    def parts(w):
        pa = base + N @ w
        return pseudo_inertia(pa[: 10 * n].reshape(n, 10)), pa[10 * n :]

    def value(w):
        Js, e = parts(w)
        slack = (e - lb)[bounded]
        if np.any(slack <= 0):
            return np.inf
        out = _EXTRA_PULL * float(np.sum(((e - e_ref) / e_scale) ** 2)) - kappa * float(
            np.sum(np.log(slack / e_scale[bounded]))
        )
        try:
            L = np.linalg.cholesky(Js - shift)
        except np.linalg.LinAlgError:
            return np.inf
        logdet = 2 * float(np.log(np.diagonal(L, axis1=1, axis2=2)).sum())
        return out + float(np.einsum("lab,lba->", A, Js)) - logdet

    w = np.zeros(N.shape[1])
    f = value(w)
    if not np.isfinite(f):  # the start sits on the margin: nothing safe to move
        return phi, info
    f_start = f
    for step_count in range(1, max_iter + 1):
        Js, e = parts(w)
        grad = 2 * _EXTRA_PULL * Ne.T @ ((e - e_ref) / e_scale**2)
        hess = 2 * _EXTRA_PULL * (Ne.T / e_scale**2) @ Ne
        slack = (e - lb)[bounded]
        Nb = Ne[bounded]
        grad -= kappa * Nb.T @ (1.0 / slack)
        hess += kappa * (Nb.T / slack**2) @ Nb
        grad += trace_grad
        _add_neg_logdet(Js - shift, B_all, 1.0, grad, hess)
        step = _newton_direction(hess, grad)
        decrement = float(-grad @ step)
        info["iterations"] = step_count
        if decrement <= 1e-10 * max(1.0, abs(f)):
            break
        t = 1.0
        while True:
            f_new = value(w + t * step)
            if f_new <= f - 0.25 * t * decrement:
                break
            t *= 0.5
            if t < 1e-12:
                break
        if t < 1e-12:
            break
        w, f = w + t * step, f_new
    target = P[:, act] @ base
    moved = base + N @ w
    # back onto the affine set exactly (the null space is numerical: rounding of its basis)
    moved += np.linalg.lstsq(P[:, act], target - P[:, act] @ moved, rcond=None)[0]
    phi[act] = moved
    phi[10 * n + e_idx] = np.maximum(phi[10 * n + e_idx], lb)
    info["divergence"] = {"start": f_start, "end": f}
    return phi, info


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


def link_inertials(standard: ArrayLike) -> list[dict[str, Any]]:
    """Mass, centre of mass and inertia about it of every link, as a URDF ``<inertial>`` takes them.

    Parameters
    ----------
    standard : array_like, shape (10 n,)
        Standard parameters ``[m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`` per link, about the
        link frame's origin (kg, kg m, kg m^2).

    Returns
    -------
    list of dict
        Per link: ``mass`` (kg), ``com`` (m, link frame), ``inertia_com`` ``[ixx, ixy, ixz, iyy, iyz,
        izz]`` (kg m^2, about the centre of mass, link-frame axes; URDF's order), ``standard`` (the
        10 values given) and ``min_eigenvalue`` of the pseudo-inertia (kg m^2; > 0: a real body).
    """
    p = np.asarray(standard, dtype=np.float64).reshape(-1, 10)
    out = []
    for v in p:
        m = float(v[0])
        c = v[1:4] / m if m > 0 else np.zeros(3)
        Io = np.array([[v[4], v[5], v[7]], [v[5], v[6], v[8]], [v[7], v[8], v[9]]])
        Ic = Io - m * (float(c @ c) * np.eye(3) - np.outer(c, c))
        out.append(
            {
                "mass": m,
                "com": [float(a) for a in c],
                "inertia_com": [
                    float(Ic[0, 0]),
                    float(Ic[0, 1]),
                    float(Ic[0, 2]),
                    float(Ic[1, 1]),
                    float(Ic[1, 2]),
                    float(Ic[2, 2]),
                ],
                "standard": [float(a) for a in v],
                "min_eigenvalue": float(np.linalg.eigvalsh(pseudo_inertia(v)).min()),
            }
        )
    return out


def is_consistent(params: ArrayLike, tol: float = 0.0) -> NDArray[np.bool_]:
    """Whether each link's standard parameters have a positive definite pseudo-inertia.

    Parameters
    ----------
    params : array_like, shape (10 n,)
        Standard parameters.
    tol : float
        Smallest eigenvalue accepted (kg m^2).
    """
    J = pseudo_inertia(np.asarray(params, dtype=np.float64).reshape(-1, 10))
    return np.array([scipy.linalg.eigvalsh(j).min() > tol for j in J])
