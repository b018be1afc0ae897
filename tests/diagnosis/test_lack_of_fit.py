"""The training run's lack of fit against the pure error of its repeated periods (dynid.diagnosis.lack_of_fit)."""

from __future__ import annotations

import numpy as np
import pytest

from dynid.data.dataset import Dataset
from dynid.data.preparation import Preprocessing, prepare
from dynid.diagnosis.fitting import WeightedFit
from dynid.diagnosis.lack_of_fit import LEAD_MISFIT, QUANTISATION_FACTOR, LackOfFit, training_lack_of_fit

RATE = 200.0  # Hz
PERIOD = 5.0  # s


def _noise(rng, m, std=0.05, tau=0.1):
    """White plus AR(1) noise of equal std, per joint (the field cases' colour)."""
    a = np.exp(-1.0 / (RATE * tau))
    e = rng.standard_normal((m, 2)) * std * np.sqrt(1 - a**2)
    ar = np.zeros((m, 2))
    ar[0] = rng.standard_normal(2) * std
    for i in range(1, m):
        ar[i] = a * ar[i - 1] + e[i]
    return ar + rng.standard_normal((m, 2)) * std


def _columns(dq, ddq):
    """Two joints, each its own inertia, viscous and Coulomb friction and offset: (m, 2, 8)."""
    m = dq.shape[0]
    X = np.zeros((m, 2, 8))
    for j in range(2):
        X[:, j, 4 * j : 4 * j + 4] = np.column_stack([ddq[:, j], dq[:, j], np.tanh(dq[:, j] / 0.02), np.ones(m)])
    return X


def _fit(seed: int, drag: float, periods: int = 3):
    """A periodic run of ``periods`` x 5 s, prepared as the diagnosis prepares it, and the columns' weighted
    fit.  ``drag``: a torque on joint 2 growing with the square of its speed, which the columns lack; its
    mean square over the run's, in units of the noise's variance after the filter, is returned too."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, periods * PERIOD, 1.0 / RATE)
    w0 = 2 * np.pi / PERIOD
    phase = rng.uniform(0, 2 * np.pi, (2, 3))
    q = np.stack(
        [sum(a / (k * w0) * np.sin(k * w0 * t + phase[j, k - 1]) for k, a in zip((1, 2, 3), (0.8, 0.5, 0.3), strict=True))
         for j in range(2)],
        axis=1,
    )  # fmt: skip
    dq = np.gradient(q, 1.0 / RATE, axis=0)
    ddq = np.gradient(dq, 1.0 / RATE, axis=0)
    theta = np.array([0.8, 0.5, 0.3, 0.1, 0.4, 0.3, 0.2, -0.05])
    effect = np.zeros_like(q)
    effect[:, 1] = drag * dq[:, 1] * np.abs(dq[:, 1])
    noise = _noise(rng, t.size)
    tau = np.einsum("mnk,k->mn", _columns(dq, ddq), theta) + effect + noise
    prep = prepare(Dataset(t, q, tau, dq=dq, ddq=ddq), Preprocessing(cutoff=10.0), n_joints=2)
    rows = prep.rows[::2]
    X = prep.filter(_columns(prep.dq, prep.ddq))[rows]
    y = prep.filter(prep.tau)[rows]
    fit = WeightedFit(X, y, np.ones_like(y) / 0.07)
    # The part of the effect the columns cannot fit, over the filtered noise's variance: what the misfit
    # estimates.
    g = prep.filter(effect)[rows]
    ew = (g / 0.07).reshape(-1)
    left = (ew - fit.Q @ (fit.Q.T @ ew)).reshape(g.shape) * 0.07
    truth = np.mean(left**2, axis=0) / np.var(prep.filter(noise)[rows], axis=0)
    return prep, rows, fit, truth


def test_a_drag_the_columns_lack_repeats_across_the_periods_on_its_joint_only():
    prep, rows, fit, truth = _fit(1, drag=0.5)
    out = training_lack_of_fit(prep, rows, fit, order=20)
    assert out is not None and 2.5 < out.periods <= 3.0  # the filter's trim leaves part of the first period
    assert truth[1] > LEAD_MISFIT and truth[0] < 1e-12
    lead = out.leads(0.05)
    assert lead.tolist() == [False, True], (out.misfit, out.p_raw)
    assert out.p_raw[1] < 1e-3 and out.p_raw[0] > 0.01
    # The misfit estimates the share of the effect the fit leaves, in noise variances.
    assert out.misfit[1] == pytest.approx(truth[1], rel=0.2), (out.misfit, truth)
    assert abs(out.misfit[0]) < 0.15


@pytest.mark.parametrize("seed", [2, 3, 4])
def test_without_the_drag_nothing_repeats_beyond_noise(seed):
    prep, rows, fit, _ = _fit(seed, drag=0.0)
    out = training_lack_of_fit(prep, rows, fit, order=20)
    assert not out.leads(0.05).any(), (out.misfit, out.p_raw)
    assert np.all(np.abs(out.misfit) < 0.2), out.misfit
    # Without misfit the statistic sits at its bootstrap mean, which the fit pulls below 1.
    assert np.all(out.null_mean < 1.0) and np.all(np.abs(out.ratio - out.null_mean) < 0.6)


def test_a_run_that_does_not_repeat_two_periods_gives_no_test():
    prep, rows, fit, _ = _fit(5, drag=0.06, periods=1)
    assert training_lack_of_fit(prep, rows, fit, order=20) is None


def test_the_lead_rule_takes_a_multiple_of_the_angles_share_off():
    def result(misfit, p, state):
        n = len(misfit)
        return LackOfFit(
            ratio=np.ones(n), null_mean=np.ones(n), misfit=np.array(misfit, float), p_raw=np.array(p, float),
            p_joint=np.array(p, float), state=np.array(state, float), periods=3.0,
        )  # fmt: skip

    hi = LEAD_MISFIT + 0.1
    assert result([hi, hi, hi], [0.01, 0.2, 0.01], [0.0, 0.0, 0.0]).leads(0.05).tolist() == [True, False, True]
    # What the quantised angles may repeat comes off the misfit: more than the white model's share.
    state = 0.05
    assert result([LEAD_MISFIT + 1.1 * QUANTISATION_FACTOR * state], [0.01], [state]).leads(0.05).all()
    assert not result([LEAD_MISFIT + 0.9 * QUANTISATION_FACTOR * state], [0.01], [state]).leads(0.05).any()
    doc = result([hi], [0.01], [0.0]).to_dict(0.05)
    assert doc["lead_joint"] == [True] and doc["lead_misfit"] == LEAD_MISFIT and doc["periods"] == 3.0
