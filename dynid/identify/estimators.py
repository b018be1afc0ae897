"""Layer 1: link parameters by least squares (OLS, WLS, GLS, IRLS), in scikit-learn style.

>>> est = IRLS(robot=load_robot("ur5")).fit(dataset)       # dataset: t, q, tau [, dq, ddq]
>>> est.params_, est.std_percent_, est.cond_, est.rms_
>>> tau = est.predict(q, dq, ddq)                           # or est.predict(other_dataset)

The estimators share one data path (:mod:`dynid.identify.linear_system`): preprocessing, the compiled
regressor, parallel filtering, and a compressed QR factor of the stacked system.  They differ in the
weighting of the joints (METHOD.md section 4), with ``Omega`` the joint-noise covariance:

=======  ==================================================================================
OLS      no weighting, ``x = argmin || tau - W x ||^2``
WLS      per-joint variances ``Omega_jj = var(E_j)`` of the OLS residual
GLS      full ``Omega = E^T E / (m - p)`` of the OLS residual
IRLS     GLS repeated with ``Omega`` of the latest residual until ``x`` stops changing
=======  ==================================================================================

Each whitens the stacked system (``L^-1`` per sample with ``Omega = L L^T``) and solves it by QR;
normal equations are never formed.

Covariance of the estimate
--------------------------
With independent samples it would be ``sigma^2 (W~^T W~)^-1`` (``W~`` the whitened regressor,
``sigma^2`` the whitened residual variance).  But low-pass filtered data are correlated in time: at
1 kHz with a 20 Hz cut-off, white noise stays correlated over about 27 samples, and those figures
came out too small by up to ``sqrt(fs / (2 cutoff))`` (measured on simulated UR5 data: errors of
6 reported deviations RMS, only 54 % of the parameters within 4 of them).  dynid reports the
sandwich

    cov = (W~^T W~)^-1 [ sum_i kappa_i s_i^2 W~_i^T W~_i ] (W~^T W~)^-1

with ``W~_i`` the rows of whitened joint ``i``, ``s_i^2`` their residual variance and ``kappa_i``
the long-run variance factor of their residual (:func:`residual_correlation`: a Newey-West sum of its
autocorrelation, at least what white noise through the filter gives, :attr:`Prepared.noise_correlation`).
That assumes the regressor varies slowly over the correlation time (true of excitation trajectories
against a 20 Hz filter).  ``m / mean(kappa)`` is reported as ``effective_samples_``.  On the same data
the errors are then 1.0 reported deviations RMS, 68 / 95 / 100 % within 1 / 2 / 4 of them.  Residual
correlation from unmodelled effects widens the figures too, which is the honest direction.
"""

from __future__ import annotations

import warnings
from typing import Any, ClassVar

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

from dynid._threads import single_blas_thread
from dynid.data.dataset import Dataset
from dynid.data.preparation import Preprocessing, prepare
from dynid.exceptions import IdentificationError, IdentificationWarning, UsageError
from dynid.identify.checks import check_is_fitted
from dynid.identify.columns import ColumnSet, linear_torque
from dynid.identify.linear_system import LinearSystem, WeightedSolution, build_system
from dynid.identify.registry import CONSTRAINED_METHODS, ESTIMATORS

__all__ = [
    "ESTIMATORS",
    "GLS",
    "IRLS",
    "OLS",
    "PHYSICAL_KINDS",
    "WLS",
    "IdentificationWarning",
    "LinkEstimator",
    "autocovariance",
    "bartlett_weights",
    "bounded_triangular",
    "check_is_fitted",
    "long_run_factor",
    "long_run_variance",
    "physical_lower_bounds",
    "register_estimator",
    "residual_correlation",
]


PHYSICAL_KINDS = ("armature", "coulomb", "viscous")
"""Parameter kinds that a physical model never has negative: rotor inertia, Coulomb and viscous friction."""


def physical_lower_bounds(columns: ColumnSet) -> NDArray[np.float64]:
    """Lower bound of each identified parameter: 0 for the kinds of :data:`PHYSICAL_KINDS`, else -inf.

    Parameters
    ----------
    columns : ColumnSet
        The identified parameters.
    """
    return np.array([0.0 if k in PHYSICAL_KINDS else -np.inf for k in columns.kinds])


