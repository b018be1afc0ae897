"""Layer 3: Gaussian mixture regression of what the model still misses (METHOD.md section 4).

``tau_err = tau - tau_link - tau_f`` is learnt as a function of ``u = [q, dq]``: a Gaussian mixture
over ``[u, tau_err]`` (EM with full covariances, :func:`fit_gaussian_mixture`), then the
conditional mean

    E[tau_err | u] = sum_k h_k(u) (mu_y,k + S_yu,k S_uu,k^-1 (u - mu_u,k)),
    h_k(u) = pi_k N(u; mu_u,k, S_uu,k) / sum_l pi_l N(u; mu_u,l, S_uu,l),

computed here in numpy for all samples at once.

The correction must not make predictions worse when there is nothing left to learn.  :meth:`GMRCorrection.fit`
keeps blocks of consecutive samples aside (time blocks, not random samples: neighbouring samples are
correlated and would leak), fits on the rest and keeps the correction of a joint only if it lowers that
joint's RMS on the blocks kept aside by at least ``min_improvement``; otherwise the joint's correction is
zero and ``fallback_`` says why.  Inputs outside the range seen in training are clipped to it, so
the correction never extrapolates its local linear models far from the data, and the correction is
weighted by the mixture's own input density (:func:`density_gate`): 1 on the states it was fitted on,
fading to zero outside them, so that on a new motion the model falls back to its physical layers
instead of holding the correction's edge value (simulated UR5, a position torque learnt on +-1.2 rad
and a motion 1.4-3.8 rad away: the edge value added 4-58 % to the physical layers' error, the gated
correction nothing).

Periodic data.  An excitation is usually one period repeated: time blocks then share their states
with the other periods, and the validation cannot see a correction that only remembers the motion.
When the inputs repeat (autocorrelation above 0.98 at some lag, at least two periods), the samples
kept aside are phase windows instead, the same windows of every period, so their states are absent
from the training samples.

Number of components.  ``n_components="auto"`` fits each size of the grid on the training samples
and keeps the one with the least RMS on the validation samples (held-out prediction error, what the
correction is for; the in-sample BIC kept adding components that fitted the training motion).

Inputs (``mode``).  ``position`` (the default of the three-layer pipeline): each joint's residual as
a function of its own angle ``q_j``, the physical home of what the rigid body and friction leave
(transmission and harmonic-drive errors, cogging, position-dependent friction): the velocity
dependence is the friction layer's.  ``own`` adds ``dq_j``; over ``[q_j, dq_j]`` one excitation
covers only a curve, and a mixture fitted along it predicted another motion poorly (simulated UR5,
60 s at 1 kHz: held-out RMS 0.23 N m with ``own`` against 0.06 with ``position``).  ``per_joint``
and ``vector`` (the paper's, ``[q, dq]`` of all joints) need data that cover the motions to predict.

Joint fit.  The conditional mean is a mixture of local linear experts under gates ``h_k(u)`` that
depend on the inputs only.  :meth:`GMRCorrection.design` gives the expert columns at fixed gates and
:meth:`GMRCorrection.set_experts` writes fitted experts back into the mixture (means and
covariances), so the three-layer pipeline can estimate the experts jointly with the link parameters
(:mod:`dynid.identify.model`).

This module holds the correction (:class:`GMRCorrection`), its density gate and its validation samples;
the mixtures' own arithmetic (EM, densities, the conditional mean) is :mod:`dynid.identify.mixture`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynid._rest import AT_REST
from dynid._threads import one_blas_thread
from dynid.data.periodic import period_of  # one detector for the package; re-exported here
from dynid.exceptions import DataError, ModelFileError, UsageError
from dynid.identify.checks import check_is_fitted
from dynid.identify.mixture import (
    Mixture,
    conditional_mean,
    fit_gaussian_mixture,
    gates,
    log_density,
    one_openmp_thread,
)

__all__ = [
    "GMRCorrection",
    "conditional_mean",
    "density_gate",
    "fit_gaussian_mixture",
    "period_of",
    "validation_mask",
]

_MODES = ("vector", "per_joint", "own", "position")
_GRID = (1, 2, 3, 4, 6, 8, 12, 16)  # mixture sizes tried by n_components="auto"
_PHASE_WINDOWS = 8  # phase windows per period when the data are periodic
_FLOOR_QUANTILE = 0.01  # the density gate is 1 above this quantile of the training inputs' density
# The gate's density has the components' input spreads this many times wider.  Measured on the identification
# benchmark (a new trajectory over the same workspace, slightly beyond the training angles of joint 4) and on
# tests/identify/test_physical_layers.py (a motion 0.1-3 rad beyond them): held-out RMS of joint 4 0.100 N m at 2,
# 0.070 at 3, 0.049 at 4, 0.051 at 6 (0.051 without the gate); the correction 3 rad away below 5 % of its
# size inside at 2, 4 and 6.  A lower floor quantile (0.001, or the least training density) gave 0.076.
_GATE_WIDTH = 4.0
# Beyond the training range of an input, the gate also fades as a Gaussian tail of this many of the input's
# standard deviations: the wide density above keeps a broad mixture (one or two components) near 1 far
# outside the states it saw.
_RANGE_MARGIN = 1.0


def density_gate(mdl: dict[str, Any], u: NDArray[np.float64]) -> NDArray[np.float64]:
    """Weight in [0, 1] of a mixture's correction at the inputs ``u`` (m, d): its own input density.

    The density is the mixture's over its inputs with every component four times as wide (so that the
    gaps between narrow components inside the training states, and a new motion's brief excursions just
    beyond them, do not count as outside; with the fitted widths, the gate cut corrections on the
    validation windows between components and the size selection chose too few; at twice the widths it
    doubled the held-out error of a joint whose new motion went slightly beyond the training angles).  The gate is 1 where that density is at least its ``log_floor`` (its 1 %
    quantile over the training inputs), ``p(u) / p_floor`` below it: outside the states the mixture was
    fitted on, its correction fades to zero like a Gaussian tail instead of holding its edge value.
    Beyond the training range of any input, the density is also multiplied by a Gaussian tail in the
    distance beyond it, ``exp(-d^2 / (2 margin^2))`` with ``d`` in the input's standard deviations and
    ``margin`` the mixture's ``range_margin`` (1 by default): a broad mixture of one or two components
    keeps a wide density near its floor far outside its states, and held a third of its correction
    3 rad beyond the training angles without it.  A mixture without a floor (files written before the
    gate) is not gated, and one without a ``range_margin`` has no range fade.

    Parameters
    ----------
    mdl : dict
        One mixture of :attr:`GMRCorrection.models_`.
    u : ndarray, shape (m, d)
        Inputs (unclipped), as given to :meth:`GMRCorrection.predict`.
    """
    moving = _moving(mdl, u)
    floor = float(mdl.get("log_floor", -np.inf))
    if not np.isfinite(floor):
        return moving
    inp = mdl["inputs"]
    n_in = len(inp)
    us = (u[:, inp] - mdl["mean"][:n_in]) / mdl["scale"][:n_in]
    covs = _GATE_WIDTH**2 * mdl["covariances"][:, :n_in, :n_in]
    logp = log_density(us, mdl["weights"], mdl["means"][:, :n_in], covs)
    margin = float(mdl.get("range_margin", np.inf))
    if np.isfinite(margin):
        # beyond the training range of any input, by how many of its standard deviations
        beyond = np.maximum(mdl["lo"] - u[:, inp], u[:, inp] - mdl["hi"]).clip(min=0.0) / mdl["scale"][:n_in]
        logp = logp - 0.5 * np.einsum("md,md->m", beyond, beyond) / margin**2
    return np.exp(np.minimum(logp - floor, 0.0)) * moving


def _moving(mdl: dict[str, Any], u: NDArray[np.float64]) -> NDArray[np.float64]:
    """1 where the mixture's joint moves, 0 where it is at rest (:data:`dynid._rest.AT_REST`).

    A joint at rest has no friction direction, and what its torque holds beyond the physical layers there
    is the stiction its last motion left, anything within the static level: no function of the angle.  A
    mixture of one joint's output is not fitted on its at-rest samples and predicts nothing there (on a
    simulated xArm 7 whose held-out motion stands joint 3 still at 8 % of its samples, the position
    mixture fitted on the stick samples of the training reversals predicted them wherever the joint
    stood: 2.84 times the held-out RMS of OLS with linear friction, 1.14 without the mixture).  Mixtures
    written before (no ``rest_speed``) and those over several joints' outputs are not gated."""
    k = int(mdl.get("rest_speed", -1))
    if k < 0 or k >= u.shape[1]:
        return np.ones(u.shape[0])
    return (np.abs(u[:, k]) >= AT_REST).astype(np.float64)


