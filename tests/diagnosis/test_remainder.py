"""The floor-free check: does a flexible state model predict the held-out residual it was not fitted on?

A two-joint linear model (per-joint viscous and Coulomb friction, and inertia) is fitted on a training
run and cross-fitted on a held-out run with AR(1) torque noise (100 ms).  With nothing missing, the check
must stay quiet at its level; with a friction on the sum of the two velocities (a coupled wrist, which
per-joint friction cannot hold), it must find the joint that carries it, and only that one.
"""

from __future__ import annotations

import numpy as np
import pytest

from dynid.diagnosis.crossfold import CrossFold
from dynid.diagnosis.remainder import predictable_remainder

RATE = 200.0
SIGMA = 0.05  # N m, the noise's standard deviation


def _states(rng: np.random.Generator, seconds: float) -> tuple[np.ndarray, ...]:
    """Aperiodic smooth motion of two joints: sums of sines of random frequencies and phases."""
    t = np.arange(round(seconds * RATE)) / RATE
    f = rng.uniform(0.05, 0.6, size=(5, 2))
    a = rng.uniform(0.2, 0.6, size=(5, 2))
    ph = rng.uniform(0, 2 * np.pi, size=(5, 2))
    w = 2 * np.pi * f
    arg = w[None] * t[:, None, None] + ph[None]
    q = np.sum(a * np.sin(arg), axis=1)
    dq = np.sum(a * w * np.cos(arg), axis=1)
    ddq = -np.sum(a * w**2 * np.sin(arg), axis=1)
    return t, q, dq, ddq


def _columns(dq: np.ndarray, ddq: np.ndarray) -> np.ndarray:
    """(m, 2, 6): per joint viscous, Coulomb and inertia columns, each joint its own parameters."""
    m = dq.shape[0]
    X = np.zeros((m, 2, 6))
    for j in range(2):
        X[:, j, 3 * j : 3 * j + 3] = np.column_stack([dq[:, j], np.tanh(dq[:, j] / 0.02), ddq[:, j]])
    return X


def _noise(rng: np.random.Generator, m: int) -> np.ndarray:
    phi = np.exp(-1.0 / (RATE * 0.1))
    e = rng.standard_normal((m, 2)) * SIGMA * np.sqrt(1 - phi**2)
    out = np.empty_like(e)
    out[0] = rng.standard_normal(2) * SIGMA
    for i in range(1, m):
        out[i] = phi * out[i - 1] + e[i]
    return out


def _run(seed: int, coupled: float, floor: float = SIGMA):
    rng = np.random.default_rng(seed)
    theta = np.array([0.3, 0.2, 0.05, 0.2, 0.1, 0.02])
    sides = []
    for seconds in (30.0, 20.0):
        t, q, dq, ddq = _states(rng, seconds)
        X = _columns(dq, ddq)
        y = np.einsum("mnk,k->mn", X, theta) + _noise(rng, len(t))
        # The coupled wrist: friction on dq1 + dq2 acting on joint 2 only.
        y[:, 1] += coupled * np.tanh((dq[:, 0] + dq[:, 1]) / 0.02)
        sides.append((t, (q, dq, ddq), X, y, np.ones_like(y)))
    (t_tr, s_tr, X_tr, y_tr, m_tr), (t, s_ho, X_ho, y_ho, m_ho) = sides
    sigma = np.full(2, floor)
    cf = CrossFold(X_tr, y_tr, m_tr / sigma, X_ho, y_ho, m_ho / sigma, 5)
    return predictable_remainder(cf, s_tr, t_tr, m_tr, s_ho, t, m_ho, sigma, round(0.1 * RATE), 0.05)


def test_on_noise_alone_the_check_stays_quiet_at_its_level():
    # The prediction of a fold never sees its rows, so on noise it can only add to the loss: over ten
    # runs no joint may pass at the 5 % level (a fit that saw the fold it predicts would pass on most).
    p = np.array([_run(seed, 0.0).p_joint for seed in range(10)])
    assert np.all(p >= 0.05), p
    shares = np.array([_run(seed, 0.0).share for seed in range(3)])
    assert np.all(shares < 0.05), shares


@pytest.mark.parametrize("seed", [0, 1])
def test_a_friction_on_the_sum_of_two_velocities_is_predictable_on_its_joint(seed):
    # 0.1 N m of Coulomb friction on dq1 + dq2 (twice the noise): per-joint friction holds part of it,
    # the rest is a function of the state that the trees learn on the other folds and the training run.
    rem = _run(seed, 0.1)
    assert rem.predictable.tolist() == [False, True], rem.p_joint
    assert rem.share[1] > 0.2 and rem.gain[1] > 0.5, (rem.share, rem.gain)
    # The loss is in noise variances, but the floor cancels from the test: a floor twice as high
    # quarters the gain and leaves the p-values as they are.
    high = _run(seed, 0.1, floor=2 * SIGMA)
    np.testing.assert_allclose(high.p_joint, rem.p_joint, rtol=1e-6)
    np.testing.assert_allclose(high.gain, rem.gain / 4, rtol=1e-6)


def test_on_a_spectral_floor_a_verdict_is_provisional_exactly_where_it_rests_on_the_floor():
    """A lower-bound floor can only overstate the gap.  "None" stands; accepted effects stand when they
    remove half of the whole held-out error on their joints (no floor enters); "unexplained" stands when
    the floor-free check finds a joint with a significant excess predictable, and no significant candidate
    was turned down for closing too little, or when the two runs disagree on a joint's parameters (no
    floor enters there either).  A measured floor is never provisional."""
    from types import SimpleNamespace

    from dynid.diagnosis.verdict import provisional_status as _provisional

    settings = SimpleNamespace(min_closure=0.5)
    mse = np.array([4.0, 10.0, 2.0])
    cand = SimpleNamespace(candidate=SimpleNamespace(joints=(1,), label="stribeck on joint 2"), significant=True)
    excess = {"significant_joint": np.array([False, True, False])}
    rem_on = SimpleNamespace(predictable=np.array([False, True, False]))
    rem_elsewhere = SimpleNamespace(predictable=np.array([True, False, False]))
    none_sel = SimpleNamespace(accepted=[], ranking=[], mse=mse)

    def status(verdict, sel, rem, measured=False, disagree=(False, False, False)):
        return _provisional(verdict, measured, rem, sel, excess, settings, mse, np.array(disagree))[0]

    assert not status(["none"], none_sel, None)
    # Accepted on joint 2: 10 -> 4 removes 60 % of its whole error; 10 -> 6, 40 %.
    assert not status(["stribeck"], SimpleNamespace(accepted=[cand], ranking=[cand], mse=np.array([4.0, 4.0, 2.0])), None)
    assert status(["stribeck"], SimpleNamespace(accepted=[cand], ranking=[cand], mse=np.array([4.0, 6.0, 2.0])), None)
    assert not status(["unexplained"], none_sel, rem_on)
    assert status(["unexplained"], none_sel, rem_elsewhere)  # predictable, but not where the excess is
    assert status(["unexplained"], none_sel, None)
    assert not status(["unexplained"], none_sel, None, disagree=(True, False, False))
    partial = SimpleNamespace(accepted=[], ranking=[cand], mse=mse)  # significant, turned down
    assert status(["unexplained"], partial, rem_on)
    assert status(["unexplained"], partial, None, disagree=(False, True, False))
    assert not status(["unexplained"], none_sel, None, measured=True)
