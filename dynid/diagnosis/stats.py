"""Statistics of the gap diagnosis: tests that respect residuals which are not white.

Identification residuals are low-passed (parallel filtering), coloured and often periodic, so every
test here either works on a long-run (Newey-West) variance or resamples whole blocks:

* :func:`newey_west_variance` and :func:`diebold_mariano`: is one model's held-out loss lower than
  another's, sample by sample, beyond what the serial correlation of the loss difference allows?
* :func:`excess_test`: is a held-out loss above its floor, beyond the serial correlation and the
  error that the training data's parameter uncertainty leaves on held-out data?
* :func:`holm`: Holm's step-down correction of several p-values (family-wise error rate); the fleet's
  drift tests use it too.
* :func:`ar_model`, :func:`ar_noise`, :func:`bootstrap_null`, :func:`gamma_tail`: a sieve bootstrap's
  noise model, its draws, the null distribution drawn a chunk at a time, and its moment-matched tail.
* :func:`block_bootstrap_ci`: interval of a ratio of means by the moving-block bootstrap.
* :func:`ljung_box`: whiteness of a residual.
* :func:`principal_angles`: how nearly two column spaces coincide.
* :func:`structured_change_test`: a parameter change against linear hypotheses by chi^2 and BIC.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.fft
import scipy.linalg
from numpy.typing import ArrayLike, NDArray
from scipy import stats

from dynid.exceptions import DataError
from dynid.identify.estimators import autocovariance, long_run_variance

__all__ = [
    "DMResult",
    "HypothesisFit",
    "ar_model",
    "ar_noise",
    "block_bootstrap_ci",
    "bootstrap_null",
    "default_lag",
    "diebold_mariano",
    "excess_test",
    "gamma_tail",
    "holm",
    "ljung_box",
    "newey_west_variance",
    "principal_angles",
    "structured_change_test",
]


AR_BURN = 500
"""Rows of each drawn noise series (:func:`ar_noise`) that the circular wrap of its filtering may reach,
discarded."""
BOOTSTRAP_CHUNK = 25
"""Bootstrap draws per call of the statistic in :func:`bootstrap_null` (one matrix product each)."""


def ar_model(x: NDArray[np.float64], order: int) -> tuple[NDArray[np.float64], float]:
    """Yule-Walker AR(``order``) of a series: the filter denominator ``[1, -phi_1, ...]`` and the
    innovations' std (the order is capped at a tenth of the series' length)."""
    m = x.size
    order = max(1, min(int(order), m // 10))
    acov = autocovariance((x - x.mean())[:, None], order)[:, 0] / m
    if acov[0] <= 0:
        return np.array([1.0]), 0.0
    phi = scipy.linalg.solve_toeplitz(acov[:order], acov[1 : order + 1])
    var = float(acov[0] - phi @ acov[1 : order + 1])
    return np.concatenate([[1.0], -phi]), float(np.sqrt(max(var, 1e-12 * acov[0])))


def ar_noise(
    models: list[tuple[NDArray[np.float64], float]],
    length: int,
    draws: int,
    rng: np.random.Generator,
    cache: dict[int, NDArray[np.complex128]] | None = None,
) -> NDArray[np.float64]:
    """``draws`` series of every joint's noise, shape (draws, length, n): white noise through each joint's
    autoregressive filter (:func:`ar_model`), in the frequency domain, the first :data:`AR_BURN` rows
    (where the circular wrap reaches) discarded.  A sieve bootstrap's draws (Buhlmann 1997).  ``cache``
    keeps the filters' frequency responses per length between calls."""
    size = scipy.fft.next_fast_len(length + AR_BURN, real=True)
    cache = {} if cache is None else cache
    if size not in cache:
        cache[size] = np.stack([scale / scipy.fft.rfft(a, size) for a, scale in models])  # (n, f)
    gains = cache[size]
    white = scipy.fft.rfft(rng.standard_normal((draws, len(models), size)), axis=2)
    drawn = scipy.fft.irfft(white * gains[None], size, axis=2)[:, :, size - length :]
    return drawn.transpose(0, 2, 1)