def _blocks(m: int, n_blocks: int, fraction: float) -> NDArray[np.bool_]:
    """Mask of the validation samples: every ``round(1 / fraction)``-th block of consecutive samples."""
    every = max(2, round(1.0 / fraction))
    edges = np.linspace(0, m, n_blocks + 1).astype(int)
    mask = np.zeros(m, dtype=bool)
    for b in range(n_blocks):
        if b % every == every // 2:
            mask[edges[b] : edges[b + 1]] = True
    return mask


def validation_mask(u: NDArray[np.float64], n_blocks: int, fraction: float) -> tuple[NDArray[np.bool_], str]:
    """Samples kept aside to validate a correction, and how they were chosen.

    Phase windows of every period when the inputs repeat (see the module docstring), else every
    ``round(1 / fraction)``-th of ``n_blocks`` time blocks.

    Parameters
    ----------
    u : ndarray, shape (m, d)
        Inputs in time order.
    n_blocks : int
        Time blocks (non-periodic data).
    fraction : float
        Share of the samples kept aside.
    """
    m = len(u)
    T = period_of(u)
    if T is None:
        return _blocks(
            m, n_blocks, fraction
        ), f"{n_blocks} time blocks, every {max(2, round(1 / fraction))}th kept aside"
    phase = (np.arange(m) % T) * _PHASE_WINDOWS // T
    every = max(2, round(1.0 / fraction))
    mask = (phase % every) == every // 2
    return mask, f"the same phase windows of each of {m / T:.3g} periods of {T} samples"


