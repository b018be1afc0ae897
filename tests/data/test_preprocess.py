"""Tests of dynid.data.preprocess: resampling, zero-phase filtering, differences, parallel filtering."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.signal import sosfilt

import dynid.data.preprocess as pp
from dynid.data.dataset import Dataset
from dynid.exceptions import DataError, DataWarning

FS = 1000.0  # Hz

# q(t) = sum_k a_k sin(w_k t + phi_k): amplitudes (rad), angular frequencies (rad/s), phases (rad)
AMPS = np.array([0.8, 0.3, 0.1])
OMEGAS = 2 * np.pi * np.array([0.3, 1.1, 2.7])
PHASES = np.array([0.2, 1.3, -0.7])


def sines(t: NDArray[np.float64], derivative: int = 0) -> NDArray[np.float64]:
    """Sum of sines and its exact derivatives, shape (m,)."""
    arg = np.outer(t, OMEGAS) + PHASES
    parts = [np.sin(arg), np.cos(arg), -np.sin(arg)]
    return (parts[derivative] * AMPS * OMEGAS**derivative).sum(axis=1)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(7)


def band_limited(rng: np.random.Generator, m: int, band: float = 30.0) -> NDArray[np.float64]:
    """White noise low-passed at ``band`` Hz: a random, band-limited signal of shape (m,)."""
    return pp.lowpass(rng.normal(size=m), fs=FS, cutoff=band)


def peak_lag(y: NDArray[np.float64], x: NDArray[np.float64]) -> int:
    """Lag (samples) of the cross-correlation peak of y against x (positive: y comes later)."""
    xc = np.correlate(y - y.mean(), x - x.mean(), mode="full")
    return int(np.argmax(xc)) - (len(x) - 1)


# ---------------------------------------------------------------------- filtering
def test_zero_phase_filter_adds_no_delay(rng: np.random.Generator) -> None:
    x = band_limited(rng, 4000) + 0.3 * rng.normal(size=4000)
    y = pp.lowpass(x, fs=FS, cutoff=40.0)
    assert peak_lag(y, x) == 0
    causal = sosfilt(pp.butter_sos(40.0, FS), x)  # the same filter run forward only is late
    assert peak_lag(causal, x) > 2


def test_lowpass_keeps_the_band_and_removes_the_rest() -> None:
    t = np.arange(5000) / FS
    slow, fast = np.sin(2 * np.pi * 2.0 * t), np.sin(2 * np.pi * 200.0 * t)
    y = pp.lowpass(slow + fast, fs=FS, cutoff=20.0)
    inner = slice(500, -500)
    np.testing.assert_allclose(y[inner], slow[inner], atol=1e-3)


def test_lowpass_filters_runs_separately() -> None:
    step = np.r_[np.zeros(300), np.ones(300)]
    runs = [slice(0, 300), slice(300, 600)]
    apart = pp.lowpass(step, fs=FS, cutoff=10.0, runs=runs)
    np.testing.assert_allclose(apart, step, atol=1e-9)  # constants stay constant: nothing crosses
    across = pp.lowpass(step, fs=FS, cutoff=10.0)
    assert np.abs(across - step).max() > 0.1  # a single run smears the step


def test_lowpass_in_place_on_trailing_dimensions(rng: np.random.Generator) -> None:
    y = rng.normal(size=(800, 2, 3))
    expected = np.empty_like(y)
    for i in range(2):
        for j in range(3):
            expected[:, i, j] = pp.lowpass(y[:, i, j], fs=FS, cutoff=50.0)
    out = pp.lowpass(y, fs=FS, cutoff=50.0, inplace=True)
    assert out is y
    np.testing.assert_allclose(y, expected, rtol=1e-12, atol=1e-12)


def test_filter_errors(rng: np.random.Generator) -> None:
    with pytest.raises(DataError, match=r"Nyquist frequency 500 Hz of data sampled at 1000 Hz; got 600"):
        pp.lowpass(rng.normal(size=100), fs=FS, cutoff=600.0)
    # order 5: scipy's sosfiltfilt pads with 18 samples (its first-order section pads less than 21)
    with pytest.raises(DataError, match=r"run 1 has 18 samples, too short .*needs more than 18"):
        pp.lowpass(rng.normal(size=118), fs=FS, cutoff=50.0, runs=[slice(0, 100), slice(100, 118)])
    with pytest.raises(DataError, match="order must be a positive integer"):
        pp.butter_sos(10.0, FS, order=0)
    with pytest.raises(DataError, match="inplace=True needs a writeable, C-contiguous float64 array"):
        pp.lowpass(np.zeros((100, 2), dtype=np.float32), fs=FS, cutoff=50.0, inplace=True)


def test_the_shortest_run_a_filter_takes_is_scipys(rng: np.random.Generator) -> None:
    from scipy.signal import sosfiltfilt

    y = rng.normal(size=119)
    for order in (3, 4, 5):
        runs = [slice(0, 100), slice(100, 119)]  # 19 samples: more than the 12, 15 or 18 scipy pads with
        got = pp.lowpass(y, fs=FS, cutoff=50.0, order=order, runs=runs)
        sos = pp.butter_sos(50.0, FS, order)
        np.testing.assert_allclose(got[100:], sosfiltfilt(sos, y[100:]), rtol=0, atol=1e-12)


def test_the_identification_takes_the_shortest_run_the_filter_takes(ur5) -> None:
    # build_system filters the regressor columns run by run with the same rule as the torque's filter
    from dynid.data.preparation import Preprocessing
    from dynid.identify.linear_system import build_system

    t = np.arange(0.0, 1.2, 0.001)
    q = 0.3 * np.sin(2 * np.pi * 0.5 * t[:, None] + np.arange(ur5.n))
    tau = np.cos(2 * np.pi * 0.5 * t[:, None] + np.arange(ur5.n))
    settings = Preprocessing(cutoff=40.0, order=5, trim=0.0)
    whole = Dataset(t=t, q=q, tau=tau)
    for extra, ok in ((19, True), (18, False)):  # order 5: the filter pads with 18 samples
        part = Dataset.concat([whole, whole.select_rows(np.arange(extra))])  # two runs
        if ok:
            assert build_system(ur5, part, preprocessing=settings).m == len(t) + extra
        else:
            with pytest.raises(DataError, match="run 1 has 18 samples, too short for an order-5 zero-phase"):
                build_system(ur5, part, preprocessing=settings)


# ---------------------------------------------------------------------- differences
@pytest.mark.parametrize("derivative", [1, 2])
def test_central_differences_are_second_order(derivative: int) -> None:
    errors = []
    for dt in (0.01, 0.005, 0.0025):  # omega * dt <= 0.17: the asymptotic range
        t = np.arange(0.0, 4.0 + dt / 2, dt)
        estimate = pp.central_difference(sines(t), dt, derivative=derivative)  # type: ignore[arg-type]
        errors.append(np.abs(estimate - sines(t, derivative)).max())  # ends included
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all((orders > 1.8) & (orders < 2.2)), orders


def test_central_differences_run_by_run() -> None:
    dt = 0.01
    t = np.arange(0.0, 2.0, dt)
    y = np.r_[sines(t), sines(t) + 5.0]  # a jump between the runs
    runs = [slice(0, len(t)), slice(len(t), 2 * len(t))]
    d1 = pp.central_difference(y, dt, runs=runs)
    np.testing.assert_allclose(d1[: len(t)], d1[len(t) :], atol=1e-12)
    assert np.abs(d1).max() < 10.0  # the jump never enters a difference
    with pytest.raises(DataError, match="derivative must be 1 or 2"):
        pp.central_difference(y, dt, derivative=3)  # type: ignore[arg-type]


# ---------------------------------------------------------------------- resampling
def irregular_stamps(rng: np.random.Generator, duration: float = 3.0) -> NDArray[np.float64]:
    steps = rng.uniform(0.7e-3, 1.6e-3, size=int(duration / 1e-3))
    steps[rng.choice(len(steps), size=40, replace=False)] = 0.0  # repeated stamps
    return np.cumsum(steps)


@pytest.mark.parametrize(("method", "tolerance"), [("linear", 1e-4), ("cubic", 1e-8)])  # relative
def test_resampling_recovers_a_smooth_signal(rng: np.random.Generator, method: str, tolerance: float) -> None:
    t = irregular_stamps(rng)
    y = np.column_stack([sines(t), 2 * sines(t, 1)])
    t_new, y_new = pp.resample_uniform(t, y, dt=1e-3, method=method)  # type: ignore[arg-type]
    np.testing.assert_allclose(np.diff(t_new), 1e-3, rtol=1e-9)
    assert t_new[0] == t[0]
    assert t_new[-1] <= t[-1]
    truth = np.column_stack([sines(t_new), 2 * sines(t_new, 1)])
    relative = np.abs(y_new - truth).max(axis=0) / np.abs(truth).max(axis=0)
    assert np.all(relative < tolerance), relative


def test_resampling_refuses_time_going_backwards() -> None:
    with pytest.raises(DataError, match=r"t goes backwards at row 2"):
        pp.resample_uniform([0.0, 0.002, 0.001, 0.003], np.zeros(4))
    with pytest.raises(DataError, match="method must be 'linear' or 'cubic'"):
        pp.resample_uniform([0.0, 0.001], np.zeros(2), method="spline")  # type: ignore[arg-type]


def test_resample_dataset_keeps_runs(rng: np.random.Generator) -> None:
    parts = []
    for _ in range(2):
        t = np.unique(irregular_stamps(rng, 1.0))
        parts.append(Dataset(t, sines(t), sines(t, 2)))
    joined = Dataset.concat(parts)
    out = pp.resample(joined, dt=1e-3)
    assert out.is_uniform
    assert len(out.runs) == 2
    assert out.meta["resampled"]["method"] == "linear"
    np.testing.assert_allclose(np.diff(out.t), 1e-3, rtol=1e-9)


# ---------------------------------------------------------------------- parallel filtering
def regressor(
    q: NDArray[np.float64], dq: NDArray[np.float64], ddq: NDArray[np.float64]
) -> NDArray[np.float64]:
    """A small nonlinear regressor of shape (m, n, 5), like a rigid-body one: ddq, dq, g(q), dq^2, dq|dq|."""
    return np.stack([ddq, dq, np.cos(q), dq**2 * np.sin(q), dq * np.abs(dq)], axis=-1)


@pytest.fixture
def noisy_states(rng: np.random.Generator) -> dict[str, NDArray[np.float64]]:
    """Two joints sampled at 1 kHz for 4 s; q with encoder-like noise, dq/ddq by differences."""
    dt = 1 / FS
    t = np.arange(0.0, 4.0, dt)
    q = np.column_stack([sines(t), 0.5 * sines(t + 0.4)]) + rng.normal(scale=2e-4, size=(len(t), 2))
    states = pp.lowpass(q, fs=FS, cutoff=100.0)  # light state filter, as a user would
    dq = pp.central_difference(states, dt)
    ddq = pp.central_difference(states, dt, derivative=2)
    return {"t": t, "q": states, "dq": dq, "ddq": ddq}


def test_parallel_filtering_commutes_with_the_parameters(
    rng: np.random.Generator, noisy_states: dict[str, NDArray[np.float64]]
) -> None:
    s = noisy_states
    Y = regressor(s["q"], s["dq"], s["ddq"])
    params = rng.normal(size=5)
    tau = Y @ params
    tau_f, Y_f = pp.parallel_filter(tau, Y, fs=FS, cutoff=5.0, decimate=10, trim=0.3)
    np.testing.assert_allclose(tau_f, Y_f @ params, rtol=1e-10, atol=1e-10 * np.abs(tau_f).max())

    # Building the regressor from filtered states instead is a different model: the filtered torque is not
    # explained by it (the mismatch is the fake effect parallel filtering avoids).
    q_f = pp.lowpass(s["q"], fs=FS, cutoff=5.0)
    dq_f = pp.central_difference(q_f, 1 / FS)
    Y_states = regressor(q_f, dq_f, pp.central_difference(q_f, 1 / FS, derivative=2))
    rows = pp.kept_rows([slice(0, len(tau))], decimate=10, trim_samples=300)
    mismatch = tau_f - Y_states[rows] @ params
    assert np.sqrt(np.mean(mismatch**2)) > 1e-2 * np.sqrt(np.mean(tau_f**2))


def test_parallel_filter_rows_match_preprocess(noisy_states: dict[str, NDArray[np.float64]]) -> None:
    s = noisy_states
    m = len(s["t"])
    tau = np.column_stack([np.sin(s["t"]), np.cos(3 * s["t"])])
    half = m // 2
    runs = [slice(0, half), slice(half, m)]
    ds = Dataset.concat([Dataset(s["t"][r], s["q"][r], tau[r]) for r in runs])
    prepared = pp.preprocess(ds, cutoff=20.0, decimate=4, trim=0.1)
    Y = regressor(ds.q, s["dq"], s["ddq"])
    tau_f, Y_f = pp.parallel_filter(ds.tau, Y, fs=1 / ds.dt, cutoff=20.0, runs=ds.runs, decimate=4, trim=0.1)
    assert Y_f.shape == (prepared.m, 2, 5)
    np.testing.assert_allclose(tau_f, prepared.tau, rtol=1e-12, atol=1e-12)
    assert len(prepared.runs) == 2


def test_parallel_filter_in_place_and_in_chunks(
    rng: np.random.Generator, monkeypatch: pytest.MonkeyPatch
) -> None:
    tau = rng.normal(size=(600, 3))
    Y = rng.normal(size=(600, 3, 7))
    reference_tau, reference_Y = pp.parallel_filter(tau, Y, fs=FS, cutoff=30.0)
    monkeypatch.setattr(pp, "_CHUNK_VALUES", 1000)  # a column or so at a time
    chunked_tau, chunked_Y = pp.parallel_filter(tau, Y.copy(), fs=FS, cutoff=30.0)
    np.testing.assert_allclose(chunked_Y, reference_Y, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(chunked_tau, reference_tau, rtol=1e-13, atol=1e-13)
    out_tau, out_Y = pp.parallel_filter(tau, Y, fs=FS, cutoff=30.0, inplace=True)
    assert out_Y is Y
    np.testing.assert_allclose(Y, reference_Y, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(out_tau, reference_tau, rtol=1e-13, atol=1e-13)


def test_parallel_filter_errors(rng: np.random.Generator) -> None:
    tau, Y = rng.normal(size=(500, 2)), rng.normal(size=(500, 3, 4))
    with pytest.raises(DataError, match="Y has 3 joint rows but tau has 2 columns"):
        pp.parallel_filter(tau, Y, fs=FS, cutoff=10.0)
    with pytest.raises(DataError, match="decimating by 20 puts the Nyquist frequency at 25 Hz"):
        pp.parallel_filter(tau, Y[:, :2], fs=FS, cutoff=30.0, decimate=20)


# ---------------------------------------------------------------------- the whole path
def test_preprocess_recovers_derivatives_and_records_what_it_did(rng: np.random.Generator) -> None:
    t = irregular_stamps(rng, 6.0)
    t = np.unique(t)
    q = np.column_stack([sines(t), -sines(t)]) + rng.normal(scale=1e-5, size=(len(t), 2))
    raw = Dataset(t, q, np.column_stack([sines(t, 2), sines(t, 1)]), meta={"robot": "test"})
    out = pp.preprocess(raw, cutoff=10.0, decimate=5)
    assert out.is_uniform
    assert out.dt == pytest.approx(5 * raw.dt, rel=1e-9)
    assert out.meta["reference"] == "resampled, filtered, decimated and trimmed"
    assert out.meta["preprocess"]["trim_s"] == pytest.approx(0.2)
    assert out.meta["preprocess"]["dq"] == "central difference of filtered q"
    assert out.meta["robot"] == "test"
    assert out.t[0] >= t[0] + 0.2 - 1e-9
    np.testing.assert_allclose(out.dq[:, 0], sines(out.t, 1), atol=5e-3 * np.abs(sines(t, 1)).max())
    np.testing.assert_allclose(out.ddq[:, 0], sines(out.t, 2), atol=2e-2 * np.abs(sines(t, 2)).max())


def test_preprocess_keeps_measured_velocity(rng: np.random.Generator) -> None:
    t = np.arange(0.0, 3.0, 1e-3)
    q, dq = sines(t), sines(t, 1) + rng.normal(scale=1e-3, size=len(t))
    raw = Dataset(t, q, np.zeros_like(t), dq=dq)
    out = pp.preprocess(raw, cutoff=15.0, trim=0.0, filter_torque=False)
    assert out.meta["preprocess"]["dq"] == "measured, filtered"
    assert out.meta["preprocess"]["ddq"] == "central difference of dq"
    assert out.meta["reference"] == "raw"
    np.testing.assert_allclose(out.ddq[200:-200, 0], sines(t, 2)[200:-200], atol=0.05)
    recomputed = pp.preprocess(raw, cutoff=15.0, trim=0.0, velocity="differentiate")
    assert recomputed.meta["preprocess"]["dq"] == "central difference of filtered q"


def test_preprocess_refuses_aliasing_settings() -> None:
    t = np.arange(0.0, 1.0, 1e-3)
    raw = Dataset(t, sines(t), sines(t))
    with pytest.raises(DataError, match="decimating by 10 puts the Nyquist frequency at 50 Hz"):
        pp.preprocess(raw, cutoff=80.0, decimate=10)
    with pytest.warns(DataWarning, match="decimating by 10 without a low-pass filter aliases"):
        pp.preprocess(raw, cutoff=None, decimate=10)
    with warnings.catch_warnings():
        warnings.simplefilter("error", DataWarning)
        pp.preprocess(raw, cutoff=None, decimate=1)


def test_trim_and_decimate_run_by_run(rng: np.random.Generator) -> None:
    a = Dataset(np.arange(100) * 0.01, rng.normal(size=100), rng.normal(size=100))
    joined = Dataset.concat([a, a])
    trimmed = pp.trim(joined, 0.05)
    assert trimmed.m == 2 * (100 - 2 * 5)
    assert [r.start for r in trimmed.runs] == [0, 90]
    decimated = pp.decimate(joined, 3)
    assert decimated.m == 2 * 34
    assert decimated.meta["decimated"] == 3
    with pytest.raises(DataError, match="trimming 60 samples from both ends leaves 0 of run 0"):
        pp.trim(joined, 0.6)


@pytest.mark.parametrize("order", [1, 2, 5, 8])
def test_filtfilt_rows_is_scipys_sosfiltfilt_to_the_bit(order: int) -> None:
    from scipy.signal import butter, sosfiltfilt

    rng = np.random.default_rng(order)
    sos = pp.butter_sos(35.0, 5000.0, order)
    np.testing.assert_allclose(sos, butter(order, 35.0, fs=5000.0, output="sos"), rtol=1e-12, atol=0)
    for length in (40, 3000):
        x = rng.standard_normal((length, 5)).cumsum(axis=0)
        assert np.array_equal(pp.filtfilt_rows(sos, x.T).T, sosfiltfilt(sos, x, axis=0))
        assert np.array_equal(pp.filtfilt_rows(sos, x.T, padded=False).T, sosfiltfilt(sos, x, axis=0, padlen=0))


def test_filtfilt_rows_refuses_a_signal_shorter_than_its_padding() -> None:
    sos = pp.butter_sos(35.0, 5000.0, 5)
    with pytest.raises(DataError, match="too short for an order-5 zero-phase filter"):
        pp.filtfilt_rows(sos, np.ones((2, 10)))
