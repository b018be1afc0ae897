"""Preprocessing chosen from the data: the cut-off from the spectra, a measured dq used on evidence."""

from __future__ import annotations

import numpy as np
import pytest

from dynid.data.dataset import Dataset
from dynid.data.preparation import AUTO_CUTOFF_HZ, Preprocessing, prepare
from dynid.data.preprocess import BANDWIDTH_FACTOR, choose_cutoff

RATE = 1000.0


def _recording(*, freqs, q_noise, dq=None, seconds=20.0, seed=0):
    """Two joints moving at ``freqs`` (Hz), encoder-like noise on q, torque a smooth function of q."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 1.0 / RATE)
    q = np.column_stack([0.5 * np.sin(2 * np.pi * f * t + k) for k, f in enumerate(freqs)])
    true_dq = np.column_stack(
        [0.5 * 2 * np.pi * f * np.cos(2 * np.pi * f * t + k) for k, f in enumerate(freqs)]
    )
    tau = 3.0 * np.sin(q) + 0.01 * rng.normal(size=q.shape)
    q = q + q_noise * rng.normal(size=q.shape)
    measured = None
    if dq == "true":
        measured = true_dq + 1e-4 * rng.normal(size=q.shape)
    elif dq == "scaled":
        measured = 1.3 * true_dq  # a wrong velocity scale
    return Dataset(t, q, tau, dq=measured)


def test_the_cut_off_follows_the_motion_band_and_the_noise() -> None:
    slow = _recording(freqs=(0.2, 0.3), q_noise=1e-4)
    fast = _recording(freqs=(2.0, 3.0), q_noise=1e-4)
    c_slow, d_slow = choose_cutoff(slow, upper=RATE / 5)
    c_fast, d_fast = choose_cutoff(fast, upper=RATE / 5)
    assert c_fast > 2 * c_slow  # a faster motion carries signal higher up
    for c, d in ((c_slow, d_slow), (c_fast, d_fast)):
        assert c >= BANDWIDTH_FACTOR * d["bandwidth_hz"] - 1e-9 and c >= d["motion_hz"]
    # noisier angles: their signal ends lower
    _, d_noisy = choose_cutoff(_recording(freqs=(2.0, 3.0), q_noise=1e-2), upper=RATE / 5)
    assert d_noisy["motion_hz"] < d_fast["motion_hz"]
    # never above the limit given
    assert choose_cutoff(fast, upper=5.0)[0] == 5.0


def test_the_default_preprocessing_records_the_rule_and_cutoff_overrides() -> None:
    ds = _recording(freqs=(0.2, 0.3), q_noise=1e-3)
    auto = prepare(ds)
    assert auto.settings["cutoff_hz"] >= AUTO_CUTOFF_HZ  # no measured dq: the floor holds
    assert auto.settings["cutoff_rule"].startswith("from the data")
    given = prepare(ds, Preprocessing(cutoff=7.0))
    assert given.settings["cutoff_hz"] == 7.0 and given.settings["cutoff_rule"] == "given"
    with_dq = _recording(freqs=(0.2, 0.3), q_noise=1e-3, dq="true")
    chosen, _ = choose_cutoff(with_dq, upper=RATE / 5)
    assert prepare(with_dq).settings["cutoff_hz"] == pytest.approx(chosen)  # a measured dq: no floor


def test_a_measured_velocity_is_used_only_when_it_agrees_with_the_angles() -> None:
    good = prepare(_recording(freqs=(0.5, 0.7), q_noise=1e-5, dq="true"))
    assert good.settings["dq"].startswith("measured")
    assert good.settings["dq_evidence"].startswith("measured dq used")
    bad = prepare(_recording(freqs=(0.5, 0.7), q_noise=1e-5, dq="scaled"))
    assert bad.settings["dq"].startswith("central difference")
    assert bad.settings["dq_evidence"].startswith(
        "derivative of q used: the measured dq differs from it by 30 %"
    )
    forced = prepare(
        _recording(freqs=(0.5, 0.7), q_noise=1e-5, dq="scaled"), Preprocessing(velocity="measured")
    )
    assert forced.settings["dq"].startswith("measured") and "dq_evidence" not in forced.settings
    # the settings describe the preparation again (a model file applies them to new data)
    again = Preprocessing.from_settings(bad.settings)
    assert again.velocity == "differentiate" and again.cutoff == bad.settings["cutoff_hz"]


def test_a_recording_joined_from_runs_is_read_run_by_run() -> None:
    """Two runs joined (the angles jump where they meet): a spectrum across the join read the step as
    broadband motion, a bandwidth of hundreds of Hz and the cut-off at its cap (a UR5 recording joined
    across a 0.5 s gap: 200 Hz, and link + friction 2.9-5 N m off instead of 0.2-0.4)."""
    a = _recording(freqs=(0.5, 0.7), q_noise=1e-4, seconds=10.0, seed=1)
    b = _recording(freqs=(0.5, 0.7), q_noise=1e-4, seconds=10.0, seed=2)
    b = Dataset(b.t + a.t[-1] + 0.5, b.q + np.array([1.5, -2.0]), b.tau)  # another pose, after a gap
    joined = Dataset.concat([a, b])
    assert len(joined.runs) == 2
    one, d_one = choose_cutoff(a, upper=RATE / 5)
    both, d_both = choose_cutoff(joined, upper=RATE / 5)
    assert d_both["bandwidth_hz"] < 2 * d_one["bandwidth_hz"] and both < 2 * one < RATE / 5, (d_one, d_both)
    # read as one run, the join is the broadband step that set the cap
    whole = Dataset(np.arange(joined.m) / RATE, joined.q, joined.tau)
    assert choose_cutoff(whole, upper=RATE / 5)[1]["bandwidth_hz"] > 10 * d_one["bandwidth_hz"]
