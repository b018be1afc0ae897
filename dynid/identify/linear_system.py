"""The linear identification system: from a dataset to a compressed, stacked least-squares problem.

Layer 1 of the identification (METHOD.md section 4) solves ``tau = W x`` with ``W`` the regressor
stacked over ``m`` samples (``m n`` rows) and ``x`` the identified parameters: the base parameters of
the links, optionally the armature and the linear friction of each joint (Coulomb, viscous, offset:
the columns of ``friction_columns``).  This module builds that system once, without ever holding
``W`` twice in memory, and compresses it to a small triangular factor from which every weighting
(OLS, WLS, GLS, IRLS) is solved exactly.

The data path
-------------
1. :func:`prepare`: the states at full rate (zero-phase Butterworth on ``q``, central differences
   for missing ``dq`` / ``ddq``; :func:`dynid.identify.preprocess.preprocess`), the rows kept after
   trimming and decimation, and the torque filter.
2. The regressor columns through the compiled batch path (:func:`dynid.symbolic.export.compiled_functions`),
   a chunk of samples at a time, written once into one buffer ``Z`` of shape (m, c): one column per
   structurally non-zero (joint row, parameter) pair of the regressor, plus the n torques.  For the
   UR5 with friction and armature, c = 172 instead of the 6 x 60 + 6 = 366 of the dense layout.
3. Parallel filtering (DIAGNOSIS.md section 3): the same low-pass on every column of ``Z``, torque
   included, in place.
4. One pass of blocked Householder QR over the kept rows: ``Z = Q R_Z``.  ``R_Z`` (c x c) holds all
   that least squares needs: for any joint-noise covariance ``Omega = L L^T`` the whitened stacked
   system ``(I_m (x) L^-1) [W | tau]`` has the same R factor as the small matrix
   ``[R_Z T_1; ...; R_Z T_n]`` (n c rows), with ``T_i`` the (c x (p + 1)) map from the columns of
   ``Z`` to row i of the whitened regressor and torque.  No normal equations are formed.

Armature columns that duplicate a base column (joint 1 of an arm whose first axis is vertical:
its armature acts exactly like ``Izz1R``) are not given a column of their own; their parameter is
folded into the base parameter it duplicates and a note says so (:attr:`ColumnSet.notes`).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, Literal

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray
from scipy.signal import sosfiltfilt

from dynid.exceptions import DataError, IdentificationError, ShapeError
from dynid.identify._threads import single_blas_thread
from dynid.identify.dataset import Dataset, DataWarning
from dynid.identify.preprocess import butter_sos, kept_rows, lowpass, preprocess

__all__ = [
    "EXTRA_KINDS",
    "ColumnSet",
    "LinearSystem",
    "Prepared",
    "Preprocessing",
    "WeightedSolution",
    "build_system",
    "column_set",
    "linear_torque",
    "prepare",
]

EXTRA_KINDS = ("armature", "coulomb", "viscous", "offset")
"""Kinds of the extra (non-link) parameters, in the order of the physical vector ``phi``."""
_EXTRA_PREFIX = {"armature": "ia", "coulomb": "fc", "viscous": "fv", "offset": "fo"}
_CHUNK = 16384  # samples per call of the compiled regressor and per QR block
_FILTER_COLUMNS = 16  # columns of Z filtered at once (16 x 360,000 samples: 46 MB of temporaries)
_DEPENDENT_TOL = 1e-8  # relative residual below which an extra column lies in the span of the others
AUTO_CUTOFF_HZ = 20.0
"""Cut-off (Hz) that ``cutoff="auto"`` uses on data without measured velocities and accelerations."""


# ---------------------------------------------------------------------------- preprocessing settings
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


# ---------------------------------------------------------------------------- identified columns
@dataclass(frozen=True, eq=False)
class ColumnSet:
    """The identified parameters of a robot: base parameters plus optional armature and friction.

    The physical parameter vector is ``phi = [pi (10 n), ia (n), fc (n), fv (n), fo (n)]``: standard
    link parameters, armature (kg m^2), Coulomb (N m), viscous (N m s/rad) and offset (N m) per joint.
    The identified vector is ``x = P @ phi`` (p values): the base parameters, then the extras that have
    a column of their own.

    Attributes
    ----------
    robot : RobotModel
    base : BaseParameters
    friction, armature : bool
        Whether linear friction and armature columns are part of the system.
    names, kinds, expressions : tuple of str, length p
        Name (``Izz1R``, ``ia2``, ``fc3``...), kind (``link`` or one of :data:`EXTRA_KINDS`) and
        expression in the physical parameters of each identified parameter.
    joints : ndarray of int, shape (p,)
        Link (for a link parameter, the link of its leading standard parameter) or joint (extras) it
        belongs to, numbered from 1.
    extras : ndarray of int, shape (p - n_b,)
        Index into the 4 n extras of ``phi`` of each extra column kept.
    P : ndarray, shape (p, 14 n)
        ``x = P @ phi``.
    pattern : ndarray of bool, shape (n, p)
        Structurally non-zero entries of the identified regressor.
    notes : tuple of str
        What was folded where (duplicated columns).
    """

    robot: Any
    base: Any
    friction: bool
    armature: bool
    names: tuple[str, ...]
    kinds: tuple[str, ...]
    expressions: tuple[str, ...]
    joints: NDArray[np.intp]
    extras: NDArray[np.intp]
    P: NDArray[np.float64]
    pattern: NDArray[np.bool_]
    notes: tuple[str, ...]

    @property
    def n(self) -> int:
        """Number of joints."""
        return int(self.robot.n)

    @property
    def p(self) -> int:
        """Number of identified parameters."""
        return len(self.names)

    @property
    def n_base(self) -> int:
        """Number of base link parameters (the first ``n_base`` entries of ``x``)."""
        return int(self.base.n_base)

    @cached_property
    def link_mask(self) -> NDArray[np.bool_]:
        """Parameters of the rigid-body model: base parameters and armature (no friction)."""
        return np.array([k in ("link", "armature") for k in self.kinds])

    @cached_property
    def friction_mask(self) -> NDArray[np.bool_]:
        """Linear friction parameters (Coulomb, viscous, offset)."""
        return np.array([k in ("coulomb", "viscous", "offset") for k in self.kinds])

    @property
    def extra_names(self) -> tuple[str, ...]:
        """Names of the 4 n extras of ``phi`` (``ia1..ia_n, fc1.., fv1.., fo1..``)."""
        n = self.n
        return tuple(f"{_EXTRA_PREFIX[k]}{j + 1}" for k in EXTRA_KINDS for j in range(n))

    @property
    def enabled_extras(self) -> NDArray[np.bool_]:
        """Which of the 4 n extras are part of the model (identified alone or folded into another)."""
        n = self.n
        return np.concatenate([np.full(n, self.armature), np.full(3 * n, self.friction)])

    def extra_columns(self, dq: NDArray[np.float64], ddq: NDArray[np.float64]) -> NDArray[np.float64]:
        """Values of the kept extra columns: (m, p - n_b); column k acts on joint ``extra_joint[k]``.

        Armature ``ddq_j``, Coulomb ``sign(dq_j)``, viscous ``dq_j``, offset ``1``, as in
        ``friction_columns`` / ``armature_columns`` of :mod:`dynid.symbolic.functions`.

        Parameters
        ----------
        dq, ddq : ndarray, shape (m, n)
            Joint velocities (rad/s) and accelerations (rad/s^2).
        """
        n = self.n
        out = np.empty((len(dq), len(self.extras)))
        for k, e in enumerate(self.extras):
            kind, j = EXTRA_KINDS[e // n], e % n
            if kind == "armature":
                out[:, k] = ddq[:, j]
            elif kind == "coulomb":
                out[:, k] = np.sign(dq[:, j])
            elif kind == "viscous":
                out[:, k] = dq[:, j]
            else:
                out[:, k] = 1.0
        return out

    @property
    def extra_joint(self) -> NDArray[np.intp]:
        """Joint (0-based) each kept extra column acts on."""
        return (self.extras % self.n).astype(np.intp)


_COLUMN_CACHE: dict[tuple[str, bool, bool], ColumnSet] = {}
_BASE_CACHE: dict[str, Any] = {}


def _base_and_lib(robot):
    from dynid.symbolic.base import base_parameters
    from dynid.symbolic.export import compiled_functions
    from dynid.symbolic.functions import robot_functions

    # compiled_functions recomputes the base parameters on each call: keep both per robot.
    if robot.key not in _BASE_CACHE:
        with single_blas_thread():
            _BASE_CACHE[robot.key] = (base_parameters(robot_functions(robot)), compiled_functions(robot))
    return _BASE_CACHE[robot.key]


def compiled_base_regressor(robot, q, dq, ddq) -> NDArray[np.float64]:
    """Base regressor ``Y_b`` of a batch through the compiled path: (m, n, n_b)."""
    _, lib = _base_and_lib(robot)
    return lib.base_regressor(q, dq, ddq)


def column_set(robot, *, friction: bool = True, armature: bool = True) -> ColumnSet:
    """The identified parameters of ``robot`` (cached per robot and options).

    Parameters
    ----------
    robot : RobotModel
        The robot.
    friction : bool
        Identify linear friction (Coulomb, viscous, offset per joint) with the link parameters.
    armature : bool
        Identify the armature (rotor inertia) of each joint with the link parameters.

    Returns
    -------
    ColumnSet
    """
    key = (robot.key, bool(friction), bool(armature))
    cached = _COLUMN_CACHE.get(key)
    if cached is not None:
        return cached
    with single_blas_thread():
        out = _column_set(robot, friction, armature)
    _COLUMN_CACHE[key] = out
    return out


def _column_set(robot, friction: bool, armature: bool) -> ColumnSet:
    from dynid.symbolic.base import random_states

    base, lib = _base_and_lib(robot)
    n, nb = robot.n, base.n_base
    rng = np.random.default_rng(0)
    m = max(200, 40 * n)
    q, dq, ddq = random_states(robot, m, rng)
    Yb = lib.base_regressor(q, dq, ddq)  # (m, n, nb)
    pattern_b = np.any(Yb != 0.0, axis=0)
    enabled = np.concatenate([np.full(n, bool(armature)), np.full(3 * n, bool(friction))])
    extra_names = [f"{_EXTRA_PREFIX[k]}{j + 1}" for k in EXTRA_KINDS for j in range(n)]
    P = np.zeros((nb, 14 * n))
    P[:, : 10 * n] = base.matrix
    kept_cols = [Yb.reshape(m * n, nb)]
    kept_extra: list[int] = []
    expressions = list(base.expressions)
    notes = []
    ones = np.ones(m)
    for e in np.flatnonzero(enabled):
        kind, j = EXTRA_KINDS[e // n], e % n
        values = {"armature": ddq[:, j], "coulomb": np.sign(dq[:, j]), "viscous": dq[:, j], "offset": ones}[
            kind
        ]
        col = np.zeros((m, n))
        col[:, j] = values
        col = col.reshape(m * n, 1)
        W = np.hstack(kept_cols)
        coef, *_ = np.linalg.lstsq(W, col, rcond=None)
        resid = np.linalg.norm(col - W @ coef) / max(np.linalg.norm(col), 1e-300)
        if resid < _DEPENDENT_TOL:
            coef = coef.ravel()
            coef[np.abs(coef) < 1e-9 * max(1.0, np.abs(coef).max())] = 0.0
            rows = np.flatnonzero(coef)
            P_col = np.zeros(P.shape[0])
            P_col[rows] = coef[rows]
            P[:, 10 * n + e] = P_col
            targets = []
            for r in rows:
                if r < nb:
                    c = coef[r]
                    term = extra_names[e] if abs(c - 1) < 1e-12 else f"{c:.6g}*{extra_names[e]}"
                    expressions[r] += f" + {term}"
                    targets.append(base.names[r])
                else:
                    targets.append(extra_names[kept_extra[r - nb]])
            notes.append(
                f"the {kind} column of joint {j + 1} ({extra_names[e]}) duplicates the column of "
                f"{', '.join(targets)}; {extra_names[e]} is identified inside {', '.join(targets)} "
                "instead of alone"
            )
            continue
        kept_cols.append(col)
        kept_extra.append(int(e))
        row = np.zeros((1, 14 * n))
        row[0, 10 * n + e] = 1.0
        P = np.vstack([P, row])
        expressions.append(extra_names[e])
    extras = np.array(kept_extra, dtype=np.intp)
    pattern_x = np.zeros((n, len(extras)), dtype=bool)
    pattern_x[extras % n, np.arange(len(extras))] = True
    link_of = (base.independent // 10 + 1).astype(np.intp)
    return ColumnSet(
        robot=robot,
        base=base,
        friction=bool(friction),
        armature=bool(armature),
        names=tuple(base.names) + tuple(extra_names[e] for e in extras),
        kinds=("link",) * nb + tuple(EXTRA_KINDS[e // n] for e in extras),
        expressions=tuple(expressions),
        joints=np.concatenate([link_of, extras % n + 1]).astype(np.intp),
        extras=extras,
        P=P,
        pattern=np.hstack([pattern_b, pattern_x]),
        notes=tuple(notes),
    )


def linear_torque(
    columns: ColumnSet,
    x: ArrayLike,
    q: ArrayLike,
    dq: ArrayLike,
    ddq: ArrayLike,
    *,
    mask: NDArray[np.bool_] | None = None,
) -> NDArray[np.float64]:
    """Torque of the linear model ``W(q, dq, ddq) x`` for a batch, through the compiled regressor.

    Parameters
    ----------
    columns : ColumnSet
        The identified parameters.
    x : array_like, shape (p,)
        Their values.
    q, dq, ddq : array_like, shape (m, n)
        States (rad, rad/s, rad/s^2).
    mask : ndarray of bool, shape (p,), optional
        Use only these parameters (e.g. ``columns.link_mask``: the rigid-body part).

    Returns
    -------
    ndarray, shape (m, n)
        Joint torques (N m).
    """
    robot = columns.robot
    q, dq, ddq = (robot.check_state(label, v) for label, v in (("q", q), ("dq", dq), ("ddq", ddq)))
    for label, v in (("q", q), ("dq", dq), ("ddq", ddq)):
        if not np.all(np.isfinite(v)):
            row = int(np.argmax(~np.all(np.isfinite(v), axis=1)))
            raise DataError(
                f"{label} holds a non-finite value at row {row}; give finite states (drop or interpolate that row)"
            )
    if not (q.shape == dq.shape == ddq.shape):
        raise ShapeError(
            f"q, dq and ddq have shapes {q.shape}, {dq.shape}, {ddq.shape}; give three (m, n) arrays of one shape"
        )
    x = np.asarray(x, dtype=np.float64)
    if mask is not None:
        x = np.where(mask, x, 0.0)
    nb = columns.n_base
    m = len(q)
    out = np.zeros((m, robot.n))
    xb = x[:nb]
    for a in range(0, m, _CHUNK):
        s = slice(a, min(a + _CHUNK, m))
        out[s] = compiled_base_regressor(robot, q[s], dq[s], ddq[s]) @ xb
    if len(columns.extras):
        xe = x[nb:]
        used = xe != 0
        if used.any():
            E = columns.extra_columns(dq, ddq)
            for k in np.flatnonzero(used):
                out[:, columns.extra_joint[k]] += E[:, k] * xe[k]
    return out


# ---------------------------------------------------------------------------- the compressed system
@dataclass(frozen=True, eq=False)
class WeightedSolution:
    """Least squares of the whitened system: ``min || L^-1 (tau - W x) ||^2`` over all samples.

    Attributes
    ----------
    x : ndarray, shape (p,)
        Estimate.
    R : ndarray, shape (p, p)
        Upper-triangular factor of the whitened stacked regressor.
    rhs : ndarray, shape (p,)
        ``Q^T`` times the whitened torque: ``|| W~ x - y~ ||^2 = || R x - rhs ||^2 + rss``.
    rss : float
        Whitened residual sum of squares at ``x``.
    whitener : ndarray, shape (n, n)
        ``L^-1`` used.
    """

    x: NDArray[np.float64]
    R: NDArray[np.float64]
    rhs: NDArray[np.float64]
    rss: float
    whitener: NDArray[np.float64]


@dataclass(eq=False)
class LinearSystem:
    """The stacked identification system of one dataset, compressed (see the module docstring).

    Build it with :func:`build_system`; every estimator of :mod:`dynid.identify.estimators` can fit
    it (so several methods share one pass over the data).

    Attributes
    ----------
    columns : ColumnSet
        The identified parameters.
    prepared : Prepared
        States, kept rows and filter.
    R_Z : ndarray, shape (c, c)
        R factor of the data matrix ``Z`` (regressor entries and torques) over the kept rows.
    z_joint : ndarray of int, shape (c,)
        Joint row (0-based) of each column of ``Z``.
    z_param : ndarray of int, shape (c,)
        Identified parameter of each column of ``Z``; -1 for the torque columns.
    Z : ndarray, shape (M, c) or None
        The (filtered) data matrix at full rate, kept until :meth:`release` for per-sample residuals.
    """

    columns: ColumnSet
    prepared: Prepared
    R_Z: NDArray[np.float64]
    z_joint: NDArray[np.intp]
    z_param: NDArray[np.intp]
    Z: NDArray[np.float64] | None = field(default=None, repr=False)

    @property
    def m(self) -> int:
        """Samples (kept rows)."""
        return self.prepared.m

    @property
    def n(self) -> int:
        """Joints."""
        return self.columns.n

    @property
    def p(self) -> int:
        """Identified parameters."""
        return self.columns.p

    def release(self) -> None:
        """Drop the full data matrix (the compressed factor stays; per-sample methods stop working)."""
        self.Z = None

    # -------------------------------------------------------------- weighted solves
    def _maps(self, whitener: NDArray[np.float64]) -> NDArray[np.float64]:
        """The stacked small matrix ``[R_Z T_1; ...; R_Z T_n]``, shape (n c, p + 1)."""
        c, n, p = len(self.z_joint), self.n, self.p
        out = np.empty((n * c, p + 1))
        reg = self.z_param >= 0
        for i in range(n):
            T = np.zeros((c, p + 1))
            T[np.flatnonzero(reg), self.z_param[reg]] = whitener[i, self.z_joint[reg]]
            T[np.flatnonzero(~reg), p] = whitener[i, self.z_joint[~reg]]
            out[i * c : (i + 1) * c] = self.R_Z @ T
        return out

    def whitened(
        self, whitener: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
        """R factor of the whitened system: ``(R (p, p), rhs (p,), rss)`` with rss the minimal residual.

        Parameters
        ----------
        whitener : ndarray, shape (n, n)
            ``L^-1`` with ``Omega = L L^T`` the joint-noise covariance (identity for OLS).
        """
        p = self.p
        R_aug = scipy.linalg.qr(self._maps(whitener), mode="r", check_finite=False)[0][: p + 1]
        if R_aug.shape[0] < p + 1:  # fewer stacked rows than columns (tiny data): pad
            R_aug = np.vstack([R_aug, np.zeros((p + 1 - R_aug.shape[0], p + 1))])
        return R_aug[:p, :p], R_aug[:p, p], float(R_aug[p, p] ** 2)

    def _model_map(self, x: NDArray[np.float64], mask: NDArray[np.bool_] | None) -> NDArray[np.float64]:
        """(c, n): the data matrix's columns to the model torque ``W x`` per joint (torque columns 0)."""
        xm = x if mask is None else np.where(mask, x, 0.0)
        reg = np.flatnonzero(self.z_param >= 0)
        C = np.zeros((len(self.z_joint), self.n))
        C[reg, self.z_joint[reg]] = xm[self.z_param[reg]]
        return C

    def residual_matrix(
        self, x: NDArray[np.float64], mask: NDArray[np.bool_] | None = None
    ) -> NDArray[np.float64]:
        """``E^T E`` (n x n) of the residuals ``E = tau - W x`` over the kept rows (N^2 m^2).

        Parameters
        ----------
        x : ndarray, shape (p,)
            Parameters.
        mask : ndarray of bool, shape (p,), optional
            Use only these parameters in the model.
        """
        C = -self._model_map(x, mask)  # the residual tau - W x: minus the model ...
        tau = np.flatnonzero(self.z_param < 0)
        C[tau, self.z_joint[tau]] = 1.0  # ... plus each joint's torque column
        G = self.R_Z @ C
        return G.T @ G

    def rms(self, x: NDArray[np.float64], mask: NDArray[np.bool_] | None = None) -> NDArray[np.float64]:
        """Residual RMS per joint (N m) over the kept rows.

        Parameters
        ----------
        x : ndarray, shape (p,)
            Parameters.
        mask : ndarray of bool, shape (p,), optional
            Use only these parameters in the model.
        """
        return np.sqrt(np.maximum(np.diag(self.residual_matrix(x, mask)), 0.0) / self.m)

    # -------------------------------------------------------------- per-sample values
    def _need_Z(self) -> NDArray[np.float64]:
        if self.Z is None:
            raise IdentificationError(
                "the data matrix of this system was released; per-sample values need it: build the system "
                "again with build_system(...) or call this before release()"
            )
        return self.Z

    def tau(self) -> NDArray[np.float64]:
        """Torque at the kept rows, treated like the regressor (filtered with parallel filtering): (m, n)."""
        Z = self._need_Z()
        cols = np.flatnonzero(self.z_param < 0)
        order = np.argsort(self.z_joint[cols])
        return Z[self.prepared.rows][:, cols[order]]

    def predict(self, x: NDArray[np.float64], mask: NDArray[np.bool_] | None = None) -> NDArray[np.float64]:
        """``W x`` at the kept rows (N m), (m, n), with the regressor treated like the torque.

        Parameters
        ----------
        x : ndarray, shape (p,)
            Parameters.
        mask : ndarray of bool, shape (p,), optional
            Use only these parameters.
        """
        Z = self._need_Z()
        C = self._model_map(x, mask)
        rows = self.prepared.rows
        out = np.empty((len(rows), self.n))
        for a in range(0, len(rows), _CHUNK):
            out[a : a + _CHUNK] = Z[rows[a : a + _CHUNK]] @ C
        return out


