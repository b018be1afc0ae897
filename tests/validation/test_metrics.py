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


@pytest.mark.parametrize("periods", [2, 3, 2.9])
def test_the_floor_s_interval_covers_the_variance_of_filtered_coloured_noise(periods):
    # AR(1) torque noise with a 100 ms time constant beside an equal white part, low-passed at 20 Hz as
    # the preparation does: neighbouring phases are far from independent.  The floor's 95 % interval
    # must cover the noise's true variance about 95 % of the time; a standard error that took the 5000
    # phases as independent would be several times too small and cover about one run in six.
    from scipy.signal import butter, filtfilt, lfilter

    rng = np.random.default_rng(11)
    fs, period, a = 1000.0, 5.0, np.exp(-1.0 / 100.0)
    b_lp, a_lp = butter(4, 20.0 / (fs / 2))

    def noise(m):
        coloured = lfilter([np.sqrt(1 - a * a)], [1, -a], rng.normal(size=m + 3000))[3000:]
        return filtfilt(b_lp, a_lp, rng.normal(size=m) + coloured)

    true_var = np.var(noise(400_000)[2000:-2000])
    t = np.arange(round(periods * period * fs)) / fs
    lead = t.size % round(period * fs)  # 2.9: two whole periods and 4.5 s of a third, pooled
    ratio, rel, covered = [], [], 0
    for _ in range(300):
        floor = noise_floor(t, noise(t.size)[:, None], period=period, lead=lead)
        ratio.append(floor.std[0] ** 2 / true_var)
        rel.append(floor.rel_se[0])
        lo, hi = floor.std_interval(0.95)
        covered += lo[0] ** 2 <= true_var <= hi[0] ** 2
    assert 0.90 <= covered / 300 <= 0.99
    # The standard error it states is the spread the floor really has, within 15 %.
    assert np.mean(rel) == pytest.approx(np.std(ratio), rel=0.15)


def test_a_floor_from_the_spectrum_states_no_interval(rng):
    t, tau, _ = _periodic(rng, periods=3, noise=np.array([0.05, 0.2]))
    lo, hi = noise_floor(t, tau).std_interval()
    assert np.all(np.isnan(lo)) and np.all(np.isnan(hi))


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
