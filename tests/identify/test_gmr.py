"""Layer 3: Gaussian mixture regression learns what is smooth and leaves noise alone."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from dynid.exceptions import DataError, UsageError
from dynid.identify.gmr import (
    GMRCorrection,
    conditional_mean,
    fit_gaussian_mixture,
    period_of,
    validation_mask,
)


def motion(t: np.ndarray, phase: float) -> tuple[np.ndarray, np.ndarray]:
    """Two joints' positions (rad) and velocities (rad/s) along t (s)."""
    w = np.array([0.31, 0.53])
    q = np.sin(np.outer(t, w) + phase) + 0.3 * np.sin(np.outer(t, 2.7 * w) + 2 * phase)
    dq = np.cos(np.outer(t, w) + phase) * w + 0.3 * 2.7 * w * np.cos(np.outer(t, 2.7 * w) + 2 * phase)
    return q, dq


def unmodelled(q: np.ndarray, dq: np.ndarray) -> np.ndarray:
    """A smooth torque the model lacks (N m): position ripple plus a velocity-dependent term."""
    return 0.5 * np.sin(2 * q) + 0.3 * np.tanh(dq / 0.2)


def test_conditional_mean_matches_the_textbook_formula(rng) -> None:
    K, n_in, n_out = 3, 2, 2
    w = rng.dirichlet(np.ones(K))
    mu = rng.normal(size=(K, n_in + n_out))
    A = rng.normal(size=(K, n_in + n_out, n_in + n_out))
    S = A @ A.transpose(0, 2, 1) + 0.5 * np.eye(n_in + n_out)
    u = rng.normal(size=(7, n_in))
    expected = []
    for x in u:
        h = np.array([w[k] * multivariate_normal(mu[k, :n_in], S[k, :n_in, :n_in]).pdf(x) for k in range(K)])
        h /= h.sum()
        expected.append(
            sum(
                h[k]
                * (mu[k, n_in:] + S[k, n_in:, :n_in] @ np.linalg.solve(S[k, :n_in, :n_in], x - mu[k, :n_in]))
                for k in range(K)
            )
        )
    np.testing.assert_allclose(conditional_mean(u, w, mu, S, n_in), np.array(expected), rtol=1e-10)


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("K", [1, 3, 6])
def test_the_mixture_em_is_scikit_learns(rng, d, K) -> None:
    # the same start, steps and stop as sklearn's GaussianMixture: equal parameters to rounding
    from sklearn.mixture import GaussianMixture

    q = np.sin(np.linspace(0.0, 60.0, 3000)) * 2 + 0.1 * rng.standard_normal(3000)
    cols = [
        q,
        np.cos(q) + 0.01 * rng.standard_normal(3000),
        0.3 * np.sin(3 * q) + 0.05 * rng.standard_normal(3000),
    ]
    X = np.column_stack(cols[:1] + cols[3 - d + 1 :])
    X = (X - X.mean(axis=0)) / X.std(axis=0)
    ref = GaussianMixture(K, covariance_type="full", reg_covar=1e-4, random_state=3, max_iter=200).fit(X)
    got = fit_gaussian_mixture(X, K, reg_covar=1e-4, random_state=3)
    assert got.n_iter_ == ref.n_iter_
    np.testing.assert_allclose(got.weights_, ref.weights_, rtol=0, atol=1e-12)
    np.testing.assert_allclose(got.means_, ref.means_, rtol=0, atol=1e-11)
    np.testing.assert_allclose(got.covariances_, ref.covariances_, rtol=0, atol=1e-11)


