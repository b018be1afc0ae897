"""Physically consistent identification of the link parameters (IPOPT through CasADi).

Every link's standard parameters must describe a real body: mass > 0 and the pseudo-inertia

    J = [[Sigma, h], [h^T, m]],   Sigma = tr(I)/2 * 1 - I,   h = m c   (about the joint frame)

positive definite, which implies the triangle inequalities of the inertia.  The log-Cholesky
parametrisation (Rucker & Wensing 2022) makes that hold by construction: ``J = U U^T`` with ``U``
upper triangular, its diagonal ``exp(theta_ii)`` and its six off-diagonal entries free, so the
search runs over 10 unconstrained numbers per link.

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
"""

from __future__ import annotations

import warnings
from typing import Any

import casadi as ca
import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from dynid.exceptions import IdentificationError, UsageError
from dynid.identify.estimators import ESTIMATORS, IdentificationWarning, LinkEstimator
from dynid.identify.linear_system import EXTRA_KINDS, LinearSystem, Preprocessing

_RHO = 1e-6  # weight of the vanishing pull toward the starting bodies (fixes the directions data do not see)
__all__ = [
    "ConsistentLS",
    "is_consistent",
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
    m, h = p[:, 0], p[:, 1:4]
    Ixx, Ixy, Iyy, Ixz, Iyz, Izz = p[:, 4], p[:, 5], p[:, 6], p[:, 7], p[:, 8], p[:, 9]
    inertia = np.stack(
        [np.stack([Ixx, Ixy, Ixz], -1), np.stack([Ixy, Iyy, Iyz], -1), np.stack([Ixz, Iyz, Izz], -1)], -2
    )
    tr = Ixx + Iyy + Izz
    J = np.zeros((len(p), 4, 4))
    J[:, :3, :3] = 0.5 * tr[:, None, None] * np.eye(3) - inertia
    J[:, :3, 3] = h
    J[:, 3, :3] = h
    J[:, 3, 3] = m
    return J[0] if single else J


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


def _U(theta):
    """Upper-triangular factor of the log-Cholesky parameters (numpy or CasADi)."""
    exp = ca.exp if isinstance(theta, ca.SX | ca.MX) else np.exp
    t = theta
    rows = [
        [exp(t[0]), t[1], t[2], t[3]],
        [0, exp(t[4]), t[5], t[6]],
        [0, 0, exp(t[7]), t[8]],
        [0, 0, 0, exp(t[9])],
    ]
    if isinstance(theta, ca.SX | ca.MX):
        return ca.vertcat(*[ca.horzcat(*r) for r in rows])
    return np.array(rows, dtype=np.float64)


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
    """Weighted least squares over physically consistent links (IPOPT, log-Cholesky).

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
    tol : float
        IPOPT's tolerance.
    max_iter : int
        IPOPT's iteration limit.

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
        Smallest eigenvalue of each pseudo-inertia (> 0: consistent).
    unconstrained_ : LinkEstimator
        The layer-1 fit it started from; ``cov_``, ``std_`` and ``std_percent_`` are its figures
        (valid where no constraint is active).
    distance_ : dict
        How far the consistent estimate is from the unconstrained one: ``relative``
        (``||x - x_hat|| / ||x_hat||``), ``mahalanobis`` (in standard deviations), ``rms_change``
        (N m per joint) and ``rms_ratio``.
    solver_ : dict
        IPOPT's return status, iterations and time.
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
        tol: float = 1e-8,
        max_iter: int = 1000,
    ) -> None:
        super().__init__(robot=robot, friction=friction, armature=armature, preprocessing=preprocessing)
        self.weighting = weighting
        self.reference_weight = reference_weight
        self.tol = tol
        self.max_iter = max_iter

    def _fit_system(self, system: LinearSystem) -> None:
        if self.weighting not in ESTIMATORS:
            raise UsageError(f"weighting is {self.weighting!r}; choose one of {', '.join(ESTIMATORS)}")
        if not self.reference_weight >= 0:
            raise UsageError(f"reference_weight is {self.reference_weight!r}; give a number >= 0")
        unc = ESTIMATORS[self.weighting](
            robot=self.robot, friction=self.friction, armature=self.armature, preprocessing=self.preprocessing
        )
        unc._fit_system(system)
        cols = system.columns
        n, p = cols.n, cols.p
        R, x_hat = unc.R_, unc.params_
        dof = max(system.m * n - p, 1)
        sigma2 = unc.rss_ / dof
        power = (float(unc.rhs_ @ unc.rhs_) + unc.rss_) / (system.m * n)
        scale2 = max(sigma2, 1e-8 * power, 1e-300)
        A = (R @ cols.P) / np.sqrt(scale2)
        b = (R @ x_hat) / np.sqrt(scale2)

        # starting point and reference bodies
        enabled = cols.enabled_extras
        phi_ref = np.concatenate([self.robot.params, self.robot.armature * enabled[:n], np.zeros(3 * n)])
        # start: the vector with x = x_hat closest to the URDF in a per-parameter scale (masses move
        # relative to the mass, inertias relative to the inertia, friction in N m)
        D = _phi_scale(phi_ref, n)
        phi0 = phi_ref + D * np.linalg.lstsq(cols.P * D, x_hat - cols.P @ phi_ref, rcond=None)[0]
        J_ref = pseudo_inertia(self.robot.params.reshape(n, 10))
        C, J_ref_pd = [], []
        for link in range(n):
            scale = max(float(np.linalg.eigvalsh(J_ref[link]).max()), 1e-6)
            J_ref_pd.append(_project_pd(J_ref[link], 1e-6 * scale))
            J0 = _project_pd(pseudo_inertia(phi0[10 * link : 10 * link + 10]), 1e-4 * scale)
            C.append(np.linalg.cholesky(J0[::-1, ::-1])[::-1, ::-1])  # J0 = C C^T, C upper triangular
        e_idx = np.flatnonzero(enabled)
        kinds = [EXTRA_KINDS[e // n] for e in e_idx]
        lb_e = np.array([-np.inf if k == "offset" else 0.0 for k in kinds])
        e0 = np.maximum(phi0[10 * n + e_idx], lb_e)
        e_scale = np.maximum(np.abs(e0), max(1e-2 * float(np.abs(e0).max(initial=0.0)), 1e-6))

        start_ok = all(
            np.linalg.eigvalsh(pseudo_inertia(phi0[10 * k : 10 * k + 10])).min() > 0 for k in range(n)
        ) and np.all(phi0[10 * n + e_idx] >= lb_e)
        if start_ok and self.reference_weight == 0:
            # x_hat has a consistent standard vector: it is the (weighted least-squares) answer itself.
            self._finish(
                system,
                unc,
                phi0,
                x_hat,
                sigma2,
                R,
                {"status": "unconstrained estimate is consistent", "iterations": 0, "time_s": 0.0},
                exact=True,
            )
            return

        # The NLP.  Per link J = C (U U^T) C^T with C the factor of the starting body, so every
        # variable starts at 0 and means a relative change of the body: a well-scaled problem.
        theta = ca.SX.sym("theta", 10 * n)
        eps = ca.SX.sym("eps", len(e_idx))
        e = ca.DM(e0) + ca.DM(e_scale) * eps
        std_parts = []
        divergence = 0
        reg = 0
        for link in range(n):
            th = theta[10 * link : 10 * link + 10]
            Ck = ca.DM(C[link])
            J = Ck @ (_U(th) @ _U(th).T) @ Ck.T
            std_parts += standard_from_pseudo_inertia(J)
            # log det J = 2 sum(theta_ii) + log det(C C^T); divergence from the start: tr(J0^-1 J) - log det ...
            UU = _U(th) @ _U(th).T
            reg += ca.trace(UU) - 2 * (th[0] + th[4] + th[7] + th[9]) - 4.0
            if self.reference_weight > 0:
                Jr_inv = np.linalg.inv(J_ref_pd[link])
                logdet = 2 * (th[0] + th[4] + th[7] + th[9]) + 2 * float(np.log(np.diag(C[link])).sum())
                divergence += (
                    ca.trace(ca.DM(Jr_inv) @ J) - logdet + np.linalg.slogdet(J_ref_pd[link])[1] - 4.0
                )
        e_full = [0.0] * (4 * n)
        for k, idx in enumerate(e_idx):
            e_full[idx] = e[k]
        phi = ca.vertcat(*std_parts, *e_full)
        r = ca.DM(A) @ phi - ca.DM(b)
        objective = ca.dot(r, r) + self.reference_weight * divergence + _RHO * (reg + ca.dot(eps, eps))
        z = ca.vertcat(theta, eps)
        solver = ca.nlpsol(
            "consistent",
            "ipopt",
            {"x": z, "f": objective},
            {
                "ipopt.print_level": 0,
                "ipopt.sb": "yes",
                "print_time": False,
                "ipopt.tol": float(self.tol),
                "ipopt.max_iter": int(self.max_iter),
            },
        )
        z0 = np.zeros(10 * n + len(e_idx))
        lbz = np.concatenate(
            [np.full(10 * n, -np.inf), np.where(np.isfinite(lb_e), (lb_e - e0) / e_scale, -np.inf)]
        )
        sol = solver(x0=z0, lbx=lbz, ubx=np.inf)
        stats = solver.stats()
        status = str(stats.get("return_status"))
        z_opt = np.asarray(sol["x"]).ravel()
        if not np.all(np.isfinite(z_opt)):
            raise IdentificationError(
                f"IPOPT failed on the consistent fit ({status}); add a pull toward the URDF with reference_weight > 0"
            )
        if not stats.get("success", False) and status != "Solved_To_Acceptable_Level":
            warnings.warn(
                f"IPOPT stopped before its tolerance on the consistent fit ({status}); the result is consistent "
                "but may not be the closest one: raise max_iter, or add a pull toward the URDF with reference_weight > 0",
                IdentificationWarning,
                stacklevel=4,
            )
        phi_opt = np.asarray(ca.Function("phi", [z], [phi])(z_opt)).ravel()
        phi_opt[10 * n + e_idx] = np.maximum(phi_opt[10 * n + e_idx], lb_e)  # IPOPT relaxes bounds by ~1e-8
        self._finish(
            system,
            unc,
            phi_opt,
            x_hat,
            sigma2,
            R,
            {
                "status": status,
                "iterations": int(stats.get("iter_count", -1)),
                "time_s": float(stats.get("t_wall_total", np.nan)),
            },
        )

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
