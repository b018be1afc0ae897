"""The gap map: where, in the motion, the model's held-out residual exceeds the noise floor.

The residual of each joint is binned by the conditions under which unmodelled effects show
(DIAGNOSIS.md section 1): speed (stiction / low / high), time to a velocity reversal, driving vs
back-driven, gravity load, acceleration, joint angle modulo a gear period, time in the run and
frequency band.  The excess of a bin is ``mean(r^2) / sigma^2`` (1 = at the noise floor), with a
moving-block bootstrap interval.  Three global flags complete it: whiteness (Ljung-Box), the
cross-correlation of the residual with the predicted torque over +-50 ms (a delay: a maximum inside
the window that stands above the zero-lag value, never one on its edge or on a flat curve), and the angle-domain spectrum (cogging).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynid.data.dsp import welch
from dynid.diagnosis.stats import block_bootstrap_ci, ljung_box
from dynid.validation.metrics import NoiseFloor

__all__ = ["BIN_KINDS", "gap_map"]

BIN_KINDS = ("speed", "reversal", "power", "gravity", "acceleration", "gear_phase", "time", "frequency")
"""The conditions the residual is binned by, in the order of the map."""

_FREQ_BANDS = ((0.0, 1.0), (1.0, 5.0), (5.0, 20.0), (20.0, math.inf))


def _reversal_time(t: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
    """Time (s) from each sample to the nearest sign change of v."""
    s = np.sign(v)
    idx = np.flatnonzero(s[1:] * s[:-1] < 0)
    if idx.size == 0:
        return np.full(t.size, np.inf)
    tc = 0.5 * (t[idx] + t[idx + 1])
    pos = np.searchsorted(tc, t)
    left = np.abs(t - tc[np.clip(pos - 1, 0, tc.size - 1)])
    right = np.abs(tc[np.clip(pos, 0, tc.size - 1)] - t)
    return np.minimum(left, right)


def _terciles(x: NDArray[np.float64], label: str, unit: str) -> list[tuple[str, NDArray[np.bool_]]]:
    if float(np.max(np.abs(x))) < 1e-9:  # e.g. no gravity load on a vertical first joint
        return [(f"{label} = 0 {unit}", np.ones(x.shape, dtype=bool))]
    a, b = np.quantile(x, [1 / 3, 2 / 3])
    return [
        (f"{label} < {a:.3g} {unit}", x < a),
        (f"{a:.3g}-{b:.3g} {unit}", (x >= a) & (x < b)),
        (f"{label} >= {b:.3g} {unit}", x >= b),
    ]


def _gravity(robot, q: NDArray[np.float64]) -> NDArray[np.float64]:
    import pinocchio as pin

    model = robot.pin_model
    data = model.createData()
    return np.array([pin.computeGeneralizedGravity(model, data, qi) for qi in q])


def gap_map(
    *,
    t: NDArray[np.float64],
    q: NDArray[np.float64],
    dq: NDArray[np.float64],
    ddq: NDArray[np.float64],
    tau: NDArray[np.float64],
    tau_pred: NDArray[np.float64],
    residual: NDArray[np.float64],
    noise: NoiseFloor,
    block: int,
    robot,
    gear_ratio: float = 100.0,
    noise_signal: NDArray[np.float64] | None = None,
    filter_gain=None,
) -> dict[str, Any]:
    """Residual excess over the noise floor per joint and bin, with bootstrap intervals and global flags.

    Parameters
    ----------
    t : ndarray, shape (m,)
        Time (s) of the (uniformly spaced) samples.
    q, dq, ddq : ndarray, shape (m, n)
        States (rad, rad/s, rad/s^2).
    tau, tau_pred : ndarray, shape (m, n)
        Measured (filtered) and predicted torque (N m).
    residual : ndarray, shape (m, n)
        ``tau - tau_pred`` of the model diagnosed (N m).
    noise : NoiseFloor
        Noise floor of the same (filtered) torque.
    block : int
        Block length (samples) of the bootstrap.
    robot : RobotModel
        For the gravity torque.
    gear_ratio : float
        Gear ratio N of the angle bins (``N q mod 2 pi``).
    noise_signal : ndarray, shape (m, n), optional
        A realisation of the noise, for its spectrum; default white noise of the floor's level
        shaped by ``filter_gain``.
    filter_gain : callable, optional
        ``filter_gain(f) -> |H(f)|^2`` of the torque's (zero-phase) filter, for the noise spectrum.

    Returns
    -------
    dict
        ``joints``: per joint a dict ``{kind: [{"label", "count", "excess", "low", "high"}, ...]}``,
        ``flags``: ``whiteness``, ``delay``, ``cogging`` per joint, ``units``.
    """
    m, n = residual.shape
    sigma2 = np.maximum(noise.std**2, 1e-24)
    dt = float(np.median(np.diff(t))) if m > 1 else 1.0
    fs = 1.0 / dt
    rng = np.random.default_rng(0)
    g = _gravity(robot, q)
    joints = []
    flags: dict[str, list[dict[str, Any]]] = {"whiteness": [], "delay": [], "cogging": []}
    for j in range(n):
        bins = _joint_bins(t, q[:, j], dq[:, j], ddq[:, j], tau_pred[:, j], g[:, j], gear_ratio)
        out_j = _bin_rows(bins, residual[:, j] ** 2, float(sigma2[j]), block, rng)
        out_j["frequency"] = _frequency_bins(
            residual[:, j], float(sigma2[j]), fs, filter_gain, noise_signal, j
        )
        joints.append(out_j)
        for key, item in _joint_flags(residual[:, j], tau_pred[:, j], q[:, j], fs, block, j).items():
            flags[key].append(item)
    return {
        "joints": joints,
        "flags": flags,
        "kinds": list(BIN_KINDS),
        "gear_ratio": gear_ratio,
        "units": "excess = mean(r^2) / noise variance (1: at the noise floor); 90 % moving-block bootstrap interval",
    }


def _joint_bins(
    t: NDArray[np.float64],
    q: NDArray[np.float64],
    v: NDArray[np.float64],
    ddq: NDArray[np.float64],
    tau_pred: NDArray[np.float64],
    g: NDArray[np.float64],
    gear_ratio: float,
) -> dict[str, list[tuple[str, NDArray[np.bool_]]]]:
    """One joint's bins (label and sample mask) per condition, in the map's order (frequency aside)."""
    vmax = max(float(np.max(np.abs(v))), 1e-9)
    tr = _reversal_time(t, v)
    phase = np.mod(gear_ratio * q, 2 * math.pi)
    edges = np.linspace(t[0], t[-1], 5)
    return {
        "speed": [
            ("stiction |dq| < 2 % of max", np.abs(v) < 0.02 * vmax),
            ("low speed < 30 %", (np.abs(v) >= 0.02 * vmax) & (np.abs(v) < 0.3 * vmax)),
            ("high speed >= 30 %", np.abs(v) >= 0.3 * vmax),
        ],
        "reversal": [
            ("< 50 ms from a reversal", tr < 0.05),
            ("50-200 ms", (tr >= 0.05) & (tr < 0.2)),
            (">= 200 ms", tr >= 0.2),
        ],
        "power": [
            ("driving (dq tau > 0)", v * tau_pred > 0),
            ("back-driven (dq tau < 0)", v * tau_pred <= 0),
        ],
        "gravity": _terciles(np.abs(g), "|g|", "N m"),
        "acceleration": _terciles(np.abs(ddq), "|ddq|", "rad/s^2"),
        "gear_phase": [
            (
                f"N q mod 2pi in [{k / 2:.1f}, {(k + 1) / 2:.1f}) pi (N = {gear_ratio:g})",
                (phase >= k * math.pi / 2) & (phase < (k + 1) * math.pi / 2),
            )
            for k in range(4)
        ],
        "time": [
            (f"{edges[k] - t[0]:.1f}-{edges[k + 1] - t[0]:.1f} s", (t >= edges[k]) & (t <= edges[k + 1]))
            for k in range(4)
        ],
    }


def _bin_rows(
    bins: dict[str, list[tuple[str, NDArray[np.bool_]]]],
    r2: NDArray[np.float64],
    sigma2: float,
    block: int,
    rng: np.random.Generator,
) -> dict[str, list[dict[str, Any]]]:
    """Each bin's count and bootstrapped excess of ``r2`` over ``sigma2`` (None below two samples)."""
    out: dict[str, list[dict[str, Any]]] = {}
    for kind, items in bins.items():
        rows = []
        for label, mask in items:
            cnt = int(mask.sum())
            if cnt < 2:
                rows.append({"label": label, "count": cnt, "excess": None, "low": None, "high": None})
                continue
            est, lo, hi = block_bootstrap_ci(r2[mask], sigma2, block=max(1, block), rng=rng)
            rows.append({"label": label, "count": cnt, "excess": est, "low": lo, "high": hi})
        out[kind] = rows
    return out