def _fill_Z(columns: ColumnSet, prepared: Prepared, z_cols: list[tuple[int, int]]) -> NDArray[np.float64]:
    """The data matrix at full rate, (M, c): regressor entries (joint, parameter) then torques."""
    robot, nb, n = columns.robot, columns.n_base, columns.n
    M = len(prepared.t)
    c = len(z_cols) + n
    Z = np.empty((M, c))
    link = [(k, j * nb + pi) for k, (j, pi) in enumerate(z_cols) if pi < nb]
    link_z = np.array([k for k, _ in link], dtype=np.intp)
    link_flat = np.array([f for _, f in link], dtype=np.intp)
    extra = [(k, pi - nb) for k, (_, pi) in enumerate(z_cols) if pi >= nb]
    for a in range(0, M, _CHUNK):
        s = slice(a, min(a + _CHUNK, M))
        Yb = compiled_base_regressor(robot, prepared.q[s], prepared.dq[s], prepared.ddq[s])
        Z[s, link_z] = Yb.reshape(Yb.shape[0], -1)[:, link_flat]
    if extra:
        E = columns.extra_columns(prepared.dq, prepared.ddq)
        for k, e in extra:
            Z[:, k] = E[:, e]
    Z[:, len(z_cols) :] = prepared.tau
    return Z