def bounded_triangular(
    R: NDArray[np.float64], rhs: NDArray[np.float64], lower: NDArray[np.float64]
) -> NDArray[np.float64]:
    """``min || R x - rhs ||^2`` subject to ``x >= lower`` (bounded-variable least squares).

    ``R`` is the triangular factor of a (weighted) least squares, so this is the constrained solution
    of the whole problem.  Without a finite bound it is the plain solution.

    Parameters
    ----------
    R : ndarray, shape (p, p)
        Triangular factor.
    rhs : ndarray, shape (p,)
        ``Q^T`` times the target.
    lower : ndarray, shape (p,)
        Lower bounds (-inf: none).
    """
    x = scipy.linalg.lstsq(R, rhs, cond=1e-13, check_finite=False)[0]
    if not np.any(np.isfinite(lower)) or np.all(x >= lower):
        return x
    from scipy.optimize import lsq_linear  # only when a bound is active (its import is 0.3 s)

    return lsq_linear(R, rhs, bounds=(lower, np.inf), method="bvls", lsq_solver="exact").x


def whitener(omega: NDArray[np.float64]) -> NDArray[np.float64]:
    """``L^-1`` (lower triangular) with ``Omega = L L^T``, regularised; identity for a zero ``Omega``.

    Parameters
    ----------
    omega : ndarray, shape (n, n)
        Joint-noise covariance (N^2 m^2).
    """
    n = omega.shape[0]
    scale = float(np.trace(omega)) / n
    if not np.isfinite(scale) or scale <= 1e-300:
        return np.eye(n)
    reg = omega + 1e-10 * scale * np.eye(n)
    L = np.linalg.cholesky(reg / scale)
    return scipy.linalg.solve_triangular(L, np.eye(n), lower=True)