def bootstrap_null(
    statistic: Callable[[int], NDArray[np.float64]], draws: int, *, chunk: int = BOOTSTRAP_CHUNK
) -> NDArray[np.float64]:
    """A bootstrap's null distribution, drawn ``chunk`` draws at a time.

    Parameters
    ----------
    statistic : callable
        ``statistic(d)`` draws ``d`` new samples (from the caller's generator, so the draws continue
        from one call to the next) and returns the statistic of each, shape (n, d).
    draws : int
        Draws in all (at least 1).
    chunk : int
        Draws per call: enough for a matrix product, few enough to bound the memory.

    Returns
    -------
    ndarray, shape (n, draws)
        The draws in order; :func:`gamma_tail` takes its tail.
    """
    return np.concatenate(
        [statistic(min(chunk, draws - start)) for start in range(0, draws, chunk)], axis=1
    )


def gamma_tail(observed: NDArray[np.float64], null: NDArray[np.float64]) -> NDArray[np.float64]:
    """Upper-tail p-values (n,) of statistics ``observed`` (n,) against bootstrap draws ``null`` (n, draws):
    a gamma matched to the draws' mean and variance, row by row (1 where the draws do not define one)."""
    mean = null.mean(axis=1)
    var = null.var(axis=1, ddof=1)
    p = np.ones(observed.shape[0])
    for j in range(observed.shape[0]):
        if mean[j] > 0 and var[j] > 0 and np.isfinite(observed[j]):
            p[j] = float(stats.gamma.sf(observed[j], a=mean[j] ** 2 / var[j], scale=var[j] / mean[j]))
    return p


def default_lag(m: int) -> int:
    """Newey-West truncation lag for ``m`` observations: ``floor(4 (m / 100)^(2/9))``, at least 1."""
    return max(1, math.floor(4.0 * (max(m, 1) / 100.0) ** (2.0 / 9.0)))


def newey_west_variance(x: ArrayLike, lag: int | None = None) -> float:
    """Long-run variance of a series: ``gamma_0 + 2 sum_k (1 - k / (L + 1)) gamma_k`` (Bartlett weights).

    Parameters
    ----------
    x : array_like, shape (m,)
        The series (any unit u).
    lag : int, optional
        Truncation lag L; default :func:`default_lag`.

    Returns
    -------
    float
        Long-run variance (u^2); the variance of the mean is this divided by m
        (:func:`dynid.identify.estimators.long_run_variance`, at least ``1e-300``).
    """
    x = np.asarray(x, dtype=float)
    m = x.size
    if m < 2:
        raise DataError(f"a long-run variance needs at least 2 values; got {m}: give a longer series.")
    lag = default_lag(m) if lag is None else int(min(max(lag, 0), m - 1))
    return max(float(long_run_variance(x, lag)), 1e-300)


@dataclass(frozen=True)
class DMResult:
    """Result of a Diebold-Mariano test.

    Attributes
    ----------
    mean : float
        Mean loss difference (loss of the reference minus loss of the alternative): positive when the
        alternative is better.
    stat : float
        ``mean / sqrt(long-run variance / m)``.
    p_value : float
        One-sided p-value of "the alternative has a lower expected loss".
    lag : int
        Newey-West lag used (in blocks).
    blocks : int
        Number of block means the test ran on.
    """

    mean: float
    stat: float
    p_value: float
    lag: int
    blocks: int


def diebold_mariano(
    loss_ref: ArrayLike,
    loss_alt: ArrayLike,
    *,
    block: int = 1,
    lag: int | None = None,
    extra_variance: float = 0.0,
    cap: float | None = None,
) -> DMResult:
    """One-sided Diebold-Mariano test: is ``loss_alt`` lower than ``loss_ref`` on average?

    The per-sample loss difference is first averaged over consecutive blocks of ``block`` samples
    (a low-passed residual is correlated over many samples; block means keep the Newey-West lag
    short), then its mean is compared with its Newey-West standard error.

    Parameters
    ----------
    loss_ref, loss_alt : array_like, shape (m,)
        Per-sample losses of the reference and of the alternative model on the same samples.
    block : int
        Samples per block mean (1: none).
    lag : int, optional
        Newey-West lag on the block means; default :func:`default_lag` of the block count.
    extra_variance : float
        A variance added to that of the mean difference, for a part of it that is fixed over the whole
        run and so invisible to the serial correlation (a model's parameter error).
    cap : float, optional
        Upper bound of a block mean of the difference (as in :func:`excess_test`: the capped mean is
        never above the true one, so the one-sided test stays valid, while a gain made on a few moves no
        longer swamps the variance it is divided by); the result's ``mean`` is then the capped one.

    Returns
    -------
    DMResult
    """
    d = np.asarray(loss_ref, dtype=float) - np.asarray(loss_alt, dtype=float)
    mean, var_mean, lag, count = _block_mean(
        d, block, lag, "the loss difference", "a Diebold-Mariano test", cap=cap
    )
    stat = mean / math.sqrt(var_mean + max(float(extra_variance), 0.0))
    # Student t with count - 1 degrees of freedom: conservative for few blocks (Harvey et al. 1997).
    p = float(stats.t.sf(stat, df=count - 1))
    return DMResult(mean=mean, stat=stat, p_value=p, lag=lag, blocks=count)


