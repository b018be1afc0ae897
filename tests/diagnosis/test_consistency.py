"""The parameter-constancy test between the training and the held-out run (dynid.diagnosis.consistency)."""

from __future__ import annotations

import numpy as np
import pytest

from dynid.diagnosis.consistency import LEAD_COST, Consistency, parameter_consistency
from dynid.diagnosis.crossfold import CrossFold
from dynid.diagnosis.stats import holm

RATE = 100.0  # Hz


def _motion(freqs, amps, seconds, phase):
    t = np.arange(0.0, seconds, 1.0 / RATE)
    dq = np.stack(
        [
            sum(a * np.cos(2 * np.pi * f * t + p) for f, a, p in zip(fr, am, ph, strict=True))
            for fr, am, ph in zip(freqs, amps, phase, strict=True)
        ],
        axis=1,
    )
    ddq = np.gradient(dq, 1.0 / RATE, axis=0)
    return dq, ddq


def _columns(dq, ddq):
    """Two joints, each its own inertia, viscous and Coulomb friction and offset: (m, 2, 8)."""
    m = dq.shape[0]
    X = np.zeros((m, 2, 8))
    for j in range(2):
        X[:, j, 4 * j : 4 * j + 4] = np.column_stack(
            [ddq[:, j], dq[:, j], np.tanh(dq[:, j] / 0.02), np.ones(m)]
        )
    return X


def _noise(rng, m, std=0.05, tau=0.1):
    """White plus AR(1) noise of equal std, per joint."""
    a = np.exp(-1.0 / (RATE * tau))
    e = rng.standard_normal((m, 2)) * std * np.sqrt(1 - a**2)
    ar = np.zeros((m, 2))
    for i in range(1, m):
        ar[i] = a * ar[i - 1] + e[i]
    return ar + rng.standard_normal((m, 2)) * std


def _case(seed: int, quadratic: float, noise_seed: int | None = None):
    """A periodic training run (3 x 5 s) and a held-out run of other, faster motion (20 s); ``quadratic``: a
    drag on joint 2 growing with the square of its speed, which the columns lack (N m s^2/rad^2).  Its best
    linear stand-in (viscous and Coulomb friction) is steeper on the faster run."""
    rng = np.random.default_rng(seed)
    noise_rng = rng if noise_seed is None else np.random.default_rng(10_000 + noise_seed)
    theta = np.array([0.8, 0.5, 0.3, 0.1, 0.4, 0.3, 0.2, -0.05])
    runs = []
    for freqs, gain, seconds in (
        ([[0.2, 0.6], [0.4, 0.8]], 1.0, 15.0),
        ([[0.13, 0.37], [0.29, 0.71]], 2.0, 20.0),
    ):
        phase = rng.uniform(0, 2 * np.pi, (2, 2))
        dq, ddq = _motion(freqs, gain * np.array([[1.0, 0.5], [1.2, 0.4]]), seconds, phase)
        X = _columns(dq, ddq)
        y = np.einsum("mnk,k->mn", X, theta) + _noise(noise_rng, dq.shape[0])
        y[:, 1] += quadratic * dq[:, 1] * np.abs(dq[:, 1])
        runs.append((X, y))
    (X_tr, y_tr), (X_ho, y_ho) = runs
    w_tr = np.ones_like(y_tr) / 0.07
    w_ho = np.ones_like(y_ho) / 0.07
    return CrossFold(X_tr, y_tr, w_tr, X_ho, y_ho, w_ho, 5)


def _period_noise(cf: CrossFold) -> np.ndarray:
    """The training run's deviation from its mean over its three periods, scaled to the noise's variance
    (what :func:`dynid.validation.noise.periodic_deviation` gives on prepared data)."""
    y = cf.y_tr.reshape(3, -1, cf.n)
    return ((y - y.mean(axis=0)) * np.sqrt(3 / 2)).reshape(-1, cf.n)


def test_an_effect_the_columns_lack_makes_the_runs_disagree_on_its_joint_only():
    cf = _case(1, quadratic=0.1)
    c = parameter_consistency(cf, order=10)
    assert c.cost[1] >= LEAD_COST and c.p_joint[1] < 1e-3
    assert c.cost[0] < LEAD_COST and c.p_joint[0] > 0.05
    assert c.leads(0.05).tolist() == [False, True]
    # The cross-fitted baseline absorbs most of the drag on the held-out run: about 2.3 noise variances
    # are left there, while the training run pays 0.5-0.7 of its residual for it.
    left = np.mean(cf.residual() ** 2, axis=0) / 0.05**2 / 2
    assert left[1] < 3.0


