"""dynid.data.dsp against scipy.signal: the design, the filter and the spectrum every command uses."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
import scipy.signal as ss

from dynid.data import dsp


@pytest.mark.parametrize("order", range(1, 11))
def test_butter_lowpass_is_scipys_design_section_by_section(order: int) -> None:
    for fs in (1000.0, 5000.0):
        for cutoff in np.linspace(0.2, 0.499 * fs, 25):  # near Nyquist the odd order's zeros pair otherwise
            want = ss.butter(order, cutoff, fs=fs, output="sos")
            np.testing.assert_allclose(dsp.butter_lowpass(order, cutoff, fs), want, rtol=1e-10, atol=1e-300)


@pytest.mark.parametrize(("order", "cutoff", "fs"), [(1, 50.0, 1000.0), (4, 5.0, 5000.0), (5, 0.5, 1000.0)])
def test_sosfilt_with_initial_states_is_scipys_to_the_bit(order: int, cutoff: float, fs: float) -> None:
    assert dsp._compiled() is not None  # the compiled loop, not the fallback, is what runs here
    rng = np.random.default_rng(order)
    sos = ss.butter(order, cutoff, fs=fs, output="sos")
    zi = dsp.sosfilt_zi(sos)
    np.testing.assert_allclose(zi, ss.sosfilt_zi(sos), rtol=1e-12, atol=1e-15)
    x = rng.standard_normal((4000, 3)).cumsum(axis=0) + 50.0  # a level: the initial states matter
    states = ss.sosfilt_zi(sos)[:, :, None] * x[0]
    want, final = ss.sosfilt(sos, x, axis=0, zi=states)
    assert np.array_equal(dsp.sosfilt(sos, x, zi=states), want)
    assert np.array_equal(dsp.sosfilt(sos, x), ss.sosfilt(sos, x, axis=0))
    y, z = x.copy(), states.copy()
    dsp.sosfilt_inplace(sos, y, z)
    assert np.array_equal(y, want) and np.array_equal(z, final)  # the final states, as scipy returns them
    back = x.copy()
    dsp.sosfilt_inplace(sos, back, states.copy(), reverse=True)  # from the last sample to the first
    assert np.array_equal(back, ss.sosfilt(sos, x[::-1], axis=0, zi=states)[0][::-1])
    # a step through the steady-state initial states stays at its level: no start-up transient
    step = dsp.sosfilt(sos, np.ones((50, 1)), zi=zi[:, :, None])
    np.testing.assert_allclose(step, 1.0, rtol=0, atol=1e-9)
    with pytest.raises(ValueError, match="C-contiguous float64"):
        dsp.sosfilt_inplace(sos, np.asfortranarray(x), states.copy())
    frozen = states.copy()
    frozen.setflags(write=False)
    with pytest.raises(ValueError, match="writeable C-contiguous"):  # the final states are written there
        dsp.sosfilt_inplace(sos, x.copy(), frozen)
    with pytest.raises(ValueError, match="shape \\(n_sections, 6\\)"):  # the loop would read past it
        dsp.sosfilt_inplace(sos[:, :5], x.copy(), states.copy())
    assert np.array_equal(dsp.sosfilt(sos, x[:, 0]), ss.sosfilt(sos, x[:, 0]))  # one signal, 1-D


def test_a_damaged_library_in_the_cache_is_built_again(tmp_path) -> None:
    code = (
        "import numpy as np, scipy.signal as ss\n"
        "from dynid.data import dsp, filters\n"
        "assert dsp._compiled() is not None\n"
        "sos = filters.butter_sos(20.0, 1000.0, 5)\n"
        "x = np.random.default_rng(0).standard_normal((3, 2000)).cumsum(axis=1)\n"
        "assert np.array_equal(filters.filtfilt_rows(sos, x), ss.sosfiltfilt(sos, x, axis=-1))\n"
        "print('ok')\n"
    )
    env = {**os.environ, "DYNID_CACHE_DIR": str(tmp_path)}
    first = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert first.returncode == 0 and first.stdout.strip() == "ok", first.stderr[-2000:]
    (lib,) = (tmp_path / "dsp").glob("sosfilt-*.so")
    lib.write_bytes(b"not a shared library")  # a disk that lost it, a copy cut short
    again = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert again.returncode == 0 and again.stdout.strip() == "ok", again.stderr[-2000:]
    assert lib.read_bytes()[:4] == b"\x7fELF"


def test_a_design_outside_the_band_is_refused() -> None:
    for order, cutoff in ((5, 0.0), (5, 500.0), (5, 700.0), (0, 10.0)):
        with pytest.raises(ValueError, match="order of 1 or more and a cut-off between 0 and the Nyquist"):
            dsp.butter_lowpass(order, cutoff, 1000.0)


def test_without_a_c_compiler_the_filter_is_scipys_own(tmp_path) -> None:
    """No compiler (``$CC`` names none and none is on the PATH), an empty cache: the same values."""
    code = (
        "import numpy as np, scipy.signal as ss\n"
        "from dynid.data import dsp, filters\n"
        "assert dsp._compiled() is None\n"
        "sos = filters.butter_sos(20.0, 1000.0, 5)\n"
        "x = np.random.default_rng(0).standard_normal((3, 2000)).cumsum(axis=1)\n"
        "assert np.array_equal(filters.filtfilt_rows(sos, x), ss.sosfiltfilt(sos, x, axis=-1))\n"
        "print('ok')\n"
    )
    env = {**os.environ, "CC": "no-such-cc", "PATH": str(tmp_path), "DYNID_CACHE_DIR": str(tmp_path / "cache")}
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert run.returncode == 0 and run.stdout.strip() == "ok", run.stderr[-2000:]
    assert not (tmp_path / "cache" / "dsp").exists() or not any((tmp_path / "cache" / "dsp").glob("*.so"))


@pytest.mark.parametrize("detrend", ["constant", "linear"])
def test_welch_is_scipys_density(detrend: str) -> None:
    rng = np.random.default_rng(3)
    x = rng.standard_normal((5000, 4)).cumsum(axis=0) + np.linspace(0, 30, 5000)[:, None]
    for nperseg in (1000, 777, 16):
        f, P = ss.welch(x, fs=500.0, nperseg=nperseg, axis=0, detrend=detrend)
        g, Q = dsp.welch(x, 500.0, nperseg, detrend=detrend)
        np.testing.assert_allclose(g, f, rtol=1e-15)
        np.testing.assert_allclose(Q, P, rtol=1e-9, atol=1e-12 * P.max())
    f, P = ss.welch(x[:1], fs=500.0, nperseg=1, axis=0, detrend=detrend)  # one sample: scipy's window [1]
    g, Q = dsp.welch(x[:1], 500.0, 1, detrend=detrend)
    np.testing.assert_allclose(Q, P, atol=1e-30)  # zero (scipy: its linear detrend leaves 1e-33)
    f, P = ss.welch(x[:300, 0], fs=500.0, nperseg=300, detrend=detrend)  # one segment, 1-D
    g, Q = dsp.welch(x[:300, 0], 500.0, 300, detrend=detrend)
    np.testing.assert_allclose(Q, P, rtol=1e-9, atol=1e-12 * P.max())
    with pytest.raises(ValueError, match="detrend must be"):
        dsp.welch(x, 500.0, 100, detrend="none")


def test_frequency_response_is_sosfreqz() -> None:
    sos = ss.butter(5, 20.0, fs=1000.0, output="sos")
    f = np.linspace(0.0, 500.0, 333)
    np.testing.assert_allclose(dsp.frequency_response(sos, f, 1000.0), ss.sosfreqz(sos, worN=f, fs=1000.0)[1], rtol=1e-10, atol=1e-14)
    assert abs(dsp.frequency_response(sos, [20.0], 1000.0)[0]) == pytest.approx(2**-0.5)  # -3 dB at the cut-off


def test_identify_and_validate_import_neither_scipy_signal_nor_optimize_nor_special(ur5, tmp_path) -> None:
    """scipy.signal's import (about 0.75 s) was a third of an OLS identification from the shell."""
    from dynid.data.files import save_dataset
    from dynid.identify.columns import column_set
    from dynid.sim.synthetic import random_fourier, synthetic_dataset, true_parameters

    rng = np.random.default_rng(5)
    cols = column_set(ur5)
    data = synthetic_dataset(cols, true_parameters(cols, rng), random_fourier(ur5, rng, periods=1), rate=200, rng=rng)
    save_dataset(data, tmp_path / "D.csv")
    model = tmp_path / "M.json"
    for argv in (
        ["identify", "--robot", "ur5", "--data", "D.csv", "--out", "M.json", "--method", "ols", "--friction", "linear",
         "--gmm", "off"],
        ["validate", "--model", "M.json", "--data", "D.csv", "--report", "R.html"],
    ):
        run = subprocess.run(
            [sys.executable, "-X", "importtime", "-m", "dynid", *argv, "--quiet"],
            capture_output=True, text=True, cwd=tmp_path,
        )  # fmt: skip
        assert run.returncode == 0, run.stderr[-2000:]
        imported = {line.rsplit("|", 1)[-1].strip() for line in run.stderr.splitlines() if line.startswith("import time:")}
        assert "dynid.data.dsp" in imported  # the list is the command's own imports
        assert not {name for name in imported if name.startswith("scipy.signal")}, argv[0]
        # nor scipy.optimize (0.3 s), which a linear friction with no active bound does not use
        assert "scipy.optimize" not in imported, argv[0]
        assert "scipy.special" not in imported, argv[0]  # (50 ms) nor the sigmoid friction's expit
    assert model.exists()
