"""How a dataset becomes the states and torques of the identification: settings and prepared data.

:class:`Preprocessing` holds the settings (filters, trimming, decimation, parallel filtering);
:func:`prepare` applies them to a dataset (:func:`dynid.identify.preprocess.preprocess` for the
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
from scipy.signal import sosfiltfilt

from dynid.exceptions import DataError, DataWarning
from dynid.identify.dataset import Dataset
from dynid.identify.preprocess import butter_sos, kept_rows, lowpass, preprocess

__all__ = ["AUTO_CUTOFF_HZ", "Prepared", "Preprocessing", "prepare", "still_joints"]

AUTO_CUTOFF_HZ = 20.0
"""Cut-off (Hz) that ``cutoff="auto"`` uses on data without measured velocities and accelerations."""


@dataclass(frozen=True)
class Preprocessing:
    """How a dataset becomes the states and torques of the identification.

    Parameters
    ----------
    cutoff : float or None or "auto"
        Cut-off (Hz) of the zero-phase Butterworth low-pass applied to the torque and, with
        ``parallel``, to every regressor column.  None: no filter.  ``"auto"`` (default): None when the
        dataset has measured ``dq`` and ``ddq``, else 20 Hz (at most a fifth of the sampling rate).
    state_cutoff : float or None or "auto"
        Cut-off (Hz) of the low-pass on ``q`` (and measured ``dq``, ``ddq``) before differentiation.
        ``"auto"`` (default): the same as ``cutoff``.
    order : int
        Butterworth order (5 in the paper); run forward and backward.
    decimate : int
        Keep one sample in ``decimate`` after filtering.
    trim : float or None
        Time (s) dropped at both ends of each run (filter transients).  Default ``5 / cutoff`` (the
        lower of the two cut-offs; 0 without a filter): the edge transient of a zero-phase filter on
        ``q`` lasts that long in the differentiated ``ddq`` (measured: 10 % error at 2 / cutoff, 1e-4 at
        5 / cutoff).
    parallel : bool
        Parallel filtering (default): the regressor is built from the states and filtered like the
        torque.  False: the paper's way, regressor from filtered states and torque filtered apart.
    """

    cutoff: float | Literal["auto"] | None = "auto"
    state_cutoff: float | Literal["auto"] | None = "auto"
    order: int = 5
    decimate: int = 1
    trim: float | None = None
    parallel: bool = True

    def resolve(self, ds: Dataset) -> dict[str, Any]:
        """Concrete settings for a dataset (no ``"auto"`` left): a JSON-ready dict.

        Parameters
        ----------
        ds : Dataset
            The data the settings apply to (its sampling rate and signals decide ``"auto"``).
        """
        fs = 1.0 / ds.dt
        cutoff = self.cutoff
        if cutoff == "auto":
            cutoff = None if (ds.dq is not None and ds.ddq is not None) else min(AUTO_CUTOFF_HZ, fs / 5.0)
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
        return {
            "cutoff_hz": None if cutoff is None else float(cutoff),
            "state_cutoff_hz": None if state_cutoff is None else float(state_cutoff),
            "order": int(self.order),
            "decimate": int(self.decimate),
            "trim_s": trim,
            "parallel": bool(self.parallel),
        }

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
        h = sosfiltfilt(sos, impulse, padlen=0)
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
    settings = (preprocessing or Preprocessing()).resolve(ds)
    parallel = settings["parallel"] and settings["cutoff_hz"] is not None
    state_cutoff = settings["state_cutoff_hz"] if parallel else settings["cutoff_hz"]
    states = preprocess(
        ds,
        cutoff=state_cutoff,
        order=settings["order"],
        decimate=1,
        trim=0.0,
        filter_torque=not parallel,
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
        settings={**settings, "dq": states.meta["preprocess"]["dq"], "ddq": states.meta["preprocess"]["ddq"]},
        reference=reference,
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
