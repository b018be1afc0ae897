"""How a dataset becomes the states and torques of the identification: settings and prepared data.

:class:`Preprocessing` holds the settings (filters, trimming, decimation, parallel filtering);
:func:`prepare` applies them to a dataset (:func:`dynid.data.preprocess.preprocess` for the
states) and returns a :class:`Prepared`: the states at full rate, the rows kept after trimming and
decimation, and the torque filter that every regressor column shares (parallel filtering).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from functools import cached_property
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from dynid.data.dataset import Dataset
from dynid.data.preprocess import (
    butter_sos,
    central_difference,
    choose_cutoff,
    filtfilt_rows,
    kept_rows,
    lowpass,
    preprocess,
    resample,
)
from dynid.exceptions import DataError, DataWarning

__all__ = ["AUTO_CUTOFF_HZ", "Prepared", "Preprocessing", "prepare", "still_joints"]

AUTO_CUTOFF_HZ = 20.0
"""Lowest cut-off (Hz) that ``cutoff="auto"`` chooses on data without measured velocities (the
earlier fixed default, kept as a floor so that simulated data keep their preprocessing)."""
DQ_AGREEMENT = 0.05
"""Relative RMS difference below which a measured ``dq`` counts as agreeing with the derivative of ``q``."""


@dataclass(frozen=True)
class Preprocessing:
    """How a dataset becomes the states and torques of the identification.

    Parameters
    ----------
    cutoff : float or None or "auto"
        Cut-off (Hz) of the zero-phase Butterworth low-pass applied to the torque and, with
        ``parallel``, to every regressor column.  None: no filter.  ``"auto"`` (default): None when the
        dataset has measured ``dq`` and ``ddq``; else chosen from the recording by
        :func:`dynid.data.preprocess.choose_cutoff` (the motion's and the torque's signal band),
        at most a fifth of the sampling rate and, without a measured ``dq``, at least
        :data:`AUTO_CUTOFF_HZ`.  The prepared settings record the rule (``cutoff_rule``).
    state_cutoff : float or None or "auto"
        Cut-off (Hz) of the low-pass on ``q`` (and measured ``dq``, ``ddq``) before differentiation.
        ``"auto"`` (default): the same as ``cutoff``.
    order : int
        Butterworth order (5 in the paper); run forward and backward.
    decimate : int
        Keep one sample in ``decimate`` after filtering.
    thin : bool
        With ``decimate`` 1 (default True): a recording whose data matrix would not fit the memory dynid
        holds is identified on one sample in ``D`` (:func:`dynid.identify.linear_system.thinned_for_memory`,
        the model file says so).  False keeps every sample whatever it costs (``--decimate 1`` on the
        command line).
    trim : float or None
        Time (s) dropped at both ends of each run (filter transients).  Default ``5 / cutoff`` (the
        lower of the two cut-offs; 0 without a filter): the edge transient of a zero-phase filter on
        ``q`` lasts that long in the differentiated ``ddq`` (measured: 10 % error at 2 / cutoff, 1e-4 at
        5 / cutoff).
    parallel : bool
        Parallel filtering (default): the regressor is built from the states and filtered like the
        torque.  False: the paper's way, regressor from filtered states and torque filtered apart.
    velocity : {"auto", "measured", "differentiate"}
        A measured ``dq``: used if it agrees with the derivative of the filtered ``q`` (relative RMS
        difference below :data:`DQ_AGREEMENT`; ``"auto"``, default), always, or never.  The prepared
        settings say which (``dq``, ``dq_evidence``).
    """

    cutoff: float | Literal["auto"] | None = "auto"
    state_cutoff: float | Literal["auto"] | None = "auto"
    order: int = 5
    decimate: int = 1
    thin: bool = True
    trim: float | None = None
    parallel: bool = True
    velocity: Literal["auto", "measured", "differentiate"] = "auto"

    def resolve(self, ds: Dataset) -> dict[str, Any]:
        """Concrete settings for a dataset (no ``"auto"`` left): a JSON-ready dict.

        Parameters
        ----------
        ds : Dataset
            The data the settings apply to (its sampling rate and signals decide ``"auto"``).
        """
        return self._resolve(ds)[0]

    def _resolve(self, ds: Dataset) -> tuple[dict[str, Any], str]:
        """The settings of :meth:`resolve` and one sentence on how the cut-off was chosen."""
        fs = 1.0 / ds.dt
        cutoff = self.cutoff
        rule = "given"
        if cutoff == "auto":
            if ds.dq is not None and ds.ddq is not None:
                cutoff, rule = None, "none: dq and ddq are measured"
            else:
                upper = fs / 5.0
                if isinstance(self.decimate, int | np.integer) and self.decimate > 1:
                    upper = min(upper, 0.8 * fs / (2 * self.decimate))
                uniform = ds if ds.is_uniform else resample(ds)
                chosen, details = choose_cutoff(uniform, upper=upper)
                floor = min(AUTO_CUTOFF_HZ, upper) if ds.dq is None else 0.0
                cutoff = float(max(chosen, floor))
                rule = details["rule"] + (
                    f"; raised to {floor:g} Hz (the floor without a measured dq)" if chosen < floor else ""
                )
        state_cutoff = cutoff if self.state_cutoff == "auto" else self.state_cutoff
        for label, value in (("cutoff", cutoff), ("state_cutoff", state_cutoff)):
            if value is not None and not (isinstance(value, int | float) and 0 < value < fs / 2):
                raise DataError(
                    f"{label} is {value!r}; give a frequency (Hz) between 0 and the Nyquist frequency "
                    f"{fs / 2:g} Hz of these data, 'auto', or None for no filter"
                )
        if not (isinstance(self.decimate, int | np.integer) and self.decimate >= 1):
            raise DataError(f"decimate is {self.decimate!r}; give a positive integer (1 keeps every sample)")
        if cutoff is not None and self.decimate > 1 and cutoff >= fs / (2 * self.decimate):
            raise DataError(
                f"decimating by {self.decimate} puts the Nyquist frequency at {fs / (2 * self.decimate):g} Hz, "
                f"not above the {cutoff:g} Hz cut-off; lower the cut-off or decimate less"
            )
        lowest = min((c for c in (cutoff, state_cutoff) if c is not None), default=None)
        trim = (5.0 / lowest if lowest is not None else 0.0) if self.trim is None else float(self.trim)
        if not (math.isfinite(trim) and trim >= 0):
            raise DataError(f"trim is {trim!r}; give a non-negative time in seconds")
        if self.velocity not in ("auto", "measured", "differentiate"):
            raise DataError(f"velocity is {self.velocity!r}; give 'auto', 'measured' or 'differentiate'")
        return {
            "cutoff_hz": None if cutoff is None else float(cutoff),
            "state_cutoff_hz": None if state_cutoff is None else float(state_cutoff),
            "order": int(self.order),
            "decimate": int(self.decimate),
            "trim_s": trim,
            "parallel": bool(self.parallel),
        }, rule

    @classmethod
    def from_settings(cls, settings: dict[str, Any]) -> Preprocessing:
        """The preprocessing that :meth:`resolve` described (to apply it again, e.g. from a model file).

        Parameters
        ----------
        settings : dict
            The output of :meth:`resolve`.
        """
        return cls(
            cutoff=settings["cutoff_hz"],
            state_cutoff=settings["state_cutoff_hz"],
            order=int(settings["order"]),
            decimate=int(settings["decimate"]),
            trim=float(settings["trim_s"]),
            parallel=bool(settings["parallel"]),
            # files written before the choice: a measured dq was always used
            velocity=_velocity_choice(settings),
        )


@dataclass(frozen=True, eq=False)
class Prepared:
    """A dataset made ready for identification or prediction (see :func:`prepare`).

    Attributes
    ----------
    t : ndarray, shape (M,)
        Time stamps (s) at full rate (after resampling, before trimming and decimation).
    q, dq, ddq : ndarray, shape (M, n)
        States the regressor is evaluated at (rad, rad/s, rad/s^2).
    tau : ndarray, shape (M, n)
        Measured torque (N m): raw with parallel filtering (it is filtered with the regressor),
        filtered otherwise.
    runs : list of slice
        Runs filtered separately.
    rows : ndarray of int, shape (m,)
        Rows kept (trimmed, decimated): the samples of the identification.
    fs : float
        Sampling rate (Hz) at full rate.
    settings : dict
        The resolved :class:`Preprocessing` settings.
    reference : str
        How the measured torque at the kept rows was treated ("raw", "filtered and trimmed", ...).
    """

    t: NDArray[np.float64]
    q: NDArray[np.float64]
    dq: NDArray[np.float64]
    ddq: NDArray[np.float64]
    tau: NDArray[np.float64]
    runs: list[slice]
    rows: NDArray[np.intp]
    fs: float
    settings: dict[str, Any]
    reference: str

    @property
    def m(self) -> int:
        """Number of samples kept."""
        return len(self.rows)

    @property
    def parallel_filter(self) -> bool:
        """Whether the torque and the regressor columns are low-passed together."""
        return bool(self.settings["parallel"] and self.settings["cutoff_hz"] is not None)

    @cached_property
    def sos(self) -> NDArray[np.float64] | None:
        """The parallel filter in second-order sections, or None."""
        if not self.parallel_filter:
            return None
        return butter_sos(self.settings["cutoff_hz"], self.fs, self.settings["order"])

    @cached_property
    def noise_correlation(self) -> float:
        """How much the torque's filter correlates white noise from one kept sample to the next.

        ``kappa = sum_k rho(k D)`` over all lags, ``rho`` the autocorrelation of white noise after the
        zero-phase low-pass (``cutoff``) and ``D`` the decimation: a sum of ``m`` kept samples of
        filtered white noise has ``kappa`` times the variance of ``m`` independent ones, so ``m / kappa``
        is their effective count.  About ``1.09 fs / (2 cutoff D)`` for the order-5 Butterworth
        (27.3 at 20 Hz and 1 kHz), at least 1; 1 without a filter.
        """
        cutoff = self.settings["cutoff_hz"]
        if cutoff is None:
            return 1.0
        sos = butter_sos(cutoff, self.fs, self.settings["order"])
        half = int(np.ceil(40 * self.fs / cutoff)) + 64  # the impulse response has died out by then
        impulse = np.zeros(2 * half + 1)
        impulse[half] = 1.0
        h = filtfilt_rows(sos, impulse[None, :], padded=False)[0]
        acf = np.correlate(h, h, mode="full")[len(h) - 1 :]
        rho = acf / acf[0]
        D = int(self.settings["decimate"])
        return max(1.0, float(1.0 + 2.0 * rho[D::D].sum()))

    def filter(self, signal: NDArray[np.float64]) -> NDArray[np.float64]:
        """Apply the parallel filter (the torque's) to a full-rate signal of shape (M, ...).

        Parameters
        ----------
        signal : ndarray, shape (M, ...)
            Samples at full rate (time along axis 0).
        """
        if not self.parallel_filter:
            return np.asarray(signal, dtype=np.float64)
        return lowpass(
            signal,
            fs=self.fs,
            cutoff=self.settings["cutoff_hz"],
            order=self.settings["order"],
            runs=self.runs,
        )

    @cached_property
    def tau_reference(self) -> NDArray[np.float64]:
        """Measured torque at the kept rows, treated as the model's predictions are (N m), (m, n)."""
        return self.filter(self.tau)[self.rows]

    def kept(self) -> Dataset:
        """The kept samples as a dataset: states and the reference torque."""
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DataWarning)
            return Dataset(
                self.t[self.rows],
                self.q[self.rows],
                self.tau_reference,
                dq=self.dq[self.rows],
                ddq=self.ddq[self.rows],
                meta={"preprocess": self.settings, "reference": self.reference},
            )


