"""Layer 3: Gaussian mixture regression of what the model still misses (METHOD.md section 4).

``tau_err = tau - tau_link - tau_f`` is learnt as a function of ``u = [q, dq]``: a Gaussian mixture
over ``[u, tau_err]`` (EM by :class:`sklearn.mixture.GaussianMixture`, full covariances), then the
conditional mean

    E[tau_err | u] = sum_k h_k(u) (mu_y,k + S_yu,k S_uu,k^-1 (u - mu_u,k)),
    h_k(u) = pi_k N(u; mu_u,k, S_uu,k) / sum_l pi_l N(u; mu_u,l, S_uu,l),

computed here in numpy for all samples at once.

The correction must not make predictions worse when there is nothing left to learn.  :meth:`GMRCorrection.fit`
keeps blocks of consecutive samples aside (time blocks, not random samples: neighbouring samples are
correlated and would leak), fits on the rest and keeps the correction of a joint only if it lowers that
joint's RMS on the blocks kept aside by at least ``min_improvement``; otherwise the joint's correction is
zero and ``fallback_`` says why.  Inputs outside the range seen in training are clipped to it, so
the correction never extrapolates its local linear models far from the data.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray
from scipy.special import logsumexp

from dynid.exceptions import DataError, ModelFileError, UsageError
from dynid.identify._threads import one_blas_thread

__all__ = ["GMRCorrection", "conditional_mean"]

_MODES = ("vector", "per_joint", "own")
_BIC_GRID = (1, 2, 3, 4, 6, 8, 12, 16)  # mixture sizes tried by n_components="auto"
_BIC_SAMPLES = 4000  # samples of the BIC search (evenly strided); the chosen size is refitted on all


def conditional_mean(
    u: NDArray[np.float64],
    weights: NDArray[np.float64],
    means: NDArray[np.float64],
    covariances: NDArray[np.float64],
    n_in: int,
) -> NDArray[np.float64]:
    """Conditional mean of a Gaussian mixture: ``E[y | u]`` with ``x = [u, y]``.

    Parameters
    ----------
    u : ndarray, shape (m, n_in)
        Inputs.
    weights : ndarray, shape (K,)
        Mixture weights.
    means : ndarray, shape (K, n_in + n_out)
        Component means over ``[u, y]``.
    covariances : ndarray, shape (K, n_in + n_out, n_in + n_out)
        Component covariances.
    n_in : int
        Number of inputs (the first ``n_in`` coordinates).

    Returns
    -------
    ndarray, shape (m, n_out)
    """
    m = u.shape[0]
    K = len(weights)
    n_out = means.shape[1] - n_in
    logp = np.empty((K, m))
    cond = np.empty((K, m, n_out))
    for k in range(K):
        S = covariances[k]
        L = np.linalg.cholesky(S[:n_in, :n_in])
        diff = (u - means[k, :n_in]).T  # (n_in, m)
        sol = scipy.linalg.solve_triangular(L, diff, lower=True, check_finite=False)
        maha = np.einsum("im,im->m", sol, sol)
        logdet = 2.0 * np.log(np.diag(L)).sum()
        logp[k] = math.log(max(weights[k], 1e-300)) - 0.5 * (maha + logdet + n_in * math.log(2 * math.pi))
        # S_yu S_uu^-1 (u - mu) = (L^-1 S_uy)^T L^-1 (u - mu)
        A = scipy.linalg.solve_triangular(L, S[:n_in, n_in:], lower=True, check_finite=False)  # (n_in, n_out)
        cond[k] = means[k, n_in:] + sol.T @ A
    h = np.exp(logp - logsumexp(logp, axis=0))
    return np.einsum("km,kmo->mo", h, cond)


def _blocks(m: int, n_blocks: int, fraction: float) -> NDArray[np.bool_]:
    """Mask of the validation samples: every ``round(1 / fraction)``-th block of consecutive samples."""
    every = max(2, round(1.0 / fraction))
    edges = np.linspace(0, m, n_blocks + 1).astype(int)
    mask = np.zeros(m, dtype=bool)
    for b in range(n_blocks):
        if b % every == every // 2:
            mask[edges[b] : edges[b + 1]] = True
    return mask


class GMRCorrection:
    """Gaussian mixture regression of the torque residual on ``u = [q, dq]``, guarded by validation.

    Parameters
    ----------
    n_components : int or "auto"
        Mixture components, or ``"auto"``: the least BIC among 1, 2, 3, 4, 6, 8, 12, 16 up to
        ``max_components`` (on a subsample of 4,000 samples; the search stops after two sizes without
        a better BIC).
    max_components : int
        Largest mixture tried by ``"auto"``.
    mode : {"vector", "per_joint", "own"}
        ``own`` (default): one mixture per joint over ``[q_j, dq_j, tau_err_j]``; ``per_joint``: one
        mixture per joint over ``[u, tau_err_j]``; ``vector``: one mixture over ``[u, tau_err]`` (the
        paper's).  Over all of ``u`` (12 dimensions for 6 joints) a mixture fitted on one excitation
        predicts poorly on another motion (a test: held-out RMS 0.5 -> 0.12 N m with ``own``, up to
        0.5 -> 1.9 N m worse with ``vector``): the internal validation blocks share the excitation and
        cannot see that.  Use ``vector`` / ``per_joint`` only for data that cover the motions to predict.
    validation_fraction : float
        Share of the samples kept aside (in time blocks) to decide whether the correction helps.
    n_blocks : int
        Number of time blocks the samples are cut into.
    min_improvement : float
        Relative drop of a joint's validation RMS needed to keep its correction (0.02 = 2 %).
    max_samples : int
        Training samples used by EM (evenly strided in time).
    reg_covar : float
        Added to the covariance diagonals (inputs and outputs are standardised first).
    random_state : int
        Seed of EM's initialisation.

    Attributes
    ----------
    active_ : ndarray of bool, shape (n,)
        Joints whose correction is kept.
    n_components_ : list of int
        Components of each mixture.
    validation_rms_ : ndarray, shape (2, n)
        Validation RMS (N m) per joint without (row 0) and with (row 1) the correction.
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
            raise DataError(f"mode 'own' needs u = [q, dq] with 2 n = {2 * n} columns; got {d}")
        return [(np.array([j, n + j]), np.array([j])) for j in range(n)]

    def _check(
        self, u: ArrayLike, y: ArrayLike | None = None
    ) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
        u = np.atleast_2d(np.asarray(u, dtype=np.float64))
        if y is not None:
            y = np.asarray(y, dtype=np.float64)
            y = y.reshape(-1, 1) if y.ndim == 1 else y
            if y.shape[0] != u.shape[0]:
                raise DataError(
                    f"u has {u.shape[0]} rows but the residual has {y.shape[0]}; give one row per sample"
                )
        for label, a in (("u", u), ("tau_err", y)):
            if a is not None and not np.all(np.isfinite(a)):
                raise DataError(f"{label} holds non-finite values; drop or interpolate those samples")
        return u, y

    def _fit_one(self, X: NDArray[np.float64]) -> tuple[Any, int, list[float]]:
        """EM on X (standardised); with "auto", K by BIC on a subsample, then the chosen K on all of X."""
        from sklearn.exceptions import ConvergenceWarning
        from sklearn.mixture import GaussianMixture

        def fit(K: int, data: NDArray[np.float64]):
            with warnings.catch_warnings():
                # EM that stops at max_iter still gives a usable mixture; the validation decides.
                warnings.simplefilter("ignore", ConvergenceWarning)
                return GaussianMixture(
                    n_components=K,
                    covariance_type="full",
                    reg_covar=self.reg_covar,
                    random_state=self.random_state,
                    max_iter=200,
                ).fit(data)

        if self.n_components != "auto":
            K = int(self.n_components)
            gm = fit(K, X)
            return gm, K, [float(gm.bic(X))]
        sub = X[:: max(1, -(-len(X) // _BIC_SAMPLES))]
        best_K, best_bic, bics, worse = 1, np.inf, [], 0
        for K in _BIC_GRID:
            if K > int(self.max_components) or K > len(sub) // (X.shape[1] + 2):
                break
            bic = float(fit(K, sub).bic(sub))
            bics.append(bic)
            if bic < best_bic:
                best_K, best_bic, worse = K, bic, 0
            else:
                worse += 1
                if worse >= 2:
                    break
        return fit(best_K, X), best_K, bics

    # ------------------------------------------------------------------ fit / predict
    @one_blas_thread
    def fit(self, u: ArrayLike, y: ArrayLike) -> GMRCorrection:
        """Fit the mixtures on the training blocks and decide, per joint, whether to keep them.

        Parameters
        ----------
        u : array_like, shape (m, d)
            Inputs in time order, usually ``[q, dq]`` (rad, rad/s).
        y : array_like, shape (m, n)
            Torque residual (N m) in the same order.
        """
        if self.mode not in _MODES:
            raise UsageError(f"mode is {self.mode!r}; choose one of {', '.join(_MODES)}")
        if not (
            self.n_components == "auto" or (isinstance(self.n_components, int) and self.n_components >= 1)
        ):
            raise UsageError(f"n_components is {self.n_components!r}; give a positive integer or 'auto'")
        u, y = self._check(u, y)
        assert y is not None
        m, n = y.shape
        if m < 20 * self.n_blocks:
            raise DataError(
                f"the mixture regression needs at least {20 * self.n_blocks} samples to keep validation blocks "
                f"aside; got {m}: use more data or fewer blocks"
            )
        val = _blocks(m, int(self.n_blocks), float(self.validation_fraction))
        train_idx = np.flatnonzero(~val)
        train_idx = train_idx[:: max(1, -(-len(train_idx) // int(self.max_samples)))]
        self.models_ = []
        self.n_components_ = []
        self.bic_ = []
        for inp, out in self._specs(u.shape[1], n):
            X = np.hstack([u[:, inp], y[:, out]])
            mean = X[train_idx].mean(axis=0)
            scale = X[train_idx].std(axis=0)
            scale[scale <= 0] = 1.0
            gm, K, bics = self._fit_one((X[train_idx] - mean) / scale)
            self.models_.append(
                {
                    "lo": X[train_idx, : len(inp)].min(axis=0),
                    "hi": X[train_idx, : len(inp)].max(axis=0),
                    "inputs": inp,
                    "outputs": out,
                    "mean": mean,
                    "scale": scale,
                    "weights": gm.weights_,
                    "means": gm.means_,
                    "covariances": gm.covariances_,
                }
            )
            self.n_components_.append(int(K))
            self.bic_.append(bics)
        self.active_ = np.ones(n, dtype=bool)
        pred = self._raw_predict(u[val], n)
        before = np.sqrt(np.mean(y[val] ** 2, axis=0))
        after = np.sqrt(np.mean((y[val] - pred) ** 2, axis=0))
        self.validation_rms_ = np.vstack([before, after])
        helps = after <= (1.0 - float(self.min_improvement)) * before
        self.active_ = helps
        if helps.all():
            self.fallback_ = None
        else:
            off = [str(j + 1) for j in np.flatnonzero(~helps)]
            self.fallback_ = (
                f"no correction for joint{'s' if len(off) > 1 else ''} {', '.join(off)}: on the validation blocks "
                f"it did not lower the RMS by {100 * float(self.min_improvement):g} %"
            )
        self.n_outputs_ = n
        return self

    def _raw_predict(self, u: NDArray[np.float64], n: int) -> NDArray[np.float64]:
        out = np.zeros((u.shape[0], n))
        for mdl in self.models_:
            inp, outp = mdl["inputs"], mdl["outputs"]
            n_in = len(inp)
            # no extrapolation: inputs outside the training range are clipped to it
            us = (np.clip(u[:, inp], mdl["lo"], mdl["hi"]) - mdl["mean"][:n_in]) / mdl["scale"][:n_in]
            ys = conditional_mean(us, mdl["weights"], mdl["means"], mdl["covariances"], n_in)
            out[:, outp] = ys * mdl["scale"][n_in:] + mdl["mean"][n_in:]
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
        if not hasattr(self, "active_"):
            raise UsageError("this GMRCorrection is not fitted yet; call fit(u, tau_err) first")
        u, _ = self._check(u)
        if not self.active_.any():
            return np.zeros((u.shape[0], self.n_outputs_))
        return self._raw_predict(u, self.n_outputs_)

    # ------------------------------------------------------------------ files
    def to_arrays(self, prefix: str = "gmr") -> dict[str, NDArray[Any]]:
        """The fitted mixtures as named arrays (for an ``.npz`` file).

        Parameters
        ----------
        prefix : str
            Prefix of the array names.
        """
        if not hasattr(self, "active_"):
            raise UsageError("this GMRCorrection is not fitted yet; call fit(u, tau_err) first")
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
            out.active_ = np.asarray(arrays[f"{prefix}_active"], dtype=bool)
        except (KeyError, ValueError, TypeError) as err:
            raise ModelFileError(
                f"the mixture arrays are incomplete ({err}); write them with GMRCorrection.to_arrays"
            ) from None
        out.n_outputs_ = len(out.active_)
        out.n_components_ = [len(mdl["weights"]) for mdl in out.models_]
        out.fallback_ = None
        return out
