"""The low-pass cut-off chosen from a recording itself: where its motion and torque carry signal.

:func:`choose_cutoff` reads the spectra of ``q`` and ``tau`` and picks the cut-off that torque and
regressor are filtered at (:class:`dynid.data.preparation.Preprocessing` with ``cutoff="auto"``).
Split out of :mod:`dynid.data.preprocess`, which re-exports its names.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynid.data.dataset import Dataset
from dynid.data.dsp import welch

__all__ = ["BANDWIDTH_FACTOR", "SIGNAL_DB", "choose_cutoff"]

BANDWIDTH_FACTOR = 10.0
"""The cut-off :func:`choose_cutoff` chooses is at least this many times the motion's bandwidth."""
SIGNAL_DB = 30.0
"""How far (dB) above its high-frequency noise floor a spectrum counts as signal in :func:`choose_cutoff`."""


def _spectrum(x: NDArray[np.float64], fs: float, runs: list[slice] | None = None):
    """Welch power spectrum of each column of ``x``, run by run (the runs' spectra averaged by length).

    A recording joined from runs jumps where they meet; a spectrum across the join reads that step as
    broadband motion (a 10 s run joined to another: a "bandwidth" of 297 Hz, the cut-off at its cap).
    """
    runs = [slice(0, len(x))] if not runs else list(runs)
    longest = max(r.stop - r.start for r in runs)
    nper = int(max(16, min(longest // 4, round(2.0 * fs))))
    usable = [r for r in runs if r.stop - r.start >= nper] or [max(runs, key=lambda r: r.stop - r.start)]
    spectra = [welch(x[r], fs, min(nper, r.stop - r.start), detrend="linear") for r in usable]
    if len(spectra) == 1:  # one run: its spectrum as it is
        return spectra[0]
    lengths = [r.stop - r.start for r in usable]
    return spectra[0][0], sum(P * w for (_, P), w in zip(spectra, lengths, strict=True)) / sum(lengths)


def _signal_edge(x: NDArray[np.float64], fs: float, runs: list[slice] | None = None) -> tuple[float, float]:
    """Median over columns of the highest frequency (Hz) at which the spectrum of ``x`` stands
    :data:`SIGNAL_DB` above its noise floor (the median of the upper half of the band), and the
    frequency below which 99.9 % of its power lies (spectra taken run by run)."""
    f, P = _spectrum(x, fs, runs)
    floor = np.median(P[f >= fs / 4], axis=0)
    edges, bands = [], []
    for j in range(P.shape[1]):
        total = P[1:, j].sum()
        if not np.isfinite(total) or total <= 0:
            continue  # a still joint says nothing
        cum = np.cumsum(P[1:, j]) / total
        bands.append(float(f[1:][np.searchsorted(cum, 0.999)]))
        above = np.flatnonzero(P[1:, j] > 10 ** (SIGNAL_DB / 10) * max(floor[j], 1e-300))
        edges.append(float(f[1:][above.max()]) if len(above) else float(f[1]))
    if not edges:
        return float("nan"), float("nan")
    return float(np.median(edges)), float(np.max(bands))


def choose_cutoff(ds: Dataset, *, upper: float) -> tuple[float, dict[str, Any]]:
    """A low-pass cut-off (Hz) for torque and regressor, chosen from the recording itself.

    The filter should pass every frequency at which the data carry information and stop the rest:

    - the motion: the highest frequency at which the spectrum of ``q`` stands :data:`SIGNAL_DB` above
      its own noise floor (encoder noise, quantisation), median over the joints; above it the
      differentiated ``ddq`` is noise;
    - the torque: the same edge of the torque's spectrum; vibration and drive noise that no motion
      explains sit below it only where they are stronger than the motion's torque.

    The cut-off is the higher of the two edges (nothing that either signal carries is cut), at least
    :data:`BANDWIDTH_FACTOR` times the motion's bandwidth (99.9 % of the power of ``q``) and at most
    ``upper``.  The floor keeps the harmonics of the nonlinear dynamics (products of sines of the
    angles, the sign switch of Coulomb friction), which separate friction from the link columns.

    Measured on the real recordings (identified on the first part, scored on the rest, see
    ``benchmarks/real_robots_benchmark.py``): the Panda's q stands 30 dB above its floor up to 4.5 Hz,
    its torque up to 5 Hz, its bandwidth is 1.5 Hz; the TX40's q up to 52 Hz.  On the Panda, cut-offs
    of 6-12 Hz gave the lowest error of the whole model, but its physical layers alone then lost up to
    36 % against OLS with linear friction on some joints; from 15 Hz (ten times the bandwidth) they
    did not (the TX40: best from 40 Hz, both ways).

    Parameters
    ----------
    ds : Dataset
        The recording (uniform stamps; resample first otherwise).
    upper : float
        Largest cut-off allowed (Hz).

    Returns
    -------
    cutoff : float
        The cut-off (Hz).
    details : dict
        ``motion_hz`` (edge of q), ``torque_hz`` (edge of tau), ``bandwidth_hz`` (99.9 % of q's power),
        ``rule`` (one sentence).
    """
    fs = 1.0 / ds.dt
    runs = ds.runs
    motion, bandwidth = _signal_edge(np.asarray(ds.q, dtype=np.float64), fs, runs)
    torque, _ = _signal_edge(np.asarray(ds.tau, dtype=np.float64), fs, runs)
    if not np.isfinite(motion):
        return float(upper), {
            "motion_hz": None,
            "torque_hz": None,
            "bandwidth_hz": None,
            "rule": f"no joint moves: the largest cut-off, {upper:g} Hz",
        }
    chosen = max(motion, torque if np.isfinite(torque) else motion, BANDWIDTH_FACTOR * bandwidth)
    cutoff = float(min(chosen, upper))
    rule = (
        f"from the data: q carries signal up to {motion:.3g} Hz, the torque up to {torque:.3g} Hz "
        f"(30 dB above their noise floors), the motion's bandwidth is {bandwidth:.3g} Hz (the cut-off is at "
        f"least {BANDWIDTH_FACTOR:g} times that)" + (f"; capped at {upper:g} Hz" if chosen > upper else "")
    )
    return cutoff, {
        "motion_hz": motion,
        "torque_hz": torque if np.isfinite(torque) else None,
        "bandwidth_hz": bandwidth,
        "rule": rule,
    }