def prepare(
    ds: Dataset, preprocessing: Preprocessing | None = None, *, n_joints: int | None = None
) -> Prepared:
    """States at full rate, kept rows and torque treatment of a dataset.

    Parameters
    ----------
    ds : Dataset
        Measured or simulated data: ``t``, ``q``, ``tau`` and optionally ``dq``, ``ddq``.
    preprocessing : Preprocessing, optional
        Settings (default :class:`Preprocessing`).
    n_joints : int, optional
        Joint count the data must have.

    Returns
    -------
    Prepared
    """
    if not isinstance(ds, Dataset):
        raise DataError(
            f"expected a Dataset; got {type(ds).__name__}; build one with Dataset(t, q, tau) or load_dataset(path)"
        )
    if n_joints is not None:
        ds.check_joints(n_joints)
    pre = preprocessing or Preprocessing()
    settings, rule = pre._resolve(ds)
    parallel = settings["parallel"] and settings["cutoff_hz"] is not None
    state_cutoff = settings["state_cutoff_hz"] if parallel else settings["cutoff_hz"]
    velocity, evidence = pre.velocity, None
    if ds.dq is not None and velocity == "auto":
        velocity, evidence = _velocity_evidence(ds, state_cutoff, settings["order"])
    states = preprocess(
        ds,
        cutoff=state_cutoff,
        order=settings["order"],
        decimate=1,
        trim=0.0,
        filter_torque=not parallel,
        velocity="differentiate" if velocity == "differentiate" else "measured",
    )
    trim_samples = int(np.ceil(settings["trim_s"] * (1.0 / states.dt) - 1e-9))
    rows = kept_rows(states.runs, decimate=settings["decimate"], trim_samples=trim_samples)
    steps = []
    if states.meta["preprocess"].get("resampled"):
        steps.append("resampled")
    if settings["cutoff_hz"] is not None:
        steps.append("filtered")
    if settings["decimate"] > 1:
        steps.append("decimated")
    if settings["trim_s"] > 0:
        steps.append("trimmed")
    reference = (
        "raw" if not steps else (", ".join(steps[:-1]) + " and " + steps[-1] if len(steps) > 1 else steps[0])
    )
    return Prepared(
        t=states.t,
        q=states.q,
        dq=states.dq,  # type: ignore[arg-type]
        ddq=states.ddq,  # type: ignore[arg-type]
        tau=states.tau,
        runs=states.runs,
        rows=rows,
        fs=1.0 / states.dt,
        settings={
            **settings,
            "dq": states.meta["preprocess"]["dq"],
            "ddq": states.meta["preprocess"]["ddq"],
            "cutoff_rule": rule,
            **({} if evidence is None else {"dq_evidence": evidence}),
        },
        reference=reference,
    )