def test_the_kmeans_start_is_scikit_learns_to_the_label(rng) -> None:
    """The mixture's k-means start (scikit-learn is not imported for it): the same labels from the same
    seed, on clustered, plain and rounded data (ties), one to three coordinates, 2 to 8 clusters."""
    import warnings

    from sklearn.cluster import KMeans

    from dynid.identify.mixture import kmeans_labels

    for case in range(24):
        m, d, K = int(rng.integers(20, 3000)), int(rng.integers(1, 4)), int(rng.integers(2, 9))
        X = rng.standard_normal((m, d))
        if case % 3 == 0:
            X[: m // 2] += 3.0
        if case % 4 == 0:
            X = np.round(X, 1)  # many equal samples and equidistant ones
        if case % 5 == 0:  # fewer distinct samples than clusters: empty clusters stay where scikit-learn puts them
            X = np.repeat(X[: max(1, K // 2)], m // max(1, K // 2) + 1, axis=0)[:m]
        for seed in (0, 7):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # fewer distinct points than clusters, on rounded data
                want = KMeans(n_clusters=K, n_init=1, random_state=np.random.RandomState(seed)).fit(X).labels_
            assert np.array_equal(kmeans_labels(X, K, np.random.RandomState(seed)), want), (case, seed, m, d, K)
    # two distinct points and four clusters: empty clusters take the farthest samples, as scikit-learn's do
    X = np.repeat([[0.0, 0.0], [1.0, 1.0]], 10, axis=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        want = KMeans(n_clusters=4, n_init=1, random_state=np.random.RandomState(1)).fit(X).labels_
    assert np.array_equal(kmeans_labels(X, 4, np.random.RandomState(1)), want)


def test_stacked_component_densities_equal_one_at_a_time(rng, monkeypatch) -> None:
    from scipy.special import logsumexp

    import dynid.identify.mixture as mixture_module
    from dynid.identify.mixture import _component, _component_log_densities, _logsumexp

    monkeypatch.setattr(mixture_module, "_DENSITY_VALUES", 70)  # blocks of 7 rows: 400 rows in 58 blocks

    K, d = 5, 2
    w = rng.dirichlet(np.ones(K))
    mu = rng.normal(size=(K, d))
    A = rng.normal(size=(K, d, d))
    S = A @ A.transpose(0, 2, 1) + 0.1 * np.eye(d)
    u = 3 * rng.normal(size=(400, d))
    got = _component_log_densities(u, w, mu, S)
    expected = np.array([_component(u, w[k], mu[k], S[k])[2] for k in range(K)])
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-10)
    np.testing.assert_allclose(_logsumexp(got), logsumexp(got, axis=0), rtol=1e-14, atol=1e-12)
    far = np.array([[-np.inf, 0.0, -1e300], [-np.inf, -1e3, -1e300]])  # underflow and empty columns
    np.testing.assert_array_equal(_logsumexp(far), logsumexp(far, axis=0))


def test_the_mixture_em_recovers_known_components(rng) -> None:
    w = np.array([0.3, 0.7])
    mu = np.array([[-2.0, 1.0], [1.5, -0.5]])
    S = np.array([[[0.2, 0.05], [0.05, 0.1]], [[0.3, -0.1], [-0.1, 0.2]]])
    k = rng.random(40_000) < w[0]
    X = np.where(
        k[:, None], rng.multivariate_normal(mu[0], S[0], k.size), rng.multivariate_normal(mu[1], S[1], k.size)
    )
    got = fit_gaussian_mixture(X, 2, reg_covar=1e-9)
    order = np.argsort(got.means_[:, 0])
    np.testing.assert_allclose(got.weights_[order], w, atol=0.01)
    np.testing.assert_allclose(got.means_[order], mu, atol=0.02)
    np.testing.assert_allclose(got.covariances_[order], S, atol=0.02)


def test_learns_a_smooth_unmodelled_torque(rng) -> None:
    t = np.arange(12_000) * 0.01
    q, dq = motion(t, 0.0)
    y = unmodelled(q, dq) + 0.05 * rng.normal(size=q.shape)
    gmr = GMRCorrection().fit(np.hstack([q, dq]), y)
    assert gmr.active_.all() and gmr.fallback_ is None
    t2 = np.arange(3000) * 0.01
    q2, dq2 = motion(t2, 1.3)  # another motion: held out
    y2 = unmodelled(q2, dq2) + 0.05 * rng.normal(size=q2.shape)
    before = np.sqrt(np.mean(y2**2, axis=0))
    after = np.sqrt(np.mean((y2 - gmr.predict(np.hstack([q2, dq2]))) ** 2, axis=0))
    assert np.all(after < 0.4 * before)


@pytest.mark.parametrize("mode", ["own", "vector"])
def test_pure_noise_is_left_alone(rng, mode) -> None:
    t = np.arange(8000) * 0.01
    q, dq = motion(t, 0.0)
    gmr = GMRCorrection(mode=mode).fit(np.hstack([q, dq]), 0.1 * rng.normal(size=q.shape))
    assert not gmr.active_.any()
    assert "did not lower the RMS" in gmr.fallback_
    q2, dq2 = motion(np.arange(2000) * 0.01, 0.7)
    y2 = 0.1 * rng.normal(size=q2.shape)
    pred = gmr.predict(np.hstack([q2, dq2]))
    assert np.sqrt(np.mean((y2 - pred) ** 2)) <= np.sqrt(np.mean(y2**2))


def test_round_trip_through_arrays(rng) -> None:
    t = np.arange(4000) * 0.01
    q, dq = motion(t, 0.0)
    u = np.hstack([q, dq])
    gmr = GMRCorrection(n_components=3).fit(u, unmodelled(q, dq))
    again = GMRCorrection.from_arrays(gmr.to_arrays())
    np.testing.assert_allclose(again.predict(u), gmr.predict(u), atol=1e-12)


def test_bad_gmr_input_is_refused(rng) -> None:
    u = rng.normal(size=(100, 4))
    with pytest.raises(DataError, match="needs at least 400 samples"):
        GMRCorrection().fit(u, rng.normal(size=(100, 2)))
    with pytest.raises(UsageError, match="mode is 'joint'; choose one of vector, per_joint, own"):
        GMRCorrection(mode="joint").fit(u, rng.normal(size=(100, 2)))
    with pytest.raises(DataError, match="u has 100 rows but the residual has 99"):
        GMRCorrection().fit(u, rng.normal(size=(99, 2)))


def test_experts_written_back_reproduce_the_design(rng) -> None:
    t = np.arange(6000) * 0.01
    q, dq = motion(t, 0.0)
    u = np.hstack([q, dq])
    for mode in ("position", "own"):
        gmr = GMRCorrection(mode=mode).fit_mixtures(u, unmodelled(q, dq), [3, 4])
        design = gmr.design(u)
        coefs = [rng.normal(size=D.shape[1]) for D in design]
        gmr.set_experts(coefs, noise=[0.01, 0.01])
        expected = np.column_stack([D @ c for D, c in zip(design, coefs, strict=True)])
        np.testing.assert_allclose(gmr.predict(u), expected, rtol=1e-9, atol=1e-12)
        for mdl in gmr.models_:  # still a valid mixture
            assert np.all(np.linalg.eigvalsh(mdl["covariances"]) > 0)


def test_periodic_inputs_are_validated_on_unseen_phases(rng) -> None:
    t = np.arange(9000) * 0.01  # three periods of 30 s
    w = 2 * np.pi / 30.0
    q = np.column_stack([np.sin(w * t), np.sin(2 * w * t + 1)])
    u = np.hstack([q, np.gradient(q, t, axis=0)])
    assert period_of(u + 1e-3 * rng.normal(size=u.shape)) == pytest.approx(3000, abs=3)
    mask, how = validation_mask(u, 20, 0.25)
    assert "phase windows" in how and mask.mean() == pytest.approx(0.25, abs=0.01)
    np.testing.assert_array_equal(mask[:3000], mask[3000:6000])  # the same phases in every period
    assert period_of(rng.normal(size=(5000, 3))) is None
    assert "time blocks" in validation_mask(rng.normal(size=(5000, 3)), 20, 0.25)[1]


def _broad(rng, margin: float) -> tuple[GMRCorrection, np.ndarray]:
    """A one-component mixture of a linear torque of q on q in [-1.3, 1.3] rad (its widest gate)."""
    t = np.arange(6000) * 0.01
    q, dq = motion(t, 0.0)
    y = 0.8 * q + 0.02 * rng.normal(size=q.shape)
    u = np.hstack([q, dq])
    return GMRCorrection(n_components=1, range_margin=margin).fit(u, y), u


def test_the_correction_fades_beyond_the_training_range(rng) -> None:
    gmr, u = _broad(rng, 1.0)
    assert gmr.active_.all()
    inside = np.sqrt(np.mean(gmr.predict(u) ** 2, axis=0))
    # inside the training range the fade does nothing: the same mixture without it predicts the same
    plain = GMRCorrection.from_arrays(
        {**gmr.to_arrays(), **{f"gmr_{i}_range_margin": np.inf for i in range(2)}}
    )
    np.testing.assert_allclose(gmr.predict(u), plain.predict(u), rtol=1e-12, atol=1e-12)
    far = u + np.array([5.0, 5.0, 0.0, 0.0])  # 2.4-5 rad beyond the training angles, at the training speeds
    outside = np.sqrt(np.mean(gmr.predict(far) ** 2, axis=0))
    assert np.all(outside < 0.05 * inside), (outside, inside)
    # the broad mixture's own density gate (components four times as wide) holds most of the edge value
    held = np.sqrt(np.mean(plain.predict(far) ** 2, axis=0))
    assert np.all(held > 0.3 * inside), (held, inside)
    # a step just beyond the range keeps most of the correction
    near = np.sqrt(np.mean(gmr.predict(u + np.array([0.1, 0.1, 0.0, 0.0])) ** 2, axis=0))
    assert np.all(near > 0.7 * inside), (near, inside)


@pytest.mark.parametrize("margin", [0.0, -1.0, float("nan")])
def test_a_range_margin_that_is_not_positive_is_refused(rng, margin) -> None:
    u = rng.normal(size=(400, 2))
    with pytest.raises(UsageError, match=r"range_margin is .*give a positive number"):
        GMRCorrection(n_components=1, range_margin=margin).fit(u, u[:, :1])


@pytest.mark.parametrize("reg", [-1e-4, float("nan"), float("inf")])
def test_a_covariance_regularisation_that_is_not_finite_and_nonnegative_is_refused(rng, reg) -> None:
    u = rng.normal(size=(400, 2))
    with pytest.raises(UsageError, match=r"reg_covar is .*give a finite number >= 0"):
        GMRCorrection(n_components=1, reg_covar=reg).fit(u, u[:, :1])
    with pytest.raises(UsageError, match=r"reg_covar is .*give a finite number >= 0"):
        fit_gaussian_mixture(u, 2, reg_covar=reg)


@pytest.mark.parametrize(
    ("X", "K", "message"),
    [
        (np.ones(10), 1, r"an \(m, d\) array with m >= 2; got shape \(10,\)"),
        (np.ones((1, 2)), 1, r"m >= 2; got shape \(1, 2\)"),
        (np.array([[0.0, 1.0], [np.nan, 2.0], [1.0, 1.0]]), 1, "with non-finite values"),
        (np.ones((5, 2)), 6, "K is 6; give a whole number of components from 1 to the 5 samples"),
        (np.ones((5, 2)), 0, "K is 0"),
    ],
)
def test_bad_mixture_input_is_refused(X, K, message) -> None:
    with pytest.raises((DataError, UsageError), match=message):
        fit_gaussian_mixture(X, K)


def test_a_collapsed_component_without_regularisation_is_refused_in_one_sentence() -> None:
    X = np.repeat(np.array([[0.0, 0.0], [1.0, 2.0], [3.0, 1.0]]), 10, axis=0)  # 3 distinct points
    with pytest.raises(DataError, match="a component of the 3-component mixture collapsed"):
        fit_gaussian_mixture(X, 3, reg_covar=0.0)


def test_files_written_before_the_range_fade_keep_their_predictions(rng) -> None:
    gmr, u = _broad(rng, 1.0)
    arrays = {k: v for k, v in gmr.to_arrays().items() if not k.endswith("_range_margin")}
    old = GMRCorrection.from_arrays(arrays)
    far = u + np.array([5.0, 5.0, 0.0, 0.0])
    again = GMRCorrection.from_arrays(gmr.to_arrays())
    np.testing.assert_array_equal(again.predict(far), gmr.predict(far))
    assert np.all(np.abs(old.predict(far)).max(axis=0) > 10 * np.abs(gmr.predict(far)).max(axis=0))


@pytest.mark.parametrize("mode", ["position", "own"])
def test_a_joint_at_rest_gets_no_correction_and_teaches_none(rng, mode) -> None:
    """A joint standing still between motions holds whatever stiction its last motion left (here +-2 N m,
    its sign by the last direction): no function of the angle.  The mixture is fitted on the moving
    samples only and predicts nothing at rest, so another motion that stops elsewhere is not given the
    training's stick torque; a file written before the rule has no such gate."""
    t = np.arange(12_000) * 0.01
    q, dq = motion(t, 0.0)
    stop = (np.sin(0.9 * t) > 0.6)[:, None]  # stands still 30 % of the time, at the angles it stopped at
    for j in range(2):
        for k in np.flatnonzero(stop[:, 0])[1:]:
            q[k, j] = q[k - 1, j]
    dq = np.where(stop, 0.0, dq)
    last = np.sign(np.maximum.accumulate(np.where(dq != 0, np.arange(len(t))[:, None], 0), axis=0))
    ripple = 0.5 * np.sin(2 * q)
    stick = 2.0 * np.where(stop, np.sign(np.cos(3 * q)) * last, 0.0)  # an angle-locked stick torque
    y = ripple + stick + 0.05 * rng.normal(size=q.shape)
    u = np.hstack([q, dq])
    gmr = GMRCorrection(mode=mode).fit(u, y)
    assert gmr.active_.all()
    pred = gmr.predict(u)
    np.testing.assert_array_equal(pred[stop[:, 0]], 0.0)
    moving = ~stop[:, 0]
    # fitted on the moving samples, where the ripple is: the stick torque did not bend it
    assert np.sqrt(np.mean((pred[moving] - ripple[moving]) ** 2)) < 0.1
    # another motion that stops: nothing predicted at rest, the ripple where it moves
    q2, dq2 = motion(np.arange(3000) * 0.01, 1.3)
    dq2[:500] = 0.0
    pred2 = gmr.predict(np.hstack([q2, dq2]))
    np.testing.assert_array_equal(pred2[:500], 0.0)
    assert np.sqrt(np.mean((pred2[500:] - 0.5 * np.sin(2 * q2[500:])) ** 2)) < 0.15
    old = GMRCorrection.from_arrays({k: v for k, v in gmr.to_arrays().items() if not k.endswith("_rest_speed")})
    assert np.all(np.abs(old.predict(u)[stop[:, 0]]).max(axis=0) > 0.1)