def _joint_flags(
    r: NDArray[np.float64],
    tau_pred: NDArray[np.float64],
    q: NDArray[np.float64],
    fs: float,
    block: int,
    j: int,
) -> dict[str, dict[str, Any]]:
    """One joint's global flags: ``whiteness`` (Ljung-Box), ``delay`` (cross-correlation), ``cogging``."""
    # Whiteness on a series decimated to about the filter's bandwidth (a low-passed residual is never white).
    stride = max(1, int(fs / 50.0))
    qlb, plb = ljung_box(r[::stride], lags=20)
    return {
        "whiteness": {"joint": j + 1, "Q": qlb, "p_value": plb, "white": bool(plb >= 0.05)},
        "delay": {"joint": j + 1, **_xcorr(r, tau_pred, fs, block)},
        "cogging": {"joint": j + 1, **_angle_spectrum(r, q)},
    }


def _frequency_bins(r, sigma2, fs, filter_gain, noise_signal, j) -> list[dict[str, Any]]:
    m = r.size
    nper = int(min(m, 2048))
    if nper < 16:
        return []
    f, p = welch(r, fs, nper, detrend="constant")
    if noise_signal is not None:
        _, pn = welch(noise_signal[:, j], fs, nper, detrend="constant")
    else:
        shape = np.ones_like(f) if filter_gain is None else np.maximum(filter_gain(f), 0.0)
        df = f[1] - f[0]
        total = float(np.sum(shape) * df)
        pn = sigma2 * shape / max(total, 1e-300)
    rows = []
    for lo, hi in _FREQ_BANDS:
        band = (f >= lo) & (f < hi)
        if lo >= fs / 2 or band.sum() == 0:
            continue
        num = float(np.sum(p[band]))
        den = float(np.sum(pn[band]))
        label = f"{lo:g}-{hi:g} Hz" if math.isfinite(hi) else f">= {lo:g} Hz"
        rows.append(
            {
                "label": label,
                "count": int(band.sum()),
                "excess": num / den if den > 0 else None,
                "low": None,
                "high": None,
                "power": num * (f[1] - f[0]),
            }
        )
    return rows


