"""The field benchmark's cases are what they claim, so that it cannot silently test the lab setting.

One field case of the UR5 (a Stribeck effect given by value, no calibration): the training run repeats
its 5 s period three times, the held-out run (minimum-jerk moves with rests) repeats none; the torque
noise added is white + AR(1) of equal std with a 100 ms correlation time; the logged angles sit on a
14-bit encoder's counts; the datasets carry no dq or ddq; and the training run's spread across periods,
which the diagnosis uses as the held-out floor, matches the injected noise after the diagnosis' filter.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynid.diagnosis.field_cases import (
    FIELD_ENCODER_BITS,
    FIELD_NOISE_TIME,
    field_case,
    injected_noise,
    min_jerk_motion,
    true_noise_std,
)
from dynid.validation.noise import detect_period


@pytest.fixture(scope="module")
def case(ur5):
    return field_case(ur5, ["stribeck@3:2"], level=1.0, seed=3, heldout_seconds=15.0)


def test_training_is_periodic_and_the_heldout_run_is_not(case) -> None:
    assert case.period == pytest.approx(5.0)
    assert case.train.t[-1] == pytest.approx(3 * case.period)
    assert detect_period(case.train.t, case.train.q) == pytest.approx(case.period, abs=0.01)
    assert detect_period(case.heldout.t, case.heldout.q) is None
    # The motion rests between moves: some stretches of at least 0.3 s keep the angles still.
    still = np.all(np.abs(case.heldout_run.dq_desired) < 1e-9, axis=1)
    assert 0.05 < np.mean(still) < 0.5


def test_the_torque_noise_is_white_plus_ar1_of_100_ms(case) -> None:
    run = case.heldout_run
    # It is the noise the simulator added: the measured torque is the drive torque plus it, to the
    # current sensor's step.
    lsb = run.noise.current_lsb * run.truth.scales.torque
    assert np.all(np.abs(run.tau - run.tau_drive - case.heldout_noise) <= 0.5 * lsb + 1e-9)
    assert np.all(
        np.abs(case.train_run.tau - case.train_run.tau_drive - injected_noise(case.train_run))
        <= 0.5 * lsb + 1e-9
    )
    zs = [(v - v.mean(axis=0)) / v.std(axis=0) for v in (case.heldout_noise, injected_noise(case.train_run))]

    def acf(lag: int) -> float:
        return float(np.mean(np.concatenate([z[lag:] * z[:-lag] for z in zs])))

    lag = round(FIELD_NOISE_TIME * run.rate)
    # White and coloured parts of equal variance: half the variance is correlated at one tick ...
    assert acf(1) == pytest.approx(0.5, abs=0.05)
    # ... and that half decays by e after 100 ms (0.9 per tick, the lab's colour, would leave 0.5 * 2.7e-5).
    assert acf(lag) / acf(1) == pytest.approx(math.exp(-1.0), abs=0.1)


def test_the_angles_are_quantised_and_the_files_have_no_derivatives(case) -> None:
    step = 2 * math.pi / 2**FIELD_ENCODER_BITS
    for ds in (case.train, case.heldout):
        counts = ds.q / step
        np.testing.assert_allclose(counts, np.round(counts), atol=1e-6)
        assert ds.dq is None and ds.ddq is None
    # 14 bits, not the lab's 18: the held-out angles move by whole coarse counts.
    moves = np.abs(np.diff(case.heldout.q, axis=0))
    assert np.min(moves[moves > 0]) == pytest.approx(step, rel=1e-6)


def test_the_training_periods_floor_measures_the_injected_noise(ur5, case) -> None:
    """The floor the diagnosis takes for an aperiodic held-out run (the training run's spread across its
    periods, same filter) is within 25 % of the injected held-out noise after that filter."""
    from dynid.diagnosis.baseline import model_structure
    from dynid.identify.model import identify
    from dynid.identify.preparation import Preprocessing, prepare
    from dynid.validation.noise import measure_noise

    model = identify(ur5, case.train, method="ols", friction="linear", gmm="off", armature=True)
    structure = model_structure(model, None, case.train, case.heldout)
    settings = Preprocessing.from_settings(structure.preprocessing)
    trained = measure_noise(prepare(case.train, settings, n_joints=ur5.n))
    held = measure_noise(prepare(case.heldout, settings, n_joints=ur5.n))
    assert trained.method == "periods" and held.method == "spectrum"
    true = true_noise_std(model, case)
    np.testing.assert_array_less(0.75 * true, trained.std)
    np.testing.assert_array_less(trained.std, 1.25 * true)


def test_min_jerk_motion_is_smooth_and_within_limits(ur5) -> None:
    traj = min_jerk_motion(ur5, np.random.default_rng(0), 10.0)
    assert np.all(np.abs(traj.dq) <= 0.5 * ur5.dq_max + 1e-9)
    assert np.all(np.abs(traj.ddq) <= 0.5 * ur5.ddq_max + 1e-9)
    np.testing.assert_allclose(traj.q[0], traj.q[1], atol=1e-6)  # starts at rest
    # The velocity is the derivative of the angle (central differences, 1 ms).
    dq = np.gradient(traj.q, traj.t, axis=0)
    np.testing.assert_allclose(dq[1:-1], traj.dq[1:-1], atol=2e-3 * np.max(np.abs(traj.dq)))
