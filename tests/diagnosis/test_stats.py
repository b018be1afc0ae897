"""The diagnosis' statistics (dynid.diagnosis.stats) against closed forms and hand computations."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats as sps

from dynid.diagnosis.stats import (
    default_lag,
    diebold_mariano,
    excess_test,
    holm,
    ljung_box,
    newey_west_variance,
)
from dynid.exceptions import DataError


def _bartlett_by_loop(x: np.ndarray, lag: int) -> float:
    """The Newey-West long-run variance written out: gamma_k = sum_t d_t d_(t+k) / m, Bartlett weights."""
    d = x - x.mean()
    m = d.size
    total = sum(d[t] * d[t] for t in range(m)) / m
    for k in range(1, lag + 1):
        gamma = sum(d[t] * d[t + k] for t in range(m - k)) / m
        total += 2.0 * (1.0 - k / (lag + 1.0)) * gamma
    return float(total)


# ---------------------------------------------------------------------------- Newey-West
def test_newey_west_at_lag_0_is_the_plain_variance(rng):
    x = rng.normal(2.0, 3.0, size=257)
    assert newey_west_variance(x, lag=0) == pytest.approx(np.var(x), rel=1e-12)


def test_newey_west_by_hand_on_five_values():
    # x = 1 2 4 3 5: mean 3, d = -2 -1 1 0 2; gamma_0 = 10/5 = 2, gamma_1 = (2 - 1 + 0 + 0)/5 = 0.2,
    # gamma_2 = (-2 + 0 + 2)/5 = 0.
    x = np.array([1.0, 2.0, 4.0, 3.0, 5.0])
    assert newey_west_variance(x, lag=1) == pytest.approx(2.0 + 2.0 * 0.5 * 0.2, rel=1e-12)  # 2.2
    assert newey_west_variance(x, lag=2) == pytest.approx(2.0 + 2.0 * (2 / 3) * 0.2, rel=1e-12)  # 34/15


def test_newey_west_bartlett_sum_at_lag_2(rng):
    # a coloured series, so that gamma_1 and gamma_2 both count
    e = rng.standard_normal(300)
    x = e[2:] + 0.8 * e[1:-1] + 0.5 * e[:-2]
    assert newey_west_variance(x, lag=2) == pytest.approx(_bartlett_by_loop(x, 2), rel=1e-10)
    assert newey_west_variance(x, lag=2) > 1.5 * np.var(x)  # positive autocorrelation adds variance


def test_newey_west_default_lag_and_lag_range(rng):
    x = rng.standard_normal(100)
    assert default_lag(100) == 4 and default_lag(1) == 1 and default_lag(1000) == 6
    assert newey_west_variance(x) == pytest.approx(_bartlett_by_loop(x, 4), rel=1e-10)
    short = np.array([1.0, 2.0, 4.0, 3.0, 5.0])
    assert newey_west_variance(short, lag=50) == pytest.approx(_bartlett_by_loop(short, 4), rel=1e-12)
    with pytest.raises(DataError, match="at least 2 values; got 1"):
        newey_west_variance([1.0])


# ---------------------------------------------------------------------------- Diebold-Mariano
def test_diebold_mariano_by_hand():
    ref = np.array([3.0, 1.0, 4.0, 1.0, 5.0, 9.0, 2.0, 6.0, 5.0, 3.0])
    alt = np.array([2.0, 1.5, 3.0, 0.0, 4.0, 6.0, 2.5, 4.0, 4.0, 2.0])
    d = ref - alt  # 1 -0.5 1 1 1 3 -0.5 2 1 1: mean 1.0, var (ddof 0) 9.5 / 10 = 0.95
    assert d.mean() == pytest.approx(1.0) and np.var(d) == pytest.approx(0.95)
    res = diebold_mariano(ref, alt, lag=0)
    stat = 1.0 / math.sqrt(0.95 / 10)
    assert res.mean == pytest.approx(1.0, rel=1e-12)
    assert res.stat == pytest.approx(stat, rel=1e-12)
    assert res.p_value == pytest.approx(sps.t.sf(stat, df=9), rel=1e-10)
    assert res.blocks == 10 and res.lag == 0
    # an extra variance adds to that of the mean
    wider = diebold_mariano(ref, alt, lag=0, extra_variance=0.15)
    assert wider.stat == pytest.approx(1.0 / math.sqrt(0.095 + 0.15), rel=1e-12)
    # the default lag is the Newey-West default of the block count
    assert diebold_mariano(ref, alt).lag == default_lag(10)


def test_diebold_mariano_blocks_are_means_of_consecutive_samples(rng):
    ref, alt = rng.exponential(size=(2, 403))
    res = diebold_mariano(ref, alt, block=5, lag=2)
    d = (ref - alt)[:400].reshape(80, 5).mean(axis=1)
    same = diebold_mariano(d, np.zeros(80), lag=2)
    assert res.blocks == 80
    assert res.stat == pytest.approx(same.stat, rel=1e-12)
    assert res.p_value == pytest.approx(same.p_value, rel=1e-12)
    assert res.stat == pytest.approx(d.mean() / math.sqrt(_bartlett_by_loop(d, 2) / 80), rel=1e-10)


def test_diebold_mariano_is_antisymmetric(rng):
    ref, alt = rng.exponential(size=(2, 200))
    a, b = diebold_mariano(ref, alt, lag=3), diebold_mariano(alt, ref, lag=3)
    assert b.stat == pytest.approx(-a.stat, rel=1e-12)
    assert a.p_value + b.p_value == pytest.approx(1.0, abs=1e-12)


def test_diebold_mariano_p_values_are_uniform_under_the_null():
    rng = np.random.default_rng(11)
    p = np.array([diebold_mariano(*rng.normal(size=(2, 200)) ** 2, lag=0).p_value for _ in range(1000)])
    # equal expected losses: p uniform on (0, 1)
    assert 0.03 <= np.mean(p < 0.05) <= 0.075
    assert 0.45 <= np.mean(p < 0.5) <= 0.55
    assert sps.kstest(p, "uniform").pvalue > 0.01


def test_diebold_mariano_finds_a_better_model(rng):
    e = rng.standard_normal(1000)
    res = diebold_mariano((e + 0.5) ** 2, e**2)  # the alternative removes a bias of 0.5
    assert res.mean == pytest.approx(0.25 + np.mean(e), abs=0.1)
    assert res.p_value < 1e-6


def test_diebold_mariano_needs_eight_blocks():
    with pytest.raises(
        DataError, match=r"70 samples, 7 blocks of 10; a Diebold-Mariano test needs at least 8"
    ):
        diebold_mariano(np.ones(70), np.zeros(70), block=10)


# ---------------------------------------------------------------------------- Holm
def test_holm_on_a_known_vector():
    # sorted: 0.005 x 4 = 0.02; 0.01 x 3 = 0.03; 0.03 x 2 = 0.06; 0.04 x 1 = 0.04 -> kept at 0.06
    adjusted = holm([0.01, 0.04, 0.03, 0.005])
    np.testing.assert_allclose(adjusted, [0.03, 0.06, 0.06, 0.02], rtol=1e-12)


def test_holm_caps_at_one_keeps_order_and_handles_edges():
    np.testing.assert_allclose(holm([0.5, 0.6]), [1.0, 1.0])
    np.testing.assert_allclose(holm([0.2]), [0.2])
    assert holm([]).shape == (0,)
    rng = np.random.default_rng(3)
    p = rng.uniform(size=20)
    adj = holm(p)
    order = np.argsort(p)
    assert np.all(np.diff(adj[order]) >= 0)  # monotone in the raw p-values
    assert np.all(adj >= p) and np.all(adj <= 1.0)
    assert adj[order[0]] == pytest.approx(min(1.0, 20 * p[order[0]]))


# ---------------------------------------------------------------------------- Ljung-Box
def test_ljung_box_by_hand_on_six_values():
    # x = 1 3 2 5 4 6: mean 3.5, d = -2.5 -0.5 -1.5 1.5 0.5 2.5, sum d^2 = 17.5;
    # lag 1: 1.25 + 0.75 - 2.25 + 0.75 + 1.25 = 1.75 -> rho_1 = 0.1;
    # lag 2: 3.75 - 0.75 - 0.75 + 3.75 = 6 -> rho_2 = 12/35.
    # Q = m (m + 2) (rho_1^2 / (m - 1) + rho_2^2 / (m - 2)) = 48 (0.01 / 5 + (144/1225) / 4)
    q, p = ljung_box([1.0, 3.0, 2.0, 5.0, 4.0, 6.0], lags=2)
    expected = 48.0 * (0.01 / 5.0 + (144.0 / 1225.0) / 4.0)
    assert q == pytest.approx(expected, rel=1e-12)
    # chi^2 with 2 degrees of freedom: its tail is exp(-Q / 2)
    assert p == pytest.approx(math.exp(-expected / 2.0), rel=1e-10)


def test_ljung_box_tail_is_chi2_with_lags_degrees_of_freedom(rng):
    x = rng.standard_normal(300)
    q, p = ljung_box(x, lags=10)
    d = x - x.mean()
    rho = np.array([d[k:] @ d[:-k] for k in range(1, 11)]) / (d @ d)
    assert q == pytest.approx(300 * 302 * np.sum(rho**2 / (300 - np.arange(1, 11))), rel=1e-12)
    assert p == pytest.approx(sps.chi2.sf(q, 10), rel=1e-12)


def test_ljung_box_separates_white_from_coloured():
    rng = np.random.default_rng(5)
    p_white = np.array([ljung_box(rng.standard_normal(400), lags=10)[1] for _ in range(300)])
    assert 0.02 <= np.mean(p_white < 0.05) <= 0.09  # near its nominal level
    e = rng.standard_normal(500)
    ar = np.empty_like(e)
    ar[0] = e[0]
    for k in range(1, e.size):
        ar[k] = 0.5 * ar[k - 1] + e[k]
    assert ljung_box(ar, lags=10)[1] < 1e-10


def test_ljung_box_edge_cases():
    assert ljung_box(np.full(50, 2.0)) == (0.0, 1.0)  # constant: nothing to correlate
    q, p = ljung_box([1.0, 2.0])
    assert math.isnan(q) and math.isnan(p)  # too short for one lag
    # the lag count is cut to m - 2
    assert ljung_box([1.0, 3.0, 2.0, 5.0, 4.0, 6.0], lags=20) == ljung_box(
        [1.0, 3.0, 2.0, 5.0, 4.0, 6.0], lags=4
    )


# ---------------------------------------------------------------------------- excess test
def test_the_capped_excess_test_finds_an_excess_that_sits_in_a_few_blocks(rng):
    """A friction effect seen on a few moves of an aperiodic run: most blocks half a noise variance above
    the level, two a thousand above.  The plain test's variance is swamped by those few blocks; block means
    capped at 20 above the level keep a lower mean (still a valid test) and find it."""
    block, count = 50, 200
    loss = 2.0 + rng.chisquare(3, size=block * count) / 3.0 * 0.5
    for b in rng.choice(count, size=2, replace=False):
        loss[b * block : (b + 1) * block] += 1000.0
    assert excess_test(loss, 2.0, block=block) > 0.05
    assert excess_test(loss, 2.0, block=block, cap=20.0) < 1e-6


def test_the_capped_excess_test_keeps_its_size_under_the_null():
    rng = np.random.default_rng(5)
    block = 20
    hits = capped = 0
    for _ in range(300):
        # a heavy-tailed null (squared Student t, 3 degrees of freedom, unit mean) and a cap that bites
        z = rng.standard_t(3, size=block * 60) / np.sqrt(3.0)
        means = (z**2).reshape(-1, block).mean(axis=1)
        capped += np.count_nonzero(means > 1.0 + 0.5)
        hits += excess_test(z**2, 1.0, block=block, cap=0.5) < 0.05
    assert capped > 300 * 60 * 0.05  # the cap is reached in more than 5 % of the blocks
    assert hits / 300 <= 0.07  # at most the test's level (a capped mean is never above the true one)


def test_the_excess_test_takes_a_level_per_sample(rng):
    # Samples that do not count (mask 0) have loss 0 and level 0: the mean excess is that of the rest.
    mask = (np.arange(4000) % 400 < 300).astype(float)
    loss = mask * (1.0 + 0.01 * rng.normal(size=4000))
    assert excess_test(loss, 1.0 * mask, block=10) == pytest.approx(excess_test(loss - mask, 0.0, block=10))
    assert excess_test(loss, 1.0, block=10) > 0.99  # the old constant level: a quarter of the rows below it
    assert excess_test(loss + 0.05 * mask, 1.0 * mask, block=10) < 1e-6


def test_the_excess_test_allows_for_a_floor_measured_with_its_own_error():
    """The loss is scaled by a measured floor whose variance has a 20 % standard error: a floor drawn
    too low lifts the loss over it, which the floor taken as exact calls an excess.  The true mean sits
    exactly at the level (1.3 true noise variances), so a right test rejects about alpha of the time."""
    rng = np.random.default_rng(11)
    rel, level, block, trials = 0.2, 1.3, 10, 400
    nu = 2.0 / rel**2
    plain = aware = 0
    for _ in range(trials):
        u = rng.chisquare(nu) / nu  # the floor's variance over the true one
        loss = level * rng.chisquare(1, size=block * 300) / u
        plain += excess_test(loss, level, block=block) < 0.05
        aware += excess_test(loss, level, block=block, scaled=level, rel_se=rel, draws=4000) < 0.05
    assert plain / trials > 0.25  # the floor's error alone fires the test taken as exact
    assert 0.01 <= aware / trials <= 0.08
    # an excess well beyond what the floor's error can explain is still found
    loss = 2.0 * level * rng.chisquare(1, size=block * 300)
    assert excess_test(loss, level, block=block, scaled=level, rel_se=rel) < 0.01
    # the cap, applied per draw of the floor's error, keeps the same answer when it does not bite
    capped = excess_test(loss, level, block=block, scaled=level, rel_se=rel, cap=1e6)
    assert capped == pytest.approx(excess_test(loss, level, block=block, scaled=level, rel_se=rel), rel=1e-9)