class LinkEstimator:
    """Base of the layer-1 estimators (not used alone; see :class:`OLS`, :class:`WLS`, :class:`GLS`,
    :class:`IRLS`), and of the registry :data:`ESTIMATORS`.

    A new estimator sets its ``method`` name and implements ``_iterate(system) -> (WeightedSolution,
    Omega)``, the weighting it solves on the compressed system (``self._weighted_fit(system, W)`` with
    ``W`` the whitener, see :class:`GLS`); this class turns that into the attributes below and
    :meth:`predict`.  :func:`register_estimator` makes it a ``method=`` of
    :func:`dynid.identify.model.identify` and a ``--method`` choice.

    Parameters
    ----------
    robot : RobotModel
        The robot that recorded the data.
    friction : bool
        Identify linear friction (Coulomb, viscous, offset per joint) with the link parameters.
    armature : bool
        Identify the armature of each joint with the link parameters (folded into a base parameter
        where its column duplicates one; see ``notes_``).
    preprocessing : Preprocessing, optional
        Filtering and differentiation of a dataset (default :class:`Preprocessing`).

    Attributes
    ----------
    params_ : ndarray, shape (p,)
        Identified parameters: base parameters, then armature and friction (SI units).
    names_, expressions_ : tuple of str
        Their names and expressions in the standard parameters.
    cov_ : ndarray, shape (p, p)
        Covariance of ``params_``, corrected for the correlation of the residuals in time (see the
        module docstring).
    std_, std_percent_ : ndarray, shape (p,)
        Standard deviations, absolute and in % of ``|params_|``.
    cond_ : float
        Condition number of the weighted stacked regressor.
    rms_ : ndarray, shape (n,)
        Residual RMS per joint (N m) on the identification samples.
    omega_ : ndarray, shape (n, n)
        Joint-noise covariance ``E^T E / (m - p)`` used in the weighting (OLS: of its own residual,
        for information; it weighs nothing).
    sigma2_ : float
        Whitened residual variance.
    correlation_ : ndarray, shape (n,)
        Long-run variance factor of each whitened residual row (1: independent samples; about
        ``1.09 fs / (2 cutoff decimate)`` for filtered white noise).
    effective_samples_ : float
        ``n_samples_ / mean(correlation_)``: as many independent samples carry the same information.
    n_samples_ : int
        Samples used.
    notes_ : tuple of str
        Columns folded into others.
    columns_ : ColumnSet
        The identified parameters (names, kinds, base map).
    preprocessing_ : dict
        Resolved preprocessing settings.
    solution_ : WeightedSolution
        The weighted least squares the estimate solves: ``x``, its triangular factor ``R``, ``rhs``,
        ``rss`` and the whitener (``R_``, ``rhs_``, ``rss_`` and ``whitener_`` repeat them).  For
        :class:`dynid.identify.consistent.ConsistentLS`, that of the unconstrained fit.
    """

    method: ClassVar[str] = ""

    def __init__(
        self,
        *,
        robot,
        friction: bool = True,
        armature: bool = True,
        preprocessing: Preprocessing | None = None,
    ) -> None:
        self.robot = robot
        self.friction = friction
        self.armature = armature
        self.preprocessing = preprocessing

    def __repr__(self) -> str:
        return f"{type(self).__name__}(robot={getattr(self.robot, 'name', self.robot)!r})"

    # ------------------------------------------------------------------ fit
    def fit(self, data: Dataset | LinearSystem) -> LinkEstimator:
        """Identify the parameters.

        Parameters
        ----------
        data : Dataset or LinearSystem
            Measured data, or a system already built by :func:`build_system` (several estimators can
            then share the pass over the data).

        Returns
        -------
        self
        """
        system = self._system(data)
        # (a copy without the data matrix estimates the residual's correlation otherwise: its own key)
        key = (*self._fit_key(), system.Z is None) if system.shared else None
        if key is None:
            with single_blas_thread():
                self._fit_system(system)
            return self
        if key not in system.derived:
            with single_blas_thread(), warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                self._fit_system(system)
            fitted = {k: v for k, v in vars(self).items() if k.endswith("_")}
            system.derived[key] = (_copied(fitted), [(w.message, w.category, w.filename, w.lineno) for w in caught])
        else:  # this estimator fitted this shared system already (another pipeline): its fit, its warnings
            fitted, _ = system.derived[key]
            self.__dict__.update(_copied(fitted))
        for message, category, filename, lineno in system.derived[key][1]:
            warnings.warn_explicit(message, category, filename, lineno)  # the caller's filters decide
        return self

    def _fit_key(self) -> tuple:
        """What this fit depends on besides the system: the estimator and its settings.

        The default identification fits several pipelines on one shared system
        (:func:`dynid.identify.linear_system.sharing_systems`); those with the same layer-1 estimator
        take its fit once (IRLS's 50 reweighted solves were a tenth of a default identification's time).
        """
        settings = []
        for name, value in sorted(vars(self).items()):
            if name.endswith("_") or name.startswith("_"):
                continue
            if name == "robot":
                value = id(value)  # the system holds the robot alive
            elif isinstance(value, np.ndarray):  # every digit (repr rounds them)
                value = ("array", value.shape, value.dtype.str, value.tobytes())
            elif not isinstance(value, (bool, int, float, str, type(None))):
                value = repr(value)
            settings.append((name, value))
        return ("layer 1", type(self), tuple(settings))

    def _system(self, data: Dataset | LinearSystem) -> LinearSystem:
        if isinstance(data, LinearSystem):
            cols = data.columns
            if cols.robot.key != self.robot.key:
                raise UsageError(
                    f"the system was built for the robot '{cols.robot.name}'; this estimator is for "
                    f"'{self.robot.name}': build the system with the same robot"
                )
            if (cols.friction, cols.armature) != (bool(self.friction), bool(self.armature)):
                raise UsageError(
                    f"the system has friction={cols.friction}, armature={cols.armature}; the estimator asks "
                    f"friction={bool(self.friction)}, armature={bool(self.armature)}: build it with the same options"
                )
            return data
        return build_system(
            self.robot,
            data,
            preprocessing=self.preprocessing,
            friction=self.friction,
            armature=self.armature,
        )

    def _weighted_fit(self, system: LinearSystem, W: NDArray[np.float64]) -> WeightedSolution:
        return system.solve(W)

    def _omega(self, system: LinearSystem, x: NDArray[np.float64]) -> NDArray[np.float64]:
        m, p = system.m, system.p
        if m <= p:
            raise IdentificationError(
                f"{self.method.upper()} estimates the joint-noise covariance from the residuals and needs more "
                f"samples than parameters; the data give {m} samples for {p} parameters: record more than {p} "
                "samples, or use OLS"
            )
        return system.residual_matrix(x) / (m - p)

    def _reweighted_fit(
        self, system: LinearSystem, x: NDArray[np.float64], *, diagonal: bool
    ) -> tuple[WeightedSolution, NDArray[np.float64]]:
        """Refit weighted by ``Omega`` of the residual of ``x`` (its diagonal only with ``diagonal``).

        Returns (the new solution, Omega used).
        """
        omega = self._omega(system, x)
        if diagonal:
            omega = np.diag(np.diag(omega))
        return self._weighted_fit(system, whitener(omega)), omega

    def _iterate(self, system: LinearSystem) -> tuple[WeightedSolution, NDArray[np.float64]]:
        """Return (the solution, Omega used); subclasses choose the weighting."""
        raise NotImplementedError

    def _fit_system(self, system: LinearSystem) -> None:
        sol, omega = self._iterate(system)
        x, R, rss = sol.x, sol.R, sol.rss
        m, n, p = system.m, system.n, system.p
        dof = m * n - p
        sigma2 = rss / dof
        Rinv = scipy.linalg.solve_triangular(R, np.eye(p), check_finite=False)
        W = whitener(omega) if self.method != "ols" else np.eye(n)
        kappa, lag = residual_correlation(system, x, W)
        # per whitened joint row i: its information M_i, residual variance s_i^2 and correlation kappa_i
        c = len(system.z_joint)
        blocks = system.stacked(W)[:, :p]
        resid = W @ system.residual_matrix(x) @ W.T
        s2 = np.maximum(np.diag(resid), 0.0) / max(m - p / n, 1.0)
        middle = np.zeros((p, p))
        for i in range(n):
            B = blocks[i * c : (i + 1) * c]
            middle += kappa[i] * s2[i] * (B.T @ B)
        cov = Rinv @ (Rinv.T @ middle @ Rinv) @ Rinv.T
        cov = 0.5 * (cov + cov.T)
        std = np.sqrt(np.maximum(np.diag(cov), 0.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            pct = np.where(np.abs(x) > 0, 100.0 * std / np.abs(x), np.inf)
        sv = np.linalg.svd(R, compute_uv=False)
        cols: ColumnSet = system.columns
        self.params_ = x
        self.names_ = cols.names
        self.expressions_ = cols.expressions
        self.cov_ = cov
        self.std_ = std
        self.std_percent_ = pct
        self.cond_ = float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")
        self.rms_ = system.rms(x)
        self.omega_ = omega
        self.sigma2_ = float(sigma2)
        self.n_samples_ = m
        self.notes_ = cols.notes
        self.columns_ = cols
        self.preprocessing_ = system.prepared.settings
        self.solution_ = sol
        self.R_ = R
        self.rhs_ = sol.rhs
        self.rss_ = rss
        self.whitener_ = W
        self.correlation_ = kappa
        self.effective_samples_ = float(m / np.mean(kappa))
        self.correlation_lag_ = lag

    # ------------------------------------------------------------------ predict
    def predict(self, q, dq=None, ddq=None) -> NDArray[np.float64]:
        """Joint torques (N m) of the identified linear model.

        Parameters
        ----------
        q : ndarray, shape (m, n), or Dataset
            Joint angles (rad); or a dataset, preprocessed as the identification data were (the result
            then holds the kept rows, filtered like the torque: compare it with
            ``prepare(ds, ...).tau_reference``).
        dq, ddq : ndarray, shape (m, n)
            Joint velocities (rad/s) and accelerations (rad/s^2); not given with a dataset.

        Returns
        -------
        ndarray, shape (m, n)
        """
        check_is_fitted(self)
        if isinstance(q, Dataset):
            prep = prepare(q, Preprocessing.from_settings(self.preprocessing_), n_joints=self.robot.n)
            full = linear_torque(self.columns_, self.params_, prep.q, prep.dq, prep.ddq)
            return prep.filter(full)[prep.rows]
        if dq is None or ddq is None:
            raise UsageError("predict takes (q, dq, ddq) arrays or one Dataset; dq and ddq are missing")
        return linear_torque(self.columns_, self.params_, q, dq, ddq)

    def summary(self) -> list[dict[str, Any]]:
        """One row per parameter: name, expression, value, std, std_percent, kind."""
        check_is_fitted(self)
        return [
            {
                "name": name,
                "expression": expr,
                "value": float(v),
                "std": float(s),
                "std_percent": float(pc) if np.isfinite(pc) else None,
                "kind": kind,
            }
            for name, expr, v, s, pc, kind in zip(
                self.names_,
                self.expressions_,
                self.params_,
                self.std_,
                self.std_percent_,
                self.columns_.kinds,
                strict=True,
            )
        ]


def residual_correlation(
    system: LinearSystem, x: NDArray[np.float64], whitener: NDArray[np.float64]
) -> tuple[NDArray[np.float64], int]:
    """Long-run variance factor of each whitened residual row: ``kappa_i = sum_k w_k rho_i(k)``.

    ``rho_i`` is the autocorrelation of row ``i`` of the whitened residual ``L^-1 (tau - W x)`` over
    the kept samples, summed with Bartlett weights ``w_k = 1 - |k| / (L + 1)`` up to the lag ``L`` (a
    Newey-West estimate).  ``L`` is 8 times the filter's correlation sum
    (:attr:`Prepared.noise_correlation`; the Bartlett sum then reaches 97 % of it for filtered white
    noise) and at least the Newey-West rule ``4 (m / 100)^(2/9)``.  Each ``kappa_i`` is kept at least
    at the filter's own value (what white noise through that filter gives) and at least 1.  Without
    the per-sample data (a released system) the filter's value is used.

    Parameters
    ----------
    system : LinearSystem
        The identification system.
    x : ndarray, shape (p,)
        The estimate.
    whitener : ndarray, shape (n, n)
        ``L^-1`` of the weighting.

    Returns
    -------
    kappa : ndarray, shape (n,)
        Factor per whitened row (1: independent samples).
    lag : int
        The lag ``L`` used (0 without data).
    """
    m, n = system.m, system.n
    floor = system.prepared.noise_correlation
    if system.Z is None or m < 8:
        return np.full(n, floor), 0
    return long_run_factor((system.tau() - system.predict(x)) @ whitener.T, floor)


def long_run_factor(E: NDArray[np.float64], floor: float = 1.0) -> tuple[NDArray[np.float64], int]:
    """Long-run variance factor of each column of a residual time series (see :func:`residual_correlation`).

    Parameters
    ----------
    E : ndarray, shape (m, n)
        Residuals in time order (uniform sampling).
    floor : float
        The filter's white-noise factor (:attr:`Prepared.noise_correlation`): lower bound and lag scale.

    Returns
    -------
    kappa : ndarray, shape (n,)
    lag : int
    """
    E = np.asarray(E, dtype=np.float64)
    m = len(E)
    E = E - E.mean(axis=0)
    lag = int(min(max(np.ceil(8 * floor), np.floor(4 * (m / 100.0) ** (2 / 9))), m // 4))
    if lag < 1:
        return np.full(E.shape[1], max(floor, 1.0)), 0
    acov = autocovariance(E, lag)
    var = np.where(acov[0] > 0, acov[0], 1.0)
    rho = acov[1:] / var
    kappa = 1.0 + 2.0 * (bartlett_weights(lag) @ rho)
    return np.maximum(kappa, max(floor, 1.0)), lag


def long_run_variance(E: NDArray[np.float64], lag: int) -> NDArray[np.float64]:
    """Newey-West long-run variance of each column of a time series (Bartlett weights).

    ``gamma_0 + 2 sum_{k=1..L} (1 - k / (L + 1)) gamma_k`` with ``gamma_k = sum_t d_t d_{t+k} / m`` of
    the demeaned columns ``d``; the variance of a column's mean is this divided by m.

    Parameters
    ----------
    E : ndarray, shape (m,) or (m, n)
        The series in time order, uniformly sampled (any unit u).
    lag : int
        Truncation lag L, from 0 to m - 1.

    Returns
    -------
    ndarray, shape () or (n,)
        Long-run variance (u^2), one per column.

    Raises
    ------
    UsageError
        A lag outside 0 to m - 1.
    """
    E = np.asarray(E, dtype=np.float64)
    m = len(E)
    if not 0 <= lag < max(m, 1):
        raise UsageError(
            f"the Newey-West lag is {lag}; with {m} samples it must be from 0 to {m - 1}: give a lag in that range."
        )
    D = (E - E.mean(axis=0)).reshape(m, -1)
    acov = autocovariance(D, lag)
    out = (acov[0] + 2.0 * (bartlett_weights(lag) @ acov[1:])) / m
    return out.reshape(E.shape[1:])


def autocovariance(E: NDArray[np.float64], lag: int) -> NDArray[np.float64]:
    """``sum_t e_t e_{t+k}`` for k = 0..lag of each column of E (m, n) (zero-padded FFT), (lag + 1, n): the
    lagged products, not divided by their count."""
    size = 1 << int(np.ceil(np.log2(2 * len(E))))
    F = np.fft.rfft(E, n=size, axis=0)
    return np.fft.irfft(np.abs(F) ** 2, n=size, axis=0)[: lag + 1]


def bartlett_weights(lag: int) -> NDArray[np.float64]:
    """Bartlett weights ``1 - k / (L + 1)`` for k = 1..L, (L,): the Newey-West weights of lags 1..L, which
    keep a long-run variance (or a sandwich's meat) non-negative."""
    return 1.0 - np.arange(1, lag + 1) / (lag + 1.0)


class OLS(LinkEstimator):
    """Ordinary least squares: ``x = argmin || tau - W x ||^2`` (METHOD.md section 4).

    Parameters
    ----------
    robot, friction, armature, preprocessing
        As in :class:`LinkEstimator`.
    """

    method = "ols"

    def _iterate(self, system):
        sol = self._weighted_fit(system, np.eye(system.n))
        dof = max(system.m - system.p, 1)
        return sol, system.residual_matrix(sol.x) / dof


class WLS(LinkEstimator):
    """Weighted least squares: each joint weighted by the inverse variance of its OLS residual.

    Parameters
    ----------
    robot, friction, armature, preprocessing
        As in :class:`LinkEstimator`.
    """

    method = "wls"

    def _iterate(self, system):
        start = self._weighted_fit(system, np.eye(system.n))
        return self._reweighted_fit(system, start.x, diagonal=True)


class GLS(LinkEstimator):
    """Generalised least squares with the full joint-noise covariance ``Omega = E^T E / (m - p)``.

    ``E`` is the OLS residual (m, n); the stacked noise covariance is block diagonal with m copies
    of ``Omega``.

    Parameters
    ----------
    robot, friction, armature, preprocessing
        As in :class:`LinkEstimator`.
    """

    method = "gls"

    def _iterate(self, system):
        start = self._weighted_fit(system, np.eye(system.n))
        return self._reweighted_fit(system, start.x, diagonal=False)


class IRLS(LinkEstimator):
    """Iteratively reweighted least squares: GLS with ``Omega`` of the latest residual, to convergence.

    Parameters
    ----------
    robot, friction, armature, preprocessing
        As in :class:`LinkEstimator`.
    weighting : {"full", "diagonal"}
        Full ``Omega`` (GLS steps) or its diagonal (WLS steps).
    tol : float
        Stop when the change of the estimate, ``max |dx| / (|x| + std)``, falls below ``tol``.
    max_iter : int
        Most weightings tried; an :class:`IdentificationWarning` says when that was not enough.
        The iteration converges linearly, and slowly on long recordings where a joint's weight and
        the estimate move together: each step shrinks the change by about 0.92 on the identification
        benchmark's 60,000 samples (2.4 standard deviations from the fixed point after 5 steps, 0.06
        after 50, the tolerance after 174) and more slowly on the whole TX40 recording, where a joint at
        rest has no friction direction (0.57 after 50, the tolerance after 225; 0.87 a step, 0.01 after
        50, when it had one).  A step costs about a millisecond there: the default tries 300 (with 50, a
        UR5 whose joints carry a position torque of 1 N m stopped short enough that the mixture of joint
        2 learnt a twentieth of it).  Where it does not settle (a noise-free double pendulum: 742 steps)
        the warning says so.

    Attributes
    ----------
    n_iter_ : int
        Weightings solved (after the OLS start).
    converged_ : bool
        Whether the tolerance was met.
    """

    method = "irls"

    def __init__(
        self,
        *,
        robot,
        friction: bool = True,
        armature: bool = True,
        preprocessing: Preprocessing | None = None,
        weighting: str = "full",
        tol: float = 1e-6,
        max_iter: int = 300,
    ) -> None:
        super().__init__(robot=robot, friction=friction, armature=armature, preprocessing=preprocessing)
        self.weighting = weighting
        self.tol = tol
        self.max_iter = max_iter

    def _iterate(self, system):
        if self.weighting not in ("full", "diagonal"):
            raise UsageError(f"weighting is {self.weighting!r}; IRLS weighs with 'full' or 'diagonal' Omega")
        if not (int(self.max_iter) >= 1 and self.tol > 0):
            raise UsageError(
                f"IRLS needs max_iter >= 1 and tol > 0; got max_iter={self.max_iter!r}, tol={self.tol!r}"
            )
        sol = self._weighted_fit(system, np.eye(system.n))
        x = sol.x
        converged = False
        it = 0
        omega = np.eye(system.n)
        for it in range(1, int(self.max_iter) + 1):  # noqa: B007 (it is kept)
            sol, omega = self._reweighted_fit(system, x, diagonal=self.weighting == "diagonal")
            x_new, R, rss = sol.x, sol.R, sol.rss
            dof = max(system.m * system.n - system.p, 1)
            Rinv_diag = np.sqrt(np.sum(scipy.linalg.solve_triangular(R, np.eye(system.p)) ** 2, axis=1))
            std = np.sqrt(rss / dof) * Rinv_diag
            floor = 1e-8 * float(np.abs(x_new).max(initial=0.0)) + 1e-300
            change = float(np.max(np.abs(x_new - x) / (np.abs(x_new) + std + floor)))
            x = x_new
            if change < self.tol:
                converged = True
                break
        self.n_iter_ = it
        self.converged_ = converged
        if not converged:
            warnings.warn(
                f"IRLS did not converge in {self.max_iter} iterations (last relative change {change:.3g} > tol "
                f"{self.tol:g}); raise max_iter or tol, or use GLS",
                IdentificationWarning,
                stacklevel=3,
            )
        return sol, omega


def register_estimator(cls: type[LinkEstimator], *, replace: bool = False) -> type[LinkEstimator]:
    """Add a layer-1 estimator to :data:`ESTIMATORS` under its ``method`` (usable as a class decorator).

    It is then a ``method=`` of :func:`dynid.identify.model.identify` (built there as
    ``cls(robot=..., friction=..., armature=..., preprocessing=...)``) and a ``--method`` choice of
    ``dynid identify`` and ``dynid fleet``.

    Parameters
    ----------
    cls : type
        A subclass of :class:`LinkEstimator` with a ``method`` name and its ``_iterate``.
    replace : bool
        Replace an estimator registered under the same name.

    Returns
    -------
    type
        ``cls``.

    Raises
    ------
    UsageError
        Not such a class, or a name that is taken (without ``replace``) or reserved.
    """
    if not (isinstance(cls, type) and issubclass(cls, LinkEstimator)):
        raise UsageError(f"{cls!r} is not a layer-1 estimator; subclass dynid.identify.estimators.LinkEstimator")
    name = cls.method
    if not (isinstance(name, str) and name.isidentifier()) or name in ("auto", *CONSTRAINED_METHODS):
        raise UsageError(
            f"the estimator {cls.__name__} has the method name {name!r}; give it a method attribute made of "
            f"letters, digits and underscores, other than auto and {', '.join(CONSTRAINED_METHODS)}"
        )
    if cls._iterate is LinkEstimator._iterate and cls._fit_system is LinkEstimator._fit_system:
        raise UsageError(f"the estimator {cls.__name__} does not define _iterate(system); define its weighting")
    ESTIMATORS.add(name, cls, replace=replace)
    return cls


def _copied(attrs: dict[str, Any]) -> dict[str, Any]:
    """Fitted attributes with their arrays, lists and dicts copied (the other objects shared)."""
    out = {}
    for name, value in attrs.items():
        if isinstance(value, np.ndarray):
            value = value.copy()
        elif isinstance(value, (list, dict)):
            value = type(value)(value)
        out[name] = value
    return out
