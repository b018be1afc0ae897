"""Validation metrics and the measured noise floor."""

from __future__ import annotations

import numpy as np
import pytest

from dynid.exceptions import DataError, ShapeError
from dynid.validation.metrics import noise_floor, torque_metrics


def test_metrics_of_a_known_error(rng):
    tau = rng.normal(size=(2000, 3)) * [1.0, 2.0, 4.0]
    err = np.column_stack([np.full(2000, 0.5), rng.normal(size=2000) * 0.1, np.zeros(2000)])
    m = torque_metrics(tau, tau - err)
    np.testing.assert_allclose(m["rms"], [0.5, np.sqrt(np.mean(err[:, 1] ** 2)), 0.0])
    assert m["rms_mean"] == pytest.approx(np.mean(m["rms"]))
    np.testing.assert_allclose(m["nrms"], m["rms"] / tau.std(axis=0))
    assert m["r2"][2] == 1.0
    assert 0.7 < m["r2"][0] < 0.8  # 1 - 0.25 / 1
    np.testing.assert_allclose(m["max_error"], np.abs(err).max(axis=0))


def test_metrics_refuse_mismatched_shapes():
    with pytest.raises(
        ShapeError, match=r"the measured torque has shape \(10, 2\) and the prediction \(10, 3\)"
    ):
        torque_metrics(np.zeros((10, 2)), np.zeros((10, 3)))


def _periodic(rng, *, periods, noise, coloured=0.0):
    dt, period = 0.001, 2.0
    t = np.arange(round(periods * period / dt)) * dt
    signal = np.column_stack([np.sin(2 * np.pi * t / period) * 5, np.cos(4 * np.pi * t / period) * 2])
    white = rng.normal(size=signal.shape) * noise
    if coloured:
        from scipy.signal import lfilter

        white = lfilter([np.sqrt(1 - coloured**2)], [1, -coloured], white, axis=0)
    return t, signal + white, period


@pytest.mark.parametrize("coloured", [0.0, 0.95])
def test_noise_floor_from_repeated_periods(rng, coloured):
    noise = np.array([0.05, 0.2])
    t, tau, period = _periodic(rng, periods=5, noise=noise, coloured=coloured)
    floor = noise_floor(t, tau, period=period)
    assert floor.method == "periods"
    np.testing.assert_allclose(floor.std, noise, rtol=0.05)


def test_noise_floor_from_the_spectrum_for_white_noise(rng):
    noise = np.array([0.05, 0.2])
    t, tau, _ = _periodic(rng, periods=3, noise=noise)
    floor = noise_floor(t, tau)  # no period given
    assert floor.method == "spectrum"
    np.testing.assert_allclose(floor.std, noise, rtol=0.08)


def test_noise_floor_needs_uniform_stamps(rng):
    t = np.cumsum(rng.uniform(0.5e-3, 1.5e-3, size=500))
    with pytest.raises(DataError, match="the noise floor needs uniform time stamps; resample"):
        noise_floor(t, rng.normal(size=(500, 2)))