def test_a_smaller_effect_is_found_where_the_cross_fitted_baseline_leaves_little_of_it():
    cf = _case(2, quadratic=0.05)
    c = parameter_consistency(cf, order=10)
    left = np.mean(cf.residual() ** 2, axis=0) / 0.05**2 / 2
    assert left[1] < 1.5  # inside the excess test's tolerance of 0.5 noise variance
    assert c.p_joint[1] < 1e-3 and c.cost[1] > 5 * c.null_mean[1]


def test_on_the_right_model_the_test_keeps_its_size_and_no_lead_is_raised():
    p = np.array([parameter_consistency(_case(seed, quadratic=0.0), order=10).p_joint for seed in range(40)])
    costs = np.array([parameter_consistency(_case(seed, quadratic=0.0), order=10).cost for seed in range(5)])
    # Holm over two joints at 5 %: at most one run in 20 in expectation; 5 of 40 allows for the
    # bootstrap's gamma tail.
    assert np.sum(p.min(axis=1) < 0.05) <= 5
    assert np.all(costs < LEAD_COST)


def test_noise_modelled_on_the_training_periods_holds_none_of_the_effect():
    # The drag is periodic in the periodic training run, so it drops out of the deviation over the periods:
    # the null is the same with and without it (same motion, same noise), and the drag is still found.
    free, drag = _case(1, 0.0, noise_seed=1), _case(1, 0.1, noise_seed=1)
    a = parameter_consistency(free, order=10, noise=_period_noise(free))
    b = parameter_consistency(drag, order=10, noise=_period_noise(drag))
    np.testing.assert_allclose(b.null_mean, a.null_mean, rtol=1e-9)
    assert b.noise_source == "training periods" and b.to_dict(0.05)["noise_source"] == "training periods"
    assert b.leads(0.05).tolist() == [False, True] and b.p_joint[1] < 1e-3
    assert parameter_consistency(drag, order=10).noise_source == "training residual"


def test_noise_modelled_on_the_training_periods_keeps_the_size():
    p = np.array([parameter_consistency(cf, order=10, noise=_period_noise(cf)).p_joint
                  for cf in (_case(seed, quadratic=0.0) for seed in range(40))])  # fmt: skip
    assert np.sum(p.min(axis=1) < 0.05) <= 5


@pytest.mark.parametrize("quadratic", [0.0, 0.05])
def test_the_result_is_reproducible(quadratic):
    a = parameter_consistency(_case(3, quadratic), order=10)
    b = parameter_consistency(_case(3, quadratic), order=10)
    np.testing.assert_array_equal(a.p_joint, b.p_joint)
    np.testing.assert_array_equal(a.cost, b.cost)


def test_the_per_joint_p_value_is_what_holm_adjusts():
    c = parameter_consistency(_case(1, quadratic=0.1), order=10)
    assert np.all(c.p_raw <= c.p_joint)
    np.testing.assert_allclose(holm(c.p_raw), c.p_joint, rtol=0, atol=0)
    assert c.to_dict(0.05)["p_raw"] == c.p_raw.tolist()


def test_a_lead_needs_the_cost_and_the_joints_own_p_value():
    # LEAD_COST is set on the largest cost over a run's joints, so it allows for their number itself: the
    # p-value beside it is the joint's own.  A joint whose adjusted p misses alpha while its own does not
    # is a lead; a cost below the threshold, or a wide null on the joint, is not.
    c = Consistency(
        cost=np.array([LEAD_COST + 0.01, LEAD_COST + 0.01, LEAD_COST - 0.01]),
        null_mean=np.array([0.05, 0.15, 0.05]),
        p_joint=np.array([0.06, 0.3, 1e-4]),
        p_raw=np.array([0.02, 0.1, 3e-5]),
    )
    assert c.leads(0.05).tolist() == [True, False, False]
    assert c.to_dict(0.05)["lead_joint"] == [True, False, False]