def _xcorr(r, tau, fs, block) -> dict[str, Any]:
    """Cross-correlation of the residual with the predicted torque over +-50 ms.

    Flagged when its largest magnitude exceeds the threshold at a non-zero lag inside the window, and
    stands above the zero-lag value by more than the threshold too (``rise``). On the window's edge
    (``at_edge``) the correlation rises monotonically toward a longer lag, which is no delay; a curve that
    is flat across the lags (a residual in proportion to a slow torque, as a parameter error gives) has
    its largest value anywhere, wherever the noise puts it, and is no delay either. A delay makes the
    residual follow the torque's change, so its correlation moves away from the zero-lag value.
    """
    L = max(1, round(0.05 * fs))
    a = r - r.mean()
    b = tau - tau.mean()
    da, db = float(np.sqrt(a @ a)), float(np.sqrt(b @ b))
    if da == 0 or db == 0:
        return {"lag_ms": 0.0, "rho": 0.0, "threshold": None, "at_edge": False, "rise": 0.0, "flag": False}
    lags = np.arange(-L, L + 1)
    rho = np.array(
        [
            float(a[max(0, -k) : a.size - max(0, k)] @ b[max(0, k) : b.size - max(0, -k)]) / (da * db)
            for k in lags
        ]
    )
    k = int(np.argmax(np.abs(rho)))
    # Effective sample count of low-passed signals: about one independent value per block / 10.
    m_eff = max(r.size / max(block / 10.0, 1.0), 4.0)
    thr = 3.0 / math.sqrt(m_eff)
    # A peak on the window's edge is no peak: the correlation still grows beyond the window (a slope, as a
    # slow residual against a slow torque gives), and a delay would show as a maximum inside it.
    at_edge = k in (0, lags.size - 1)
    rise = abs(float(rho[k] - rho[L]))  # rho[L] is the zero lag
    return {
        "lag_ms": float(1000.0 * lags[k] / fs),
        "rho": float(rho[k]),
        "threshold": thr,
        "at_edge": bool(at_edge),
        "rise": rise,
        "flag": bool(abs(rho[k]) > thr and lags[k] != 0 and not at_edge and rise > thr),
        "curve": {"lag_ms": (1000.0 * lags / fs).tolist(), "rho": rho.tolist()},
    }


def _angle_spectrum(r, q) -> dict[str, Any]:
    """Power of the residual at angular frequencies N (cycles per radian x 2 pi) of the joint angle."""
    ratios = np.arange(5.0, 301.0, 1.0)
    span = float(np.ptp(q))
    if span * 5.0 < 2 * math.pi:
        return {"peak_ratio": None, "peak": None, "flag": False, "note": "the joint hardly moves"}
    a = r - r.mean()
    ph = np.exp(-1j * np.outer(q, ratios[:1]))
    power = np.empty(ratios.size)
    for i, N in enumerate(ratios):
        ph = np.exp(-1j * N * q)
        power[i] = abs(np.mean(a * ph)) ** 2
    k = int(np.argmax(power))
    med = float(np.median(power))
    peak = float(power[k] / med) if med > 0 else None
    return {
        "peak_ratio": float(ratios[k]),
        "peak": peak,
        "flag": bool(peak is not None and peak > 30.0),
        "spectrum": {"N": ratios.tolist(), "power": power.tolist()},
    }