def _filter_in_place(Z: NDArray[np.float64], prepared: Prepared) -> None:
    """Low-pass every column of Z in place with the torque's filter, run by run."""
    sos = prepared.sos
    if sos is None:
        return
    pad = 3 * (2 * len(sos) + 1)
    for r, run in enumerate(prepared.runs):
        if run.stop - run.start <= pad:
            raise DataError(
                f"run {r} has {run.stop - run.start} samples, too short for an order-{2 * len(sos)} zero-phase "
                f"filter (needs more than {pad}); drop that run or record longer"
            )
        for a in range(0, Z.shape[1], _FILTER_COLUMNS):
            cols = slice(a, min(a + _FILTER_COLUMNS, Z.shape[1]))
            Z[run, cols] = sosfiltfilt(sos, Z[run, cols], axis=0)


def _qr_rows(Z: NDArray[np.float64], rows: NDArray[np.intp]) -> NDArray[np.float64]:
    """R factor (c x c) of ``Z[rows]`` by blocked Householder QR (one block in memory at a time)."""
    c = Z.shape[1]
    R = np.zeros((0, c))
    for a in range(0, len(rows), _CHUNK):
        block = np.vstack([R, Z[rows[a : a + _CHUNK]]])
        R = scipy.linalg.qr(block, mode="r", overwrite_a=True, check_finite=False)[0][:c]
    if R.shape[0] < c:
        R = np.vstack([R, np.zeros((c - R.shape[0], c))])
    return R