def _means_of_blocks(x: NDArray[np.float64], block: int, count: int) -> NDArray[np.float64]:
    """Means of the first ``count`` blocks of ``block`` samples of ``x``."""
    return x[: count * block].reshape(count, block).mean(axis=1)


def _block_mean(x: NDArray[np.float64], block: int, lag: int | None, what: str, test: str, cap=None):
    """Mean of a series, the variance of that mean from its block means (Newey-West), the lag used and
    the block count; a clear error when there are fewer than 8 blocks.  With ``cap``, every block mean is
    first lowered to at most ``cap``."""
    block = max(1, int(block))
    count = x.size // block
    if count < 8:
        raise DataError(
            f"{what} has {x.size} samples, {count} blocks of {block}; {test} needs at least 8 blocks: give "
            "longer held-out data."
        )
    means = _means_of_blocks(x, block, count)
    if cap is not None:
        means = np.minimum(means, float(cap))
    lag = default_lag(count) if lag is None else int(lag)
    return float(means.mean()), newey_west_variance(means, lag) / count, lag, count


def excess_test(
    loss: ArrayLike,
    level: float,
    weights: ArrayLike = (),
    *,
    block: int = 1,
    lag: int | None = None,
    draws: int = 20000,
    cap: float | None = None,
    scaled: ArrayLike | None = None,
    rel_se: float | None = None,
) -> float:
    """One-sided p-value of "the mean of ``loss`` is above ``level`` plus the estimation term".

    Under the null hypothesis the mean loss is ``level + sum_i w_i z_i^2 + e``, where the ``z_i`` are
    independent standard normal (a model's parameter error, fixed over the whole held-out run, seen through
    the eigenvalues ``w_i`` of its effect on the loss) and ``e`` is the sampling error of the mean,
    normal with the Newey-West variance of the block means (Student t, as in :func:`diebold_mariano`).
    The estimation term is integrated by Monte Carlo with a fixed seed (reproducible); without weights
    this is the Diebold-Mariano test of ``loss`` against the constant ``level``.

    With ``cap``, every block mean of ``loss - level`` is first lowered to at most ``cap``: the capped
    mean is never above the true one, so the test stays valid (conservative), while an excess that sits in
    a few blocks (a friction effect seen on a few moves of an aperiodic run: one block at 800 noise
    variances beside a median of 4) no longer swamps the variance that the test divides by.

    Parameters
    ----------
    loss : array_like, shape (m,)
        Per-sample loss.
    level : float or array_like, shape (m,)
        Its expected value when the model is right and its parameters exact (per sample: zero where a
        sample does not count).
    weights : array_like, shape (p,)
        Non-negative eigenvalues of the parameter error's contribution to the mean loss: their sum is
        its expected value.
    block, lag
        As in :func:`diebold_mariano`.
    draws : int
        Monte Carlo draws of the estimation term.
    cap : float, optional
        Upper bound of a block mean of ``loss - level`` (same unit as the loss); None: no bound.
    scaled, rel_se
        The part of ``level`` (same shape) that is a multiple of the true noise variance, when the loss
        is scaled by a noise floor that is itself measured, its variance with relative standard error
        ``rel_se`` (:attr:`dynid.validation.metrics.NoiseFloor.rel_se`).  A floor measured too low raises
        the loss over it and the true level alike, so that part of the level is divided by the floor's
        error ``u`` (measured over true variance), taken as ``chi^2_nu / nu`` with ``nu = 2 / rel_se^2``
        (Satterthwaite, as :meth:`~dynid.validation.metrics.NoiseFloor.std_interval`), and integrated by
        Monte Carlo with the estimation term.  None, zero or NaN: the floor is taken as exact.
    """
    x = np.asarray(loss, dtype=float) - np.asarray(level, dtype=float)
    mean, var_mean, _, count = _block_mean(x, block, lag, "the loss", "an excess test", cap=cap)
    se = math.sqrt(var_mean)
    w = np.asarray(weights, dtype=float).ravel()
    w = w[w > 1e-12 * max(float(w.max()), 1e-300)] if w.size else w
    floor_known = scaled is not None and rel_se is not None and math.isfinite(rel_se) and rel_se > 0
    if not w.size and not floor_known:
        return float(stats.t.sf(mean / se, df=count - 1))
    rng = np.random.default_rng(0)
    q = (rng.standard_normal((draws, w.size)) ** 2) @ w if w.size else np.zeros(draws)
    if floor_known:
        nu = 2.0 / float(rel_se) ** 2
        u = rng.chisquare(nu, draws) / nu
        b = max(1, int(block))
        xb = _means_of_blocks(x, b, count)
        sb = _means_of_blocks(np.broadcast_to(np.asarray(scaled, dtype=float), x.shape), b, count)
        if cap is None:
            mean = xb.mean() - (1.0 / u - 1.0) * sb.mean()
        else:  # capped block means, a few million at a time
            step = max(1, 2_000_000 // count)
            mean = np.concatenate(
                [
                    np.minimum(xb[None, :] - np.outer(1.0 / u[i : i + step] - 1.0, sb), float(cap)).mean(axis=1)
                    for i in range(0, draws, step)
                ]
            )
    return float(np.mean(stats.t.sf((mean - q) / se, df=count - 1)))


def holm(p_values: ArrayLike) -> NDArray[np.float64]:
    """Holm's step-down adjusted p-values (controls the family-wise error rate).

    Parameters
    ----------
    p_values : array_like, shape (k,)

    Returns
    -------
    ndarray, shape (k,)
        Adjusted p-values in the input order; reject where ``adjusted < alpha``.
    """
    p = np.asarray(p_values, dtype=float)
    k = p.size
    if k == 0:
        return p.copy()
    order = np.argsort(p)
    adj = np.empty(k)
    running = 0.0
    for rank, idx in enumerate(order):
        running = max(running, min(1.0, (k - rank) * p[idx]))
        adj[idx] = running
    return adj


def wald_logp(beta: ArrayLike, cov: ArrayLike) -> float:
    """Log p-value of the Wald test that ``beta`` is zero, with covariance ``cov`` (chi^2 on its rank;
    directions of zero variance are left out; 0 when none is left)."""
    beta = np.asarray(beta, dtype=float)
    cov = np.asarray(cov, dtype=float)
    lam, U = np.linalg.eigh(0.5 * (cov + cov.T))
    keep = lam > 1e-10 * max(float(lam.max(initial=0.0)), 1e-300)
    if not keep.any():
        return 0.0
    z = U[:, keep].T @ beta
    return float(stats.chi2.logsf(float(np.sum(z**2 / lam[keep])), int(keep.sum())))


def screened_holm(p_values: ArrayLike, evidence: ArrayLike, top: int) -> NDArray[np.float64]:
    """Holm over every test, and Holm over the ``top`` tests that independent evidence ranks first, at
    half the level each: ``min(1, 2 min(holm_all, holm_top))`` (1 for the others in the second family).

    ``evidence`` (smaller is stronger) must not depend on the data the p-values come from: the
    candidates ranked on the training data alone, their p-values from the held-out data.  Under the
    null the ranking then picks its family without looking at the held-out noise, so each family's Holm
    holds its half of the family-wise error rate, and the union holds the whole.  A candidate the
    training data already point at is tested among ``top``, not among all.

    Parameters
    ----------
    p_values : array_like, shape (k,)
    evidence : array_like, shape (k,)
        Ranking key from independent data (e.g. a log p-value on the training data).
    top : int
        Size of the screened family (0: Holm over all alone, not halved).

    Returns
    -------
    ndarray, shape (k,)
        Adjusted p-values in the input order.
    """
    p = np.asarray(p_values, dtype=float)
    all_ = holm(p)
    if top <= 0 or p.size == 0:
        return all_
    first = np.argsort(np.asarray(evidence, dtype=float), kind="stable")[:top]
    screened = np.ones_like(p)
    screened[first] = holm(p[first])
    return np.minimum(1.0, 2.0 * np.minimum(all_, screened))


def block_bootstrap_ci(
    num: ArrayLike,
    den: float,
    *,
    block: int,
    level: float = 0.9,
    reps: int = 200,
    rng: np.random.Generator | None = None,
) -> tuple[float, float, float]:
    """Moving-block bootstrap interval of ``mean(num) / den``.

    Parameters
    ----------
    num : array_like, shape (m,)
        Per-sample values (e.g. squared residuals, N^2 m^2).
    den : float
        Fixed denominator (e.g. the noise variance, same unit).
    block : int
        Block length (samples).
    level : float
        Coverage of the interval.
    reps : int
        Bootstrap replications.
    rng : numpy.random.Generator, optional
        Default ``np.random.default_rng(0)`` (reproducible).

    Returns
    -------
    (estimate, low, high) : tuple of float
    """
    x = np.asarray(num, dtype=float)
    m = x.size
    est = float(x.mean() / den) if m else float("nan")
    if m < 2:
        return est, float("nan"), float("nan")
    rng = np.random.default_rng(0) if rng is None else rng
    block = int(min(max(block, 1), m))
    starts_max = m - block + 1
    count = max(1, math.ceil(m / block))
    csum = np.concatenate([[0.0], np.cumsum(x)])
    block_sums = csum[block:] - csum[:-block]  # (starts_max,)
    picks = rng.integers(0, starts_max, size=(reps, count))
    means = block_sums[picks].sum(axis=1) / (count * block)
    lo, hi = np.quantile(means / den, [(1 - level) / 2, (1 + level) / 2])
    return est, float(lo), float(hi)


def ljung_box(x: ArrayLike, lags: int = 20) -> tuple[float, float]:
    """Ljung-Box statistic and p-value of "the series is white" over ``lags`` lags.

    Parameters
    ----------
    x : array_like, shape (m,)
    lags : int

    Returns
    -------
    (Q, p_value) : tuple of float
    """
    x = np.asarray(x, dtype=float)
    m = x.size
    lags = int(min(lags, m - 2))
    if lags < 1:
        return float("nan"), float("nan")
    d = x - x.mean()
    c0 = float(d @ d)
    if c0 <= 0:
        return 0.0, 1.0
    rho = np.array([float(d[k:] @ d[:-k]) / c0 for k in range(1, lags + 1)])
    q = m * (m + 2) * float(np.sum(rho**2 / (m - np.arange(1, lags + 1))))
    return q, float(stats.chi2.sf(q, lags))


def principal_angles(A: ArrayLike, B: ArrayLike) -> NDArray[np.float64]:
    """Principal angles (rad, ascending) between the column spaces of A and B (same row count).

    :func:`scipy.linalg.subspace_angles` of their column spaces, where directions whose singular value is
    below ``1e-10`` of the largest count as absent (numerically rank-deficient columns); an empty column
    space is at right angles to every other.

    Parameters
    ----------
    A : array_like, shape (r, ka)
    B : array_like, shape (r, kb)

    Returns
    -------
    ndarray, shape (min(ka, kb),)
    """
    qa = _orth(np.asarray(A, dtype=float))
    qb = _orth(np.asarray(B, dtype=float))
    if qa.shape[1] == 0 or qb.shape[1] == 0:
        return np.array([math.pi / 2])
    return np.sort(scipy.linalg.subspace_angles(qa, qb))


def _orth(A: NDArray[np.float64]) -> NDArray[np.float64]:
    """Orthonormal basis of the column space, directions below 1e-10 of the largest dropped."""
    if A.size == 0:
        return A.reshape(A.shape[0], 0)
    return scipy.linalg.orth(A, rcond=1e-10)


@dataclass(frozen=True)
class HypothesisFit:
    """Fit of one structured hypothesis ``delta = A theta`` to a parameter change.

    Attributes
    ----------
    name : str
    k : int
        Free parameters of the hypothesis.
    chi2 : float
        ``min_theta (delta - A theta)^T C^-1 (delta - A theta)``.
    dof : int
        Degrees of freedom left.
    p_value : float
        Goodness of fit (chi^2 with ``dof`` degrees of freedom).
    bic : float
        ``chi2 + k ln(n_obs)``.
    theta : ndarray, shape (k,)
        Fitted values.
    at_bound : bool
        Its one parameter was held at its lower bound (the free fit fell below what is physically possible).
    theta_se : ndarray, shape (k,) or None
        Standard error of each fitted value; NaN where the change does not determine it (a direction the
        hypothesis' columns leave free, where ``theta`` is the least-norm value).
    """

    name: str
    k: int
    chi2: float
    dof: int
    p_value: float
    bic: float
    theta: NDArray[np.float64]
    at_bound: bool = False
    theta_se: NDArray[np.float64] | None = None


def structured_change_test(
    delta: ArrayLike,
    cov: ArrayLike,
    hypotheses: dict[str, ArrayLike],
    *,
    n_obs: int,
    lower: dict[str, float] | None = None,
) -> list[HypothesisFit]:
    """Fit a parameter change against linear hypotheses by generalised least squares.

    Parameters
    ----------
    delta : array_like, shape (p,)
        Identified minus nominal parameters.
    cov : array_like, shape (p, p)
        Covariance of delta.
    hypotheses : dict of str to array_like (p, k)
        ``delta = A theta`` for each hypothesis; ``"none"`` (A with no column) is always added.
    n_obs : int
        Number of observations behind the estimate (the BIC penalty is ``k ln(n_obs)``).
    lower : dict of str to float, optional
        Lower bounds of one-parameter hypotheses, by name (an armature change of at least minus the
        nominal armature: the armature cannot be negative).  A fit below its bound is held at the bound
        (the bounded least squares of one parameter) and its chi^2 is that of the bound.

    Returns
    -------
    list of HypothesisFit
        Sorted by BIC (best first).
    """
    delta = np.asarray(delta, dtype=float)
    cov = np.asarray(cov, dtype=float)
    p = delta.size
    # Whitening by the pseudo-inverse square root (the covariance may be near singular).
    w, v = np.linalg.eigh(0.5 * (cov + cov.T))
    keep = w > max(w.max(), 1e-300) * 1e-12
    W = (v[:, keep] / np.sqrt(w[keep])).T
    dw = W @ delta
    rank = int(keep.sum())
    out = []
    for name, A in {"none": np.zeros((p, 0)), **hypotheses}.items():
        A = np.asarray(A, dtype=float).reshape(p, -1)
        Aw = W @ A
        bounded = False
        se = np.zeros(0)
        if Aw.shape[1]:
            theta, *_ = np.linalg.lstsq(Aw, dw, rcond=1e-10)
            se = _theta_se(Aw)
            k = int(np.linalg.matrix_rank(Aw, tol=1e-8 * max(np.abs(Aw).max(), 1e-300)))
            low = (lower or {}).get(name)
            if low is not None and theta.size == 1 and theta[0] < low:
                theta, bounded = np.array([float(low)]), True
        else:
            theta, k = np.zeros(0), 0
        chi2 = float(np.sum((dw - Aw @ theta) ** 2)) if Aw.shape[1] else float(dw @ dw)
        dof = max(rank - k, 1)
        out.append(
            HypothesisFit(
                name=name,
                k=k,
                chi2=chi2,
                dof=dof,
                p_value=float(stats.chi2.sf(chi2, dof)),
                bic=chi2 + k * math.log(max(n_obs, 2)),
                theta=theta,
                at_bound=bounded,
                theta_se=se,
            )
        )
    return sorted(out, key=lambda h: h.bic)


def _theta_se(Aw: NDArray[np.float64]) -> NDArray[np.float64]:
    """Standard errors of a whitened least-squares fit's values; NaN for a value its columns leave free."""
    _, sv, Vt = np.linalg.svd(Aw, full_matrices=False)
    tol = 1e-10 * max(float(sv[0]) if sv.size else 0.0, 1e-300)
    on = sv > tol
    V, s_on = Vt[on].T, sv[on]
    se = np.sqrt(np.sum((V / s_on) ** 2, axis=1))
    # a value is determined when its unit vector lies in the row space of the columns
    free = 1.0 - np.sum(V**2, axis=1) > 1e-8
    se[free] = np.nan
    return se