def _velocity_choice(settings: dict[str, Any]) -> Literal["auto", "measured", "differentiate"]:
    """How a model file's preparation treated a measured dq, to treat new data the same way."""
    if "dq_evidence" not in settings:  # no measured dq was weighed (or an older file): as before
        return "measured"
    return "measured" if str(settings.get("dq", "")).startswith("measured") else "differentiate"


def _velocity_evidence(ds: Dataset, cutoff: float | None, order: int) -> tuple[str, str]:
    """Use a measured dq or differentiate q: ("measured" | "differentiate", the evidence in a sentence).

    Both through the same filter, the measured dq is compared with the central difference of q; if
    they differ by less than :data:`DQ_AGREEMENT` of the RMS speed the measured one is used (it has no
    differentiation noise), else q is differentiated (a lagged, scaled or biased velocity would bias
    the friction and the Coriolis columns).
    """
    uniform = ds if ds.is_uniform else resample(ds)
    fs = 1.0 / uniform.dt
    q, dq = uniform.q, uniform.dq
    if cutoff is not None:
        q = lowpass(q, fs=fs, cutoff=cutoff, order=order, runs=uniform.runs)
        dq = lowpass(dq, fs=fs, cutoff=cutoff, order=order, runs=uniform.runs)
    dq_q = central_difference(q, uniform.dt, derivative=1, runs=uniform.runs)
    edge = max(1, int(0.05 * len(q)))
    inner = slice(edge, len(q) - edge)
    scale = float(np.sqrt(np.mean(dq_q[inner] ** 2)))
    if scale <= 0:
        return "measured", "the joints do not move: measured dq kept"
    diff = float(np.sqrt(np.mean((dq[inner] - dq_q[inner]) ** 2))) / scale
    if diff < DQ_AGREEMENT:
        return "measured", (
            f"measured dq used: it agrees with the derivative of q within {100 * diff:.2g} % of the RMS speed"
        )
    return "differentiate", (
        f"derivative of q used: the measured dq differs from it by {100 * diff:.2g} % of the RMS speed "
        f"(more than {100 * DQ_AGREEMENT:g} %)"
    )


def still_joints(prepared: Prepared, *, tol: float = 1e-4) -> list[int]:
    """Joints (1-based) that hardly move in the kept samples: range of q below ``tol`` (rad or m).

    Parameters
    ----------
    prepared : Prepared
        The prepared data.
    tol : float
        Range below which a joint counts as still.
    """
    q = prepared.q[prepared.rows]
    return [j + 1 for j in range(q.shape[1]) if np.ptp(q[:, j]) < tol]