def build_system(
    robot,
    data: Dataset,
    *,
    preprocessing: Preprocessing | None = None,
    friction: bool = True,
    armature: bool = True,
    keep_samples: bool = True,
) -> LinearSystem:
    """Build the compressed identification system of a dataset (the one expensive pass over the data).

    Parameters
    ----------
    robot : RobotModel
        The robot that recorded the data.
    data : Dataset
        ``t``, ``q``, ``tau`` and optionally ``dq``, ``ddq``.
    preprocessing : Preprocessing, optional
        Filtering, differentiation, trimming, decimation (default :class:`Preprocessing`).
    friction : bool
        Identify linear friction with the link parameters.
    armature : bool
        Identify the armature with the link parameters.
    keep_samples : bool
        Keep the filtered data matrix for per-sample residuals (layers 2 and 3 need them); False frees
        it at once.

    Returns
    -------
    LinearSystem

    Raises
    ------
    IdentificationError
        Fewer equations than parameters.
    DataError
        Malformed data, wrong joint count, bad filter settings.
    """
    prepared = prepare(data, preprocessing, n_joints=robot.n)
    columns = column_set(robot, friction=friction, armature=armature)
    n, p = robot.n, columns.p
    m = prepared.m
    if m * n <= p or m < 2:
        raise IdentificationError(
            f"the data give {m} samples ({m * n} equations) after preprocessing for {p} parameters; "
            f"record more than {p // n + 1} samples (in practice at least {10 * p // n}), or trim/decimate less"
        )
    z_cols = [(j, k) for k in range(p) for j in range(n) if columns.pattern[j, k]]
    Z = _fill_Z(columns, prepared, z_cols)
    _filter_in_place(Z, prepared)
    with single_blas_thread():
        R_Z = _qr_rows(Z, prepared.rows)
    z_joint = np.array([j for j, _ in z_cols] + list(range(n)), dtype=np.intp)
    z_param = np.array([k for _, k in z_cols] + [-1] * n, dtype=np.intp)
    return LinearSystem(
        columns=columns,
        prepared=prepared,
        R_Z=R_Z,
        z_joint=z_joint,
        z_param=z_param,
        Z=Z if keep_samples else None,
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


def describe_joints(joints: Sequence[int]) -> str:
    """'joint 6' or 'joints 5 and 6'."""
    js = [str(j) for j in joints]
    if len(js) == 1:
        return f"joint {js[0]}"
    return "joints " + ", ".join(js[:-1]) + " and " + js[-1]
