"""The signal processing every command needs, without importing :mod:`scipy.signal`.

Importing :mod:`scipy.signal` costs about 0.75 s of CPU (scipy 1.17 wraps each of its functions for
array-API dispatch at import, and pulls in :mod:`scipy.stats`): more than an OLS identification of a
25,000-row recording takes after its imports.  Every ``dynid`` command reads a recording, chooses a
cut-off from its spectra and filters it, so the pieces they need are written here, each checked
against :mod:`scipy.signal` in ``tests/data/test_dsp.py``:

- :func:`butter_lowpass` designs a digital Butterworth low-pass in second-order sections as
  ``scipy.signal.butter(order, cutoff, fs=fs, output="sos")`` does (the same sections in the same order);
- :func:`sosfilt_inplace` runs sections with initial states as ``scipy.signal.sosfilt`` does, to the
  bit: the same loop in C (``_sosfilt.c``), compiled once per machine into dynid's cache (about 0.1 s)
  and called without the GIL, signals innermost; scipy.signal's own where no C compiler is at hand
  (:func:`sosfilt_zi` gives the steady-state initial states);
- :func:`frequency_response` is ``scipy.signal.sosfreqz`` at given frequencies;
- :func:`welch` is ``scipy.signal.welch`` with its default Hann window and half overlap, ``constant``
  or ``linear`` detrending, one-sided density.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import os
import platform
import shlex
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["butter_lowpass", "frequency_response", "sosfilt", "sosfilt_inplace", "sosfilt_zi", "welch"]


def butter_lowpass(order: int, cutoff: float, fs: float) -> NDArray[np.float64]:
    """Digital Butterworth low-pass of ``order`` at ``cutoff`` Hz for data sampled at ``fs`` Hz.

    The analogue prototype's poles, pre-warped and mapped by the bilinear transform, all zeros at
    -1; sections ordered as :func:`scipy.signal.zpk2sos` orders them (the poles nearest the unit circle
    last, an odd order's real pole first in a first-order section) with the gain in the first.

    Returns
    -------
    ndarray, shape (ceil(order / 2), 6)
        Rows ``[b0, b1, b2, 1, a1, a2]``.
    """
    if not (int(order) == order and order >= 1 and np.isfinite(fs) and fs > 0 and 0 < cutoff < fs / 2):
        raise ValueError(
            f"a Butterworth low-pass needs an order of 1 or more and a cut-off between 0 and the Nyquist "
            f"frequency {fs / 2:g} Hz; got order {order!r} and {cutoff!r} Hz"
        )
    order = int(order)
    k = np.arange(-order + 1, order, 2)
    analog = -np.exp(1j * np.pi * k / (2 * order))  # unit-cutoff prototype, left half plane
    warped = 4.0 * np.tan(np.pi * (2.0 * cutoff / fs) / 2.0)  # scipy's pre-warping at fs = 2
    p = warped * analog
    gain = warped**order
    fs2 = 4.0
    z_poles = (fs2 + p) / (fs2 - p)
    gain = float(np.real(gain / np.prod(fs2 - p)))
    upper = z_poles[np.imag(z_poles) > 0]
    real = np.real(z_poles[np.abs(np.imag(z_poles)) <= 1e-12 * np.abs(z_poles)])
    upper = upper[np.argsort(-np.abs(1.0 - np.abs(upper)))]  # farthest from the unit circle first
    # zpk2sos's "nearest" pairing: the poles nearest the unit circle take their nearest zeros first;
    # an odd order pads a zero at the origin, which a complex pole takes where it is nearer than -1
    origin = bool(order % 2)
    sections = []
    for pole in upper[::-1]:
        if origin and abs(pole) < abs(pole + 1.0):
            origin, zeros = False, [1.0, 1.0, 0.0]
        else:
            zeros = [1.0, 2.0, 1.0]
        sections.insert(0, [*zeros, 1.0, -2.0 * float(pole.real), float(abs(pole) ** 2)])
    if order % 2:  # the real pole, farthest from the unit circle, with the zeros left
        sections.insert(0, ([1.0, 1.0, 0.0] if origin else [1.0, 2.0, 1.0]) + [1.0, -float(real[0]), 0.0])
    sos = np.array(sections, dtype=np.float64)
    sos[0, :3] *= gain
    return sos


def sosfilt_zi(sos: NDArray[np.float64]) -> NDArray[np.float64]:
    """Initial states (n_sections, 2) of :func:`sosfilt` for a step response's steady state
    (:func:`scipy.signal.sosfilt_zi`): scaled by the input's first value, no start-up transient."""
    sos = np.asarray(sos, dtype=np.float64)
    zi = np.empty((len(sos), 2))
    scale = 1.0
    for i, (b0, b1, b2, a0, a1, a2) in enumerate(sos):
        b0, b1, b2, a1, a2 = b0 / a0, b1 / a0, b2 / a0, a1 / a0, a2 / a0
        # (I - companion(a)^T) zi = b[1:] - a[1:] b0, as scipy.signal.lfilter_zi solves it
        zi[i] = scale * np.linalg.solve(np.array([[1.0 + a1, -1.0], [a2, 1.0]]), [b1 - a1 * b0, b2 - a2 * b0])
        scale *= (b0 + b1 + b2) / (1.0 + a1 + a2)
    return zi


_SOURCE = Path(__file__).with_name("_sosfilt.c")
_FLAGS = ("-x", "c", "-O2", "-fPIC", "-shared", "-ffp-contract=off")
"""How the section loop is compiled: no floating-point contraction, so its values are scipy's to the bit."""


@functools.lru_cache(maxsize=1)
def _compiled() -> Any:
    """The compiled section loop (a ctypes function), built once per machine into dynid's cache; None
    where no C compiler or cache is at hand, and :func:`sosfilt_inplace` then runs scipy.signal's."""
    try:
        from dynid.symbolic.build import cache_dir, find_compiler

        given = shlex.split(os.environ.get("CC", ""))  # "ccache gcc" stays whole
        compiler = [find_compiler("c"), *given[1:]] if given else [find_compiler("c")]
        digest = hashlib.sha256(_SOURCE.read_bytes())
        digest.update(" ".join((*compiler, *_FLAGS, sys.platform, platform.machine())).encode())
        lib = cache_dir() / "dsp" / f"sosfilt-{digest.hexdigest()[:16]}.so"
        for attempt in range(2):
            if not lib.exists():
                _build(compiler, lib)
            try:
                function = ctypes.CDLL(str(lib)).dynid_sosfilt
                break
            except (OSError, AttributeError):  # a damaged library: built once more
                if attempt:
                    raise
                lib.unlink(missing_ok=True)
    except Exception:  # no compiler, a read-only cache, a failed build: scipy.signal's loop instead
        return None
    double_p = ctypes.POINTER(ctypes.c_double)
    function.restype = None
    size = ctypes.c_ssize_t
    function.argtypes = [double_p, size, double_p, size, size, double_p, ctypes.c_int]
    return function


def _build(compiler: list[str], lib: Path) -> None:
    """Compile the section loop into ``lib``, atomically (parallel builds write the same bytes)."""
    lib.parent.mkdir(parents=True, exist_ok=True)
    handle, tmp = tempfile.mkstemp(dir=lib.parent, prefix=".sosfilt-", suffix=".so")
    os.close(handle)
    try:
        subprocess.run([*compiler, *_FLAGS, str(_SOURCE), "-o", tmp], check=True, capture_output=True, timeout=120)
        os.replace(tmp, lib)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def sosfilt_inplace(
    sos: NDArray[np.float64], x: NDArray[np.float64], zi: NDArray[np.float64], reverse: bool = False
) -> None:
    """Filter the columns of ``x`` (L, k) through ``sos`` in place, starting from the states ``zi``.

    ``x`` must be a C-contiguous float64 array, time along axis 0 (the signals of one sample side by
    side); ``zi`` (n_sections, 2, k) the transposed-direct-form states, updated to the final ones;
    ``reverse`` runs from the last sample to the first.  The values are
    ``scipy.signal.sosfilt(sos, x, axis=0, zi=zi)``'s to the bit (the same arithmetic, compiled once
    into dynid's cache, run without the GIL); scipy's own loop where it cannot be compiled.
    """
    if x.dtype != np.float64 or not x.flags.c_contiguous or not x.flags.writeable or x.ndim != 2:
        raise ValueError("x must be a writeable C-contiguous float64 array of shape (L, k)")
    sos = np.ascontiguousarray(sos, dtype=np.float64)
    if sos.ndim != 2 or sos.shape[1] != 6 or len(sos) == 0:
        raise ValueError(f"sos must be second-order sections of shape (n_sections, 6); got shape {sos.shape}")
    if np.any(sos[:, 3] != 1.0):
        sos = sos / sos[:, 3:4]
    shape = (len(sos), 2, x.shape[1])
    if zi.shape != shape or zi.dtype != np.float64 or not zi.flags.c_contiguous or not zi.flags.writeable:
        raise ValueError(f"zi must be a writeable C-contiguous float64 array of shape {shape}")
    function = _compiled()
    if function is not None:
        double_p = ctypes.POINTER(ctypes.c_double)
        function(
            sos.ctypes.data_as(double_p), len(sos), x.ctypes.data_as(double_p), x.shape[0], x.shape[1],
            zi.ctypes.data_as(double_p), int(bool(reverse)),
        )  # fmt: skip
        return
    import scipy.signal

    view = x[::-1] if reverse else x
    view[:], zf = scipy.signal.sosfilt(sos, view, axis=0, zi=zi)
    zi[:] = zf


def sosfilt(sos: NDArray[np.float64], x: NDArray[np.float64], zi: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
    """``scipy.signal.sosfilt(sos, x, axis=0, zi=zi)[0]`` for ``x`` (L, k): the filtered copy (zero
    initial states when ``zi`` is None; ``zi`` broadcast to (n_sections, 2, k) and not changed)."""
    y = np.array(x, dtype=np.float64, order="C", copy=True)
    if y.ndim == 1:  # one signal
        return sosfilt(sos, y[:, None], None if zi is None else np.asarray(zi)[..., None])[:, 0]
    states = np.zeros((len(sos), 2, y.shape[1])) if zi is None else np.ascontiguousarray(
        np.broadcast_to(zi, (len(sos), 2, y.shape[1])), dtype=np.float64
    ).copy()
    sosfilt_inplace(sos, y, states)
    return y


def frequency_response(sos: NDArray[np.float64], f: NDArray[np.float64], fs: float) -> NDArray[np.complex128]:
    """Complex response of the sections ``sos`` at the frequencies ``f`` (Hz) for data sampled at ``fs``:
    ``scipy.signal.sosfreqz(sos, worN=f, fs=fs)[1]``."""
    zinv = np.exp(-2j * np.pi * np.asarray(f, dtype=np.float64) / fs)
    h = np.ones_like(zinv)
    for b0, b1, b2, a0, a1, a2 in np.asarray(sos, dtype=np.float64):
        h = h * (b0 + zinv * (b1 + zinv * b2)) / (a0 + zinv * (a1 + zinv * a2))
    return h


def welch(
    x: NDArray[np.float64], fs: float, nperseg: int, detrend: str = "constant"
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Welch power spectral density of each column of ``x`` (L, ...) along axis 0.

    :func:`scipy.signal.welch` with ``window="hann"``, ``noverlap=nperseg // 2``, ``detrend`` either
    ``"constant"`` or ``"linear"`` per segment, ``scaling="density"``, one-sided, mean over segments.
    ``nperseg`` larger than the signal is cut to its length.

    Returns
    -------
    f : ndarray, shape (nperseg // 2 + 1,)
    P : ndarray, shape (nperseg // 2 + 1, ...)
    """
    x = np.asarray(x, dtype=np.float64)
    nperseg = int(min(nperseg, x.shape[0]))
    if nperseg < 1:
        raise ValueError(f"welch needs at least one sample per segment; got a signal of {x.shape[0]} samples")
    step = nperseg - nperseg // 2
    count = (x.shape[0] - nperseg) // step + 1
    starts = np.arange(count) * step
    segments = x[starts[:, None] + np.arange(nperseg)[None, :]]  # (count, nperseg, ...)
    if detrend == "linear":
        t = np.arange(nperseg, dtype=np.float64)
        basis = np.stack([t - t.mean(), np.ones(nperseg)], axis=1)
        coef = np.linalg.lstsq(
            basis, segments.reshape(count, nperseg, -1).transpose(1, 0, 2).reshape(nperseg, -1), rcond=None
        )[0]
        trend = (basis @ coef).reshape(nperseg, count, -1).transpose(1, 0, 2).reshape(segments.shape)
        segments = segments - trend
    elif detrend == "constant":
        segments = segments - segments.mean(axis=1, keepdims=True)
    else:
        raise ValueError(f"detrend must be 'constant' or 'linear'; got {detrend!r}")
    window = 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(nperseg) / nperseg)  # periodic Hann
    if nperseg == 1:
        window = np.ones(1)  # scipy's Hann window of one sample
    shape = (1, nperseg) + (1,) * (x.ndim - 1)
    spectrum = np.fft.rfft(segments * window.reshape(shape), n=nperseg, axis=1)
    power = (spectrum.real**2 + spectrum.imag**2) / (fs * float(window @ window))
    if nperseg % 2:
        power[:, 1:] *= 2.0
    else:
        power[:, 1:-1] *= 2.0
    return np.fft.rfftfreq(nperseg, 1.0 / fs), power.mean(axis=0)
