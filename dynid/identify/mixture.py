"""Gaussian mixtures in numpy: EM with full covariances, densities, gates and the conditional mean.

The arithmetic under the mixture regression of :mod:`dynid.identify.gmr`: :func:`fit_gaussian_mixture`
(scikit-learn's EM, all components at once; :class:`Mixture` its result, :func:`one_openmp_thread` the
thread limit of its k-means start), :func:`conditional_mean` (``E[y | u]`` with ``x = [u, y]``),
:func:`gates` (the responsibilities ``h_k(u)``) and :func:`log_density` (the mixture's log-density over
its inputs).
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Iterator
from typing import NamedTuple

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

from dynid.exceptions import DataError, UsageError

__all__ = [
    "Mixture",
    "conditional_mean",
    "fit_gaussian_mixture",
    "gates",
    "log_density",
    "one_openmp_thread",
]


class Mixture(NamedTuple):
    """A fitted Gaussian mixture: weights (K,), means (K, d), covariances (K, d, d)."""

    weights_: NDArray[np.float64]
    means_: NDArray[np.float64]
    covariances_: NDArray[np.float64]
    n_iter_: int


def kmeans_labels(X: NDArray[np.float64], K: int, random_state: np.random.RandomState) -> NDArray[np.intp]:
    """Labels of one k-means run as ``sklearn.cluster.KMeans(K, n_init=1, random_state=...)`` fits it.

    scikit-learn's algorithm step by step, so the same labels from the same seed: the data centred,
    k-means++ seeding (the first centre drawn with ``choice``, then ``2 + int(log K)`` candidates drawn
    in proportion to the squared distance, the one lowering the potential most kept), Lloyd iterations
    to 300 that stop when no label changes or the centres move by at most 1e-4 of the mean variance
    (squared shift summed), an empty cluster given the samples farthest from their centres, and the
    labels of the final centres.  Importing scikit-learn (scipy.stats with it) took 0.65-0.8 s of CPU,
    a tenth of a default identification; tests/identify/test_gmr.py compares the labels with
    scikit-learn's own.
    """
    tol = float(np.mean(np.var(X, axis=0))) * 1e-4  # on the data as given, before centring
    X = X - X.mean(axis=0)
    m, d = X.shape
    norms = np.einsum("ij,ij->i", X, X)
    weight = np.ones(m)

    def sq_dist(C):  # scikit-learn's euclidean_distances(C, X, squared=True)
        out = -2 * (C @ X.T)
        out += np.einsum("ij,ij->i", C, C)[:, None]
        out += norms[None, :]
        return np.maximum(out, 0, out=out)

    centers = np.empty((K, d))
    trials = 2 + int(np.log(K))
    centers[0] = X[random_state.choice(m, p=weight / weight.sum())]
    closest = sq_dist(centers[0:1])
    potential = closest @ weight
    for c in range(1, K):
        draws = random_state.uniform(size=trials) * potential
        ids = np.clip(np.searchsorted(np.cumsum(weight * closest), draws), None, closest.size - 1)
        to_candidates = np.minimum(closest, sq_dist(X[ids]))
        pots = to_candidates @ weight.reshape(-1, 1)
        best = int(np.argmin(pots))
        potential, closest = pots[best], to_candidates[best]
        centers[c] = X[ids[best]]

    def assign(C):  # the E-step: argmin of |c|^2 - 2 x.c (|x|^2 is common to a row)
        return np.argmin(np.einsum("ij,ij->i", C, C)[None, :] - 2 * (X @ C.T), axis=1)

    labels, old = np.full(m, -1), None
    converged = False
    for _ in range(300):
        labels = assign(centers)
        counts = np.bincount(labels, minlength=K).astype(np.float64)
        sums = np.zeros((K, d))
        np.add.at(sums, labels, X)
        empty = np.flatnonzero(counts == 0)
        if len(empty):  # each empty cluster takes one of the samples farthest from their centres
            dist = ((X - centers[labels]) ** 2).sum(axis=1)
            far = np.argpartition(dist, -len(empty))[: -len(empty) - 1 : -1]
            if np.max(dist) != 0:  # all samples on their centres (fewer distinct samples than clusters): none
                for e, f in zip(empty, far, strict=True):
                    sums[labels[f]] -= X[f]
                    sums[e] = X[f]
                    counts[e] = 1.0
                    counts[labels[f]] -= 1.0
        new, biggest = sums, int(np.argmax(counts))
        for k in range(K):  # in order, as scikit-learn averages: a cluster still empty takes the biggest one's
            if counts[k] > 0:
                new[k] *= 1.0 / counts[k]
            else:
                new[k] = new[biggest]
        shift = float((np.linalg.norm(new - centers, axis=1) ** 2).sum())
        centers = new
        if old is not None and np.array_equal(labels, old):
            converged = True
            break
        if shift <= tol:
            break
        old = labels
    return labels if converged else assign(centers)


def fit_gaussian_mixture(
    X: NDArray[np.float64],
    K: int,
    *,
    reg_covar: float = 1e-4,
    random_state: int = 0,
    max_iter: int = 200,
    tol: float = 1e-3,
) -> Mixture:
    """EM for a Gaussian mixture with full covariances, as :class:`sklearn.mixture.GaussianMixture`.

    The same algorithm as scikit-learn's (one k-means start with the same seed, the same M-step with
    ``reg_covar`` on the diagonal, the same stop on the change of the mean log-likelihood) with all
    components at once in stacked arrays.  Its parameters equal scikit-learn's 1.9 to rounding (at most
    1.3e-14 apart on standardised data, with the same iteration counts; tests/identify/test_gmr.py
    checks 1e-11); it takes a fifth of the time on the small fits dynid makes (4,000 samples of 2-3
    coordinates: about 70 % of scikit-learn's time was its per-component loops and input checks).

    Parameters
    ----------
    X : ndarray, shape (m, d)
        Samples (standardised by the caller).
    K : int
        Number of components, at most ``m``.
    reg_covar : float
        Added to the diagonal of every covariance.
    random_state : int
        Seed of the k-means start.
    max_iter, tol : int, float
        EM stops after ``max_iter`` iterations or when the mean log-likelihood changes by less than ``tol``.

    Returns
    -------
    Mixture

    Notes
    -----
    The k-means start runs on OpenMP's threads: on small fits, call it within :func:`one_openmp_thread`
    (k-means spent 0.3 s per fit on a shared 2-core machine with OpenMP's default threads, 0.02 s with
    one; setting the limit costs about 5 ms, so the callers here set it once for all their fits).
    """
    X = np.asarray(X, dtype=np.float64)
    if X.ndim != 2 or X.shape[0] < 2 or not np.all(np.isfinite(X)):
        raise DataError(
            f"the mixture needs finite samples as an (m, d) array with m >= 2; got shape {X.shape}"
            + ("" if X.size == 0 or np.all(np.isfinite(X)) else " with non-finite values")
            + ": drop or interpolate the bad samples"
        )
    m, d = X.shape
    if not (isinstance(K, (int, np.integer)) and 1 <= K <= m):
        raise UsageError(f"K is {K!r}; give a whole number of components from 1 to the {m} samples")
    if not (np.isfinite(reg_covar) and reg_covar >= 0):
        raise UsageError(f"reg_covar is {reg_covar!r}; give a finite number >= 0 (default 1e-4)")
    if not isinstance(random_state, (int, np.integer)):
        raise UsageError(f"random_state is {random_state!r}; give an integer seed")
    label = np.zeros(m, dtype=np.intp) if K == 1 else kmeans_labels(X, K, np.random.RandomState(random_state))
    XT = np.ascontiguousarray(X.T)
    diag = np.arange(d)
    tiny = 10 * np.finfo(np.float64).eps

    def m_step(R):  # R: responsibilities (K, m)
        nk = R.sum(axis=1) + tiny
        means = (R @ X) / nk[:, None]
        diff = XT[None] - means[:, :, None]  # (K, d, m)
        cov = np.matmul(diff * R[:, None, :], diff.transpose(0, 2, 1)) / nk[:, None, None]
        cov[:, diag, diag] += reg_covar
        return nk, means, cov

    def singular(call, *args):  # a collapsed component's singular covariance, in one sentence
        try:
            return call(*args)
        except np.linalg.LinAlgError:
            raise DataError(
                f"a component of the {K}-component mixture collapsed onto too few distinct samples (its "
                f"covariance is singular with reg_covar {reg_covar:g}); use fewer components or a larger reg_covar"
            ) from None

    R = np.zeros((K, m))
    R[label, np.arange(m)] = 1.0
    nk, means, cov = m_step(R)
    weights = nk / m
    bound = -np.inf
    n_iter = 0
    while n_iter < int(max_iter):
        n_iter += 1
        previous = bound
        logp = singular(_component_log_densities, X, weights, means, cov)  # weighted, (K, m), as the gates'
        norm = _logsumexp(logp)
        with np.errstate(under="ignore"):
            R = np.exp(logp - norm)
        nk, means, cov = m_step(R)
        weights = nk / nk.sum()
        bound = float(norm.mean())
        if abs(bound - previous) < tol:
            break
    singular(np.linalg.cholesky, cov)  # the returned covariances too are positive definite
    return Mixture(weights, means, cov, n_iter)


@contextlib.contextmanager
def one_openmp_thread() -> Iterator[None]:
    """OpenMP limited to one thread in the calling thread (the k-means starts of EM)."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="openmp"):
        yield


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
        L, sol, logp[k] = _component(u, weights[k], means[k, :n_in], S[:n_in, :n_in])
        # S_yu S_uu^-1 (u - mu) = (L^-1 S_uy)^T L^-1 (u - mu)
        A = scipy.linalg.solve_triangular(L, S[:n_in, n_in:], lower=True, check_finite=False)  # (n_in, n_out)
        cond[k] = means[k, n_in:] + sol.T @ A
    h = np.exp(logp - _logsumexp(logp))
    return np.einsum("km,kmo->mo", h, cond)


def _component(
    u: NDArray[np.float64], weight: float, mean: NDArray[np.float64], cov: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """One component over the inputs: Cholesky factor L of ``cov``, ``L^-1 (u - mean)^T`` (d, m) and
    ``log(weight N(u; mean, cov))`` (m,)."""
    n_in = u.shape[1]
    L = np.linalg.cholesky(cov)
    sol = scipy.linalg.solve_triangular(L, (u - mean).T, lower=True, check_finite=False)
    maha = np.einsum("im,im->m", sol, sol)
    logdet = 2.0 * np.log(np.diag(L)).sum()
    return L, sol, math.log(max(weight, 1e-300)) - 0.5 * (maha + logdet + n_in * math.log(2 * math.pi))


_DENSITY_VALUES = 2_000_000  # values of one block of the stacked densities' temporaries (K d rows, 16 MB)


def _component_log_densities(u, weights, means, covs) -> NDArray[np.float64]:
    """Weighted log-density (K, m) of each component of a Gaussian mixture at the inputs ``u`` (m, d).

    All components at once (stacked Cholesky factors): :func:`_component`'s values to rounding, in a
    third of the time on the gates of a default identification.  The rows go in blocks, so that the
    temporaries stay near 16 MB whatever the mixture and the recording (a vector-mode mixture of 16
    components over 12 inputs on 360,000 samples needed 1.1 GB in one block).
    """
    m, n_in = u.shape
    L = np.linalg.cholesky(covs)  # (K, d, d)
    Linv = np.linalg.inv(L)
    logdet = 2.0 * np.log(np.diagonal(L, axis1=1, axis2=2)).sum(axis=1)
    const = np.log(np.maximum(weights, 1e-300)) - 0.5 * (logdet + n_in * math.log(2 * math.pi))
    out = np.empty((len(weights), m))
    step = max(1, _DENSITY_VALUES // max(1, len(weights) * n_in))
    for a in range(0, m, step):
        block = u[a : a + step]
        sol = np.matmul(Linv, block.T[None] - means[:, :, None])  # L^-1 (u - mean)^T, (K, d, rows)
        out[:, a : a + len(block)] = const[:, None] - 0.5 * np.einsum("kdm,kdm->km", sol, sol)
    return out


def _logsumexp(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """``log(sum(exp(a), axis=0))`` without overflow (scipy's logsumexp, without its 2 ms of checks)."""
    top = a.max(axis=0)
    top = np.where(np.isfinite(top), top, 0.0)
    with np.errstate(divide="ignore", under="ignore"):
        return np.log(np.exp(a - top).sum(axis=0)) + top


def gates(
    u: NDArray[np.float64],
    weights: NDArray[np.float64],
    means: NDArray[np.float64],
    covs: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Responsibilities ``h_k(u)`` (m, K) of a Gaussian mixture over the inputs."""
    logp = _component_log_densities(u, weights, means, covs)
    return np.exp(logp - _logsumexp(logp)).T


def log_density(
    u: NDArray[np.float64],
    weights: NDArray[np.float64],
    means: NDArray[np.float64],
    covs: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Log-density (m,) of a Gaussian mixture over the inputs (standardised units)."""
    return _logsumexp(_component_log_densities(u, weights, means, covs))