class GMRCorrection:
    """Gaussian mixture regression of the torque residual on ``u = [q, dq]``, guarded by validation.

    Parameters
    ----------
    n_components : int or "auto"
        Mixture components, or ``"auto"``: the size among 1, 2, 3, 4, 6, 8, 12, 16 (up to
        ``max_components``) with the least RMS on the validation samples; the search stops after two
        sizes without a better one.
    max_components : int
        Largest mixture tried by ``"auto"``.
    mode : {"own", "position", "per_joint", "vector"}
        ``own`` (default): one mixture per joint over ``[q_j, dq_j, tau_err_j]``; ``position``: over
        ``[q_j, tau_err_j]`` (the three-layer pipeline's default, see the module docstring);
        ``per_joint``: one mixture per joint over ``[u, tau_err_j]``; ``vector``: one mixture over
        ``[u, tau_err]`` (the paper's).
    validation_fraction : float
        Share of the samples kept aside (time blocks, or phase windows of periodic data) to choose the
        size and decide whether the correction helps.
    n_blocks : int
        Number of time blocks the samples are cut into (non-periodic data).
    min_improvement : float
        Relative drop of a joint's validation RMS needed to keep its correction (0.02 = 2 %).
    max_samples : int
        Training samples used by EM (evenly strided in time).
    reg_covar : float
        Added to the covariance diagonals (inputs and outputs are standardised first).
    random_state : int
        Seed of EM's initialisation.
    range_margin : float
        Beyond the training range of an input, the correction also fades as a Gaussian tail of this many
        of the input's standard deviations (:func:`density_gate`); ``inf`` turns that off.  The mixtures
        tried on the validation samples never fade this way: those samples lie inside the states the
        final mixture is fitted on, even where they lie beyond the range of the others.

    Attributes
    ----------
    active_ : ndarray of bool, shape (n,)
        Joints whose correction is kept.
    n_components_ : list of int
        Components of each mixture.
    scores_ : list of list of (int, float)
        Per mixture, the sizes tried and their validation RMS (N m, summed in quadrature over outputs).
    validation_rms_ : ndarray, shape (2, n)
        Validation RMS (N m) per joint without (row 0) and with (row 1) the correction.
    validation_ : str
        How the validation samples were chosen.
    fallback_ : str or None
        Why some or all joints fell back to zero correction.
    """

    def __init__(
        self,
        *,
        n_components: int | str = "auto",
        max_components: int = 8,
        mode: str = "own",
        validation_fraction: float = 0.25,
        n_blocks: int = 20,
        min_improvement: float = 0.02,
        max_samples: int = 10_000,
        reg_covar: float = 1e-4,
        random_state: int = 0,
        range_margin: float = _RANGE_MARGIN,
    ) -> None:
        self.n_components = n_components
        self.max_components = max_components
        self.mode = mode
        self.validation_fraction = validation_fraction
        self.n_blocks = n_blocks
        self.min_improvement = min_improvement
        self.max_samples = max_samples
        self.reg_covar = reg_covar
        self.random_state = random_state
        self.range_margin = range_margin

    def __repr__(self) -> str:
        return f"GMRCorrection(n_components={self.n_components!r}, mode={self.mode!r})"

    # ------------------------------------------------------------------ set-up
    def _specs(self, d: int, n: int) -> list[tuple[NDArray[np.intp], NDArray[np.intp]]]:
        """(input columns of u, output columns of y) of each mixture."""
        if self.mode == "vector":
            return [(np.arange(d), np.arange(n))]
        if self.mode == "per_joint":
            return [(np.arange(d), np.array([j])) for j in range(n)]
        if d != 2 * n:
            raise DataError(f"mode {self.mode!r} needs u = [q, dq] with 2 n = {2 * n} columns; got {d}")
        if self.mode == "position":
            return [(np.array([j]), np.array([j])) for j in range(n)]
        return [(np.array([j, n + j]), np.array([j])) for j in range(n)]

    @staticmethod
    def _check(u: ArrayLike) -> NDArray[np.float64]:
        """The inputs as a finite (m, d) array."""
        u = np.atleast_2d(np.asarray(u, dtype=np.float64))
        if not np.all(np.isfinite(u)):
            raise DataError("u holds non-finite values; drop or interpolate those samples")
        return u

    def _check_options(self) -> None:
        margin = float(self.range_margin)
        if not margin > 0:  # NaN too
            raise UsageError(
                f"range_margin is {self.range_margin!r}; give a positive number of standard deviations, "
                "or inf for no fade beyond the training range"
            )
        reg = float(self.reg_covar)
        if not (np.isfinite(reg) and reg >= 0):
            raise UsageError(f"reg_covar is {self.reg_covar!r}; give a finite number >= 0 (default 1e-4)")

    @classmethod
    def _check_pair(cls, u: ArrayLike, y: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Inputs (m, d) and residual (m, n), one row per sample, finite."""
        u = np.atleast_2d(np.asarray(u, dtype=np.float64))
        y = np.asarray(y, dtype=np.float64)
        y = y.reshape(-1, 1) if y.ndim == 1 else y
        if y.shape[0] != u.shape[0]:
            raise DataError(
                f"u has {u.shape[0]} rows but the residual has {y.shape[0]}; give one row per sample"
            )
        u = cls._check(u)
        if not np.all(np.isfinite(y)):
            raise DataError("tau_err holds non-finite values; drop or interpolate those samples")
        return u, y

    def _em(self, K: int, data: NDArray[np.float64]) -> Mixture:
        return fit_gaussian_mixture(data, K, reg_covar=float(self.reg_covar), random_state=self.random_state)

    def _model(
        self, X: NDArray[np.float64], n_in: int, K: int, inp, out, *, margin: float | None = None
    ) -> dict[str, Any]:
        """A mixture fitted by EM on X = [u_in, y] (standardised inside), as a dict of arrays; ``margin``
        overrides :attr:`range_margin`."""
        mean = X.mean(axis=0)
        scale = X.std(axis=0)
        scale[scale <= 0] = 1.0
        K = max(1, min(int(K), len(X) // (X.shape[1] + 2)))
        gm = self._em(K, (X - mean) / scale)
        us = (X[:, :n_in] - mean[:n_in]) / scale[:n_in]
        density = log_density(
            us, gm.weights_, gm.means_[:, :n_in], _GATE_WIDTH**2 * gm.covariances_[:, :n_in, :n_in]
        )
        return {
            "lo": X[:, :n_in].min(axis=0),
            "hi": X[:, :n_in].max(axis=0),
            "inputs": inp,
            "outputs": out,
            "mean": mean,
            "scale": scale,
            "weights": gm.weights_,
            "means": gm.means_,
            "covariances": gm.covariances_,
            "log_floor": np.array(np.quantile(density, _FLOOR_QUANTILE)),
            "range_margin": np.array(float(self.range_margin if margin is None else margin)),
        }

    @staticmethod
    def _rest_speed(d: int, n: int, out) -> int:
        """The column of ``u = [q, dq]`` holding the speed of a one-joint mixture's joint (-1: none)."""
        return n + int(out[0]) if d == 2 * n and len(out) == 1 else -1

    def _moving_model(self, u, y, inp, out, K: int, rest_speed: int, **kwargs) -> dict[str, Any]:
        """A mixture fitted on the samples where its joint moves (all of them for ``rest_speed`` -1)."""
        rows = np.arange(len(u)) if rest_speed < 0 else np.flatnonzero(np.abs(u[:, rest_speed]) >= AT_REST)
        if len(rows) < 2 * (len(inp) + len(out) + 2):  # a joint that hardly moves: fitted on every sample
            rows = np.arange(len(u))
        rows = rows[:: max(1, -(-len(rows) // int(self.max_samples)))]
        mdl = self._model(np.hstack([u[rows][:, inp], y[rows][:, out]]), len(inp), K, inp, out, **kwargs)
        mdl["rest_speed"] = np.array(rest_speed)
        return mdl

    # ------------------------------------------------------------------ fit / predict
    @one_blas_thread
    @one_openmp_thread()
    def fit(self, u: ArrayLike, y: ArrayLike) -> GMRCorrection:
        """Choose the sizes and fit the mixtures; keep, per joint, only a correction that validates.

        Parameters
        ----------
        u : array_like, shape (m, d)
            Inputs in time order, usually ``[q, dq]`` (rad, rad/s).
        y : array_like, shape (m, n)
            Torque residual (N m) in the same order.
        """
        if self.mode not in _MODES:
            raise UsageError(f"mode is {self.mode!r}; choose one of {', '.join(_MODES)}")
        self._check_options()
        if not (
            self.n_components == "auto" or (isinstance(self.n_components, int) and self.n_components >= 1)
        ):
            raise UsageError(f"n_components is {self.n_components!r}; give a positive integer or 'auto'")
        u, y = self._check_pair(u, y)
        m, n = y.shape
        if m < 20 * self.n_blocks:
            raise DataError(
                f"the mixture regression needs at least {20 * self.n_blocks} samples to keep validation blocks "
                f"aside; got {m}: use more data or fewer blocks"
            )
        specs = self._specs(u.shape[1], n)
        val, self.validation_ = validation_mask(u, int(self.n_blocks), float(self.validation_fraction))
        stride = max(1, -(-m // int(self.max_samples)))
        train_idx = np.flatnonzero(~val)[::stride]
        val_idx = np.flatnonzero(val)[::stride]
        sizes = (
            [int(self.n_components)]
            if self.n_components != "auto"
            else [K for K in _GRID if K <= int(self.max_components)]
        )
        chosen, self.scores_ = [], []
        pred_val = np.zeros((len(val_idx), n))
        for inp, out in specs:
            rest = self._rest_speed(u.shape[1], n, out)
            best, scores, worse = None, [], 0
            for K in sizes:
                mdl = self._moving_model(u[train_idx], y[train_idx], inp, out, K, rest, margin=np.inf)
                pred = self._predict_model(mdl, u[val_idx])
                score = float(np.sqrt(np.mean((y[val_idx][:, out] - pred) ** 2) * len(out)))
                scores.append((K, score))
                if best is None or score < best[1]:
                    best, worse = (K, score, pred), 0
                else:
                    worse += 1
                    if worse >= 2:
                        break
            if best is None:  # no size tried
                raise UsageError(
                    f"max_components is {self.max_components!r}; give a positive integer (the largest mixture "
                    "n_components='auto' tries)"
                )
            chosen.append(best[0])
            pred_val[:, out] = best[2]
            self.scores_.append(scores)
        before = np.sqrt(np.mean(y[val_idx] ** 2, axis=0))
        after = np.sqrt(np.mean((y[val_idx] - pred_val) ** 2, axis=0))
        self.validation_rms_ = np.vstack([before, after])
        helps = after <= (1.0 - float(self.min_improvement)) * before
        self.active_ = helps
        if helps.all():
            self.fallback_ = None
        else:
            off = [str(j + 1) for j in np.flatnonzero(~helps)]
            self.fallback_ = (
                f"no correction for joint{'s' if len(off) > 1 else ''} {', '.join(off)}: on the validation samples "
                f"({self.validation_}) it did not lower the RMS by {100 * float(self.min_improvement):g} %"
            )
        # the chosen sizes refitted on all the samples
        self.models_ = [
            self._moving_model(u, y, inp, out, K, self._rest_speed(u.shape[1], n, out))
            for (inp, out), K in zip(specs, chosen, strict=True)
        ]
        self.n_components_ = [len(mdl["weights"]) for mdl in self.models_]
        self.n_outputs_ = n
        return self

    @one_blas_thread
    @one_openmp_thread()
    def fit_mixtures(
        self, u: ArrayLike, y: ArrayLike, sizes: list[int], active: ArrayLike | None = None
    ) -> GMRCorrection:
        """Fit one mixture per output group with given sizes on all the samples, without validation.

        For callers that choose the sizes and validate the correction themselves (the joint fit of
        :mod:`dynid.identify.refine`); :meth:`fit` does both.

        Parameters
        ----------
        u : array_like, shape (m, d)
            Inputs, usually ``[q, dq]`` (rad, rad/s).
        y : array_like, shape (m, n)
            Torque residual (N m).
        sizes : list of int
            Components of each mixture (one per joint, or one for ``vector``).
        active : array_like of bool, shape (n,), optional
            Outputs whose correction is on (default all).
        """
        if self.mode not in _MODES:
            raise UsageError(f"mode is {self.mode!r}; choose one of {', '.join(_MODES)}")
        self._check_options()
        u, y = self._check_pair(u, y)
        n = y.shape[1]
        specs = self._specs(u.shape[1], n)
        if len(sizes) != len(specs):
            raise UsageError(f"sizes has {len(sizes)} entries; mode {self.mode!r} has {len(specs)} mixtures")
        self.models_ = [
            self._moving_model(u, y, inp, out, K, self._rest_speed(u.shape[1], n, out))
            for (inp, out), K in zip(specs, sizes, strict=True)
        ]
        self.n_components_ = [len(mdl["weights"]) for mdl in self.models_]
        self.active_ = np.ones(n, dtype=bool) if active is None else np.asarray(active, dtype=bool).copy()
        self.n_outputs_ = n
        self.scores_ = []
        self.validation_rms_ = np.full((2, n), np.nan)
        self.validation_ = "none (sizes given)"
        self.fallback_ = None
        return self

    @staticmethod
    def _predict_model(mdl: dict[str, Any], u: NDArray[np.float64]) -> NDArray[np.float64]:
        inp = mdl["inputs"]
        n_in = len(inp)
        # no extrapolation: inputs outside the training range are clipped to it
        us = (np.clip(u[:, inp], mdl["lo"], mdl["hi"]) - mdl["mean"][:n_in]) / mdl["scale"][:n_in]
        ys = conditional_mean(us, mdl["weights"], mdl["means"], mdl["covariances"], n_in)
        return (ys * mdl["scale"][n_in:] + mdl["mean"][n_in:]) * density_gate(mdl, u)[:, None]

    def _raw_predict(self, u: NDArray[np.float64], n: int) -> NDArray[np.float64]:
        out = np.zeros((u.shape[0], n))
        for mdl in self.models_:
            out[:, mdl["outputs"]] = self._predict_model(mdl, u)
        return out * self.active_

    def predict(self, u: ArrayLike) -> NDArray[np.float64]:
        """Correction ``E[tau_err | u]`` (N m), zero for the joints where it did not help.

        Parameters
        ----------
        u : array_like, shape (m, d)
            Inputs, as in :meth:`fit`.

        Returns
        -------
        ndarray, shape (m, n)
        """
        check_is_fitted(self, "active_", call="fit(u, tau_err)")
        u = self._check(u)
        if not self.active_.any():
            return np.zeros((u.shape[0], self.n_outputs_))
        return self._raw_predict(u, self.n_outputs_)

    # ------------------------------------------------------------------ experts (joint fit)
    def design(self, u: ArrayLike) -> list[NDArray[np.float64]]:
        """Columns of the local linear experts at the fitted gates, one array per output (joint).

        The correction of output ``j`` is ``design(u)[j] @ c_j`` with, per component ``k``, the
        coefficients ``[a_k, b_k]``: ``sum_k h_k(u) (a_k + b_k . (u_s - mu_k))``, ``h_k`` the gates of
        the mixture's input marginal and ``u_s`` the standardised inputs (clipped to the training
        range).  A joint whose correction is off gets an empty (m, 0) array.

        Parameters
        ----------
        u : array_like, shape (m, d)
            Inputs, as in :meth:`fit`.
        """
        check_is_fitted(self, "active_", call="fit(u, tau_err)")
        u = self._check(u)
        cols: list[NDArray[np.float64]] = [np.zeros((len(u), 0)) for _ in range(self.n_outputs_)]
        for mdl in self.models_:
            inp = mdl["inputs"]
            n_in = len(inp)
            us = (np.clip(u[:, inp], mdl["lo"], mdl["hi"]) - mdl["mean"][:n_in]) / mdl["scale"][:n_in]
            h = gates(us, mdl["weights"], mdl["means"][:, :n_in], mdl["covariances"][:, :n_in, :n_in])
            parts = [h] + [h * (us[:, [i]] - mdl["means"][:, i]) for i in range(n_in)]
            block = np.hstack(parts) * density_gate(mdl, u)[:, None]
            for o in mdl["outputs"]:
                if self.active_[o]:
                    cols[o] = block
        return cols

    def set_experts(self, coefs: list[NDArray[np.float64]], noise: ArrayLike) -> None:
        """Write fitted experts (see :meth:`design`) back into the mixtures.

        Parameters
        ----------
        coefs : list of ndarray
            Per output, its coefficients ``[a_1..a_K, b_1,1..b_K,1, ...]`` in the order of
            :meth:`design` (N m); empty for an output whose correction is off.
        noise : array_like, shape (n,)
            Residual variance per output (N^2 m^2), the spread of each component around its expert.
        """
        noise = np.asarray(noise, dtype=np.float64)
        for mdl in self.models_:
            n_in = len(mdl["inputs"])
            K = len(mdl["weights"])
            means = mdl["means"].copy()
            cov = mdl["covariances"].copy()
            Suu = cov[:, :n_in, :n_in]
            for i, o in enumerate(mdl["outputs"]):
                c = np.asarray(coefs[o], dtype=np.float64)
                if c.size == 0:
                    continue
                sy, my = mdl["scale"][n_in + i], mdl["mean"][n_in + i]
                a = c[:K]
                beta = c[K:].reshape(n_in, K).T / sy  # (K, n_in), per standardised input
                means[:, n_in + i] = (a - my) / sy
                Suy = np.einsum("kab,kb->ka", Suu, beta)
                cov[:, :n_in, n_in + i] = Suy
                cov[:, n_in + i, :n_in] = Suy
                for i2, o2 in enumerate(mdl["outputs"]):
                    c2 = np.asarray(coefs[o2], dtype=np.float64)
                    if c2.size == 0:
                        continue
                    beta2 = c2[K:].reshape(n_in, K).T / mdl["scale"][n_in + i2]
                    cross = np.einsum("ka,ka->k", beta, np.einsum("kab,kb->ka", Suu, beta2))
                    if i2 == i:
                        cross = cross + max(float(noise[o]), 1e-12 * sy**2) / sy**2
                    cov[:, n_in + i, n_in + i2] = cross
            mdl["means"], mdl["covariances"] = means, cov

    # ------------------------------------------------------------------ files
    def to_arrays(self, prefix: str = "gmr") -> dict[str, NDArray[Any]]:
        """The fitted mixtures as named arrays (for an ``.npz`` file).

        Parameters
        ----------
        prefix : str
            Prefix of the array names.
        """
        check_is_fitted(self, "active_", call="fit(u, tau_err)")
        arrays: dict[str, NDArray[Any]] = {
            f"{prefix}_active": self.active_,
            f"{prefix}_count": np.array(len(self.models_)),
        }
        for i, mdl in enumerate(self.models_):
            for key, value in mdl.items():
                arrays[f"{prefix}_{i}_{key}"] = np.asarray(value)
        return arrays

    @classmethod
    def from_arrays(cls, arrays: Any, prefix: str = "gmr", *, mode: str = "own") -> GMRCorrection:
        """A fitted correction from :meth:`to_arrays`' output.

        Parameters
        ----------
        arrays : mapping of str to ndarray
            E.g. an opened ``.npz`` file.
        prefix : str
            Prefix used when writing.
        mode : str
            The mode it was fitted with (for information).
        """
        out = cls(mode=mode)
        try:
            count = int(arrays[f"{prefix}_count"])
            out.models_ = [
                {
                    key: np.asarray(arrays[f"{prefix}_{i}_{key}"])
                    for key in (
                        "lo",
                        "hi",
                        "inputs",
                        "outputs",
                        "mean",
                        "scale",
                        "weights",
                        "means",
                        "covariances",
                    )
                }
                for i in range(count)
            ]
            for i, mdl in enumerate(out.models_):  # files written before the gate: no gate
                key = f"{prefix}_{i}_log_floor"
                mdl["log_floor"] = np.asarray(arrays[key] if key in arrays else -np.inf, dtype=np.float64)
                key = f"{prefix}_{i}_range_margin"  # files written before the range fade: none
                mdl["range_margin"] = np.asarray(arrays[key] if key in arrays else np.inf, dtype=np.float64)
                key = f"{prefix}_{i}_rest_speed"  # files written before the rest gate: none
                mdl["rest_speed"] = np.asarray(arrays[key] if key in arrays else -1)
            out.active_ = np.asarray(arrays[f"{prefix}_active"], dtype=bool)
        except (KeyError, ValueError, TypeError) as err:
            raise ModelFileError(
                f"the mixture arrays are incomplete ({err}); write them with GMRCorrection.to_arrays"
            ) from None
        out.n_outputs_ = len(out.active_)
        out.n_components_ = [len(mdl["weights"]) for mdl in out.models_]
        out.fallback_ = None
        out.validation_ = None
        return out
