"""Measured (or simulated) robot data: the :class:`Dataset` type and its files.

A dataset holds, for ``m`` time stamps and ``n`` joints, the time ``t`` (s), the joint angles ``q`` (rad),
the joint torques ``tau`` (N m) and optionally the joint velocities ``dq`` (rad/s) and accelerations
``ddq`` (rad/s^2).  It checks itself when made: finite values, strictly increasing time, consistent shapes,
and (optionally) the joint count of a robot.

Several recordings can be joined with :meth:`Dataset.concat`; the join records where each run starts
(``meta["run_starts"]``) so that filtering and differentiation never cross from one run into the next.

Files follow the contract of the README: a CSV file whose header names the columns ``t``, ``q_1..q_n``,
``tau_1..tau_n`` and optionally ``dq_1..dq_n``, ``ddq_1..ddq_n`` (joints numbered from 1 in the model's
joint order), or an ``.npz`` archive with the same names.  :func:`save_dataset` writes a temporary file
in the target folder and renames it, so a file is either complete or absent.

:func:`load_dataset` is the one reader every command uses, and it applies one rule to every file: it
reads the file as it is or refuses it with a :class:`DataError` of one sentence (what was expected, what
came, the fix).  The single exception is a sample logged twice (a row identical to the row before it,
time stamp included): it is dropped with a :class:`DataWarning`.  Nothing is ever sorted: time that
repeats with other values or steps backwards is refused, naming the rows.  In detail:

* encoding: UTF-8 text (a byte-order mark is skipped); a binary file is refused;
* separator: commas (a file separated by semicolons, tabs or spaces is refused, naming the separator);
* values: numbers, finite (the first bad cell is named by column and row);
* time: seconds, strictly increasing; a median step of :data:`MAX_TIME_STEP` (1 s) or more is refused
  as time in milliseconds or finer units;
* magnitudes: ``|q|`` above :data:`DEGREES_THRESHOLD` (10 rad) is refused as degrees unless
  ``degrees=True`` converts ``q``, ``dq`` and ``ddq`` to radians; ``|tau|``, ``|dq|``, ``|ddq|`` above
  :data:`MAX_MAGNITUDE` (no robot arm reaches them) are refused as wrong units or corrupt cells;
  given the robot (``robot=``), a torque above :data:`TORQUE_RATIO` times what the robot's own model
  can produce within its limits is refused too (:func:`check_torque_scale`).

A :class:`Dataset` built from arrays checks structure only (shapes, finite values, increasing time) and
warns about angles that look like degrees, so that arrays in any test units can still be built.
"""

from __future__ import annotations

import io
import itertools
import json
import os
import re
import warnings
import zipfile
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import KW_ONLY, InitVar, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynid._io import atomic_path, dumps_json
from dynid.exceptions import DataError, DataWarning

__all__ = [
    "DEGREES_THRESHOLD",
    "MAX_MAGNITUDE",
    "MAX_TIME_STEP",
    "TORQUE_RATIO",
    "DataWarning",
    "Dataset",
    "check_torque_scale",
    "load_dataset",
    "save_dataset",
]

#: An angle larger than this (rad) in magnitude makes :class:`Dataset` warn that the angles look like degrees.
DEGREES_THRESHOLD = 10.0

#: A median time step (s) at or above this makes :func:`load_dataset` refuse the time column as not in seconds.
MAX_TIME_STEP = 1.0

#: Largest magnitude :func:`load_dataset` accepts per signal: torque (N m), velocity (rad/s), acceleration
#: (rad/s^2).  No robot arm joint reaches them; a value beyond is a unit or export error.
MAX_MAGNITUDE: dict[str, float] = {"tau": 1e6, "dq": 1e3, "ddq": 1e6}

#: A measured torque above this many times the robot's own torque scale (see :func:`check_torque_scale`)
#: is refused as a unit error (mN m, raw motor current) or a dataset of another robot.
TORQUE_RATIO = 20.0

_SIGNALS = ("q", "tau", "dq", "ddq")
_OPTIONAL = ("dq", "ddq")
_CONTRACT = "a dataset needs t, q_1..q_n and tau_1..tau_n (see 'Dataset files' in the README)"
_COLUMN = re.compile(r"^(q|tau|dq|ddq)_([0-9]+)$")
_UNIFORM_RTOL = 1e-6


def _describe(x: float) -> str:
    """Short text for a number in a message (``nan``, ``inf``, or 6 significant digits)."""
    return f"{x:.6g}"


def _as_float(name: str, value: ArrayLike) -> NDArray[np.float64]:
    """Own float64 copy of ``value``; a :class:`DataError` when it cannot be read as numbers."""
    try:
        return np.array(value, dtype=np.float64, copy=True)
    except (TypeError, ValueError) as err:
        raise DataError(f"{name} could not be read as numbers ({err}); give an array of floats") from None


def _first_bad(name: str, a: NDArray[np.float64], t: NDArray[np.float64]) -> str | None:
    """Message naming the first non-finite entry of ``a`` (column and row), or None when all are finite."""
    bad = ~np.isfinite(a)
    if not bad.any():
        return None
    rows = bad.reshape(len(a), -1).any(axis=1)
    row = int(np.argmax(rows))
    n_rows = int(rows.sum())
    if a.ndim == 1:
        column, value = name, float(a[row])
    else:
        j = int(np.argmax(bad[row]))
        column, value = f"{name}_{j + 1}", float(a[row, j])
    details = [] if name == "t" or not np.isfinite(t[row]) else [f"t = {t[row]:.6g} s"]
    details.append(f"{n_rows} bad row{'s' if n_rows > 1 else ''} in all")
    return (
        f"{column} is {_describe(value)} at row {row} ({'; '.join(details)}); "
        "a dataset must hold finite numbers: drop or interpolate the bad rows"
    )


def _run_starts_from_meta(meta: Mapping[str, Any], m: int) -> tuple[int, ...]:
    """Validated run start indices from ``meta["run_starts"]`` (``(0,)`` when absent)."""
    raw = meta.get("run_starts")
    if raw is None:
        return (0,)
    try:
        starts = tuple(int(s) for s in raw)
    except (TypeError, ValueError):
        raise DataError(
            f"meta['run_starts'] must be a list of row indices; got {raw!r}; "
            "leave it to Dataset.concat or give sorted integers starting at 0"
        ) from None
    increasing = all(b > a for a, b in itertools.pairwise(starts))
    if not starts or starts[0] != 0 or not increasing or starts[-1] >= m:
        raise DataError(
            f"meta['run_starts'] must be strictly increasing row indices from 0 to below m = {m}; got "
            f"{list(starts)}; leave it to Dataset.concat or fix the indices"
        )
    return starts


@dataclass(frozen=True, eq=False, repr=False)
class Dataset:
    """Time, joint angles and joint torques of one robot, with optional velocities and accelerations.

    Parameters
    ----------
    t : array_like, shape (m,)
        Time stamps (s), finite and strictly increasing.
    q : array_like, shape (m, n)
        Joint angles (rad; m for a prismatic joint).  A 1-D array is read as one joint.
    tau : array_like, shape (m, n)
        Joint torques (N m; N for a prismatic joint).
    dq : array_like, shape (m, n), optional
        Joint velocities (rad/s).
    ddq : array_like, shape (m, n), optional
        Joint accelerations (rad/s^2).
    meta : dict, optional
        Free-form description (source, units, processing done).  Keys used by dynid: ``run_starts``
        (row index where each run starts, written by :meth:`concat`), ``reference`` (how the torque was
        treated: ``"raw"``, ``"filtered and trimmed"``, ...), ``preprocess`` (the settings used).
    n_joints : int, optional
        Joint count of the robot; when given, the data must have that many columns.
    robot_name : str, optional
        Name of that robot, used in messages only.

    Raises
    ------
    DataError
        Non-finite values (the message names the column and the first bad row), time not strictly
        increasing, inconsistent shapes, fewer than 2 samples, or a joint count other than ``n_joints``.

    Warns
    -----
    DataWarning
        When some ``|q|`` exceeds :data:`DEGREES_THRESHOLD` (10 rad): the angles look like degrees.

    Notes
    -----
    The arrays are float64 copies marked read-only; use :func:`dataclasses.replace` to derive a new
    dataset.  Equality is identity (comparing arrays elementwise has no single truth value).

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(5) * 0.01
    >>> ds = Dataset(t, np.zeros((5, 2)), np.ones((5, 2)))
    >>> ds.m, ds.n, round(ds.dt, 3), ds.is_uniform
    (5, 2, 0.01, True)
    """

    t: NDArray[np.float64]
    q: NDArray[np.float64]
    tau: NDArray[np.float64]
    _: KW_ONLY
    dq: NDArray[np.float64] | None = None
    ddq: NDArray[np.float64] | None = None
    meta: dict[str, Any] = field(default_factory=dict)
    n_joints: InitVar[int | None] = None
    robot_name: InitVar[str | None] = None

    def __post_init__(self, n_joints: int | None, robot_name: str | None) -> None:
        t = _as_float("t", self.t)
        if t.ndim != 1:
            raise DataError(f"t must be a 1-D array of m time stamps (s); got shape {t.shape}; flatten it")
        m = len(t)
        if m < 2:
            raise DataError(f"a dataset needs at least 2 samples; got {m}; record or keep a longer window")
        arrays: dict[str, NDArray[np.float64] | None] = {}
        for name in _SIGNALS:
            value = getattr(self, name)
            if value is None:
                arrays[name] = None
                continue
            a = _as_float(name, value)
            if a.ndim == 1:
                a = a.reshape(-1, 1)
            if a.ndim != 2:
                raise DataError(
                    f"{name} must have shape (m, n) = ({m}, n); got shape {a.shape}; "
                    "give one row per time stamp"
                )
            if a.shape[0] != m:
                raise DataError(
                    f"{name} has {a.shape[0]} rows but t has {m}; every signal needs one row per time stamp"
                )
            arrays[name] = a
        n = arrays["q"].shape[1]  # type: ignore[union-attr]
        for name in ("tau", "dq", "ddq"):
            a = arrays[name]
            if a is not None and a.shape[1] != n:
                raise DataError(
                    f"{name} has {a.shape[1]} columns but q has {n}; every signal needs one column per joint"
                )
        for name, a in (("t", t), *arrays.items()):
            if a is not None and (msg := _first_bad(name, a, t)) is not None:
                raise DataError(msg)
        steps = np.diff(t)
        if not (steps > 0).all():
            bad_rows = np.flatnonzero(steps <= 0) + 1
            k = int(bad_rows[0]) - 1
            listed = ", ".join(str(r) for r in bad_rows[:5]) + (", ..." if len(bad_rows) > 5 else "")
            raise DataError(
                f"t must increase strictly, but t[{k + 1}] = {t[k + 1]:.9g} s is not after "
                f"t[{k}] = {t[k]:.9g} s (rows repeating or going back in time: {listed}, {len(bad_rows)} in all); "
                "sort the rows by time and drop repeated stamps "
                "(preprocess.resample_uniform does both)"
            )
        meta = dict(self.meta) if self.meta is not None else {}
        _run_starts_from_meta(meta, m)

        for a in (t, *arrays.values()):
            if a is not None:
                a.setflags(write=False)
        object.__setattr__(self, "t", t)
        for name, a in arrays.items():
            object.__setattr__(self, name, a)
        object.__setattr__(self, "meta", meta)

        if n_joints is not None:
            self.check_joints(n_joints, robot_name)
        peak = np.abs(self.q).max(axis=0)
        if peak.max() > DEGREES_THRESHOLD:
            j = int(np.argmax(peak))
            warnings.warn(
                f"q_{j + 1} reaches {peak[j]:.4g}, more than {DEGREES_THRESHOLD:g} rad; the angles look like "
                "degrees: convert them with np.deg2rad",
                DataWarning,
                stacklevel=3,
            )

    # ------------------------------------------------------------------ sizes and time
    @property
    def m(self) -> int:
        """Number of samples (rows)."""
        return len(self.t)

    @property
    def n(self) -> int:
        """Number of joints (columns of ``q``)."""
        return int(self.q.shape[1])

    @property
    def runs(self) -> list[slice]:
        """Row ranges of the runs (one slice per run; a single run when the data were never joined)."""
        starts = _run_starts_from_meta(self.meta, self.m)
        stops = (*starts[1:], self.m)
        return [slice(a, b) for a, b in zip(starts, stops, strict=True)]

    def _within_run_steps(self) -> NDArray[np.float64]:
        """Time steps (s) between consecutive samples of the same run."""
        steps = np.diff(self.t)
        starts = _run_starts_from_meta(self.meta, self.m)
        if len(starts) > 1:
            keep = np.ones(len(steps), dtype=bool)
            keep[np.asarray(starts[1:]) - 1] = False  # the step into a new run is not a sampling step
            if keep.any():
                steps = steps[keep]
        return steps

    @property
    def dt(self) -> float:
        """Median time step (s) within runs."""
        return float(np.median(self._within_run_steps()))

    @property
    def is_uniform(self) -> bool:
        """Whether every step within a run equals :attr:`dt` to a relative 1e-6."""
        steps = self._within_run_steps()
        return bool(np.all(np.abs(steps - self.dt) <= _UNIFORM_RTOL * self.dt))

    @property
    def duration(self) -> float:
        """Time (s) from the first to the last sample."""
        return float(self.t[-1] - self.t[0])

    @property
    def columns(self) -> list[str]:
        """File column names in file order: ``t``, ``q_i``, ``tau_i``, then ``dq_i``, ``ddq_i`` if present."""
        names = ["t"]
        for name in _SIGNALS:
            if getattr(self, name) is not None:
                names += [f"{name}_{j + 1}" for j in range(self.n)]
        return names

    def __repr__(self) -> str:
        extra = [name for name in _OPTIONAL if getattr(self, name) is not None]
        runs = len(self.runs)
        return (
            f"Dataset(m={self.m}, n={self.n}, t={self.t[0]:.6g}..{self.t[-1]:.6g} s, dt={self.dt:.6g} s"
            f"{'' if self.is_uniform else ' (irregular)'}, signals=q,tau{''.join(',' + e for e in extra)}"
            f"{f', runs={runs}' if runs > 1 else ''})"
        )

    # ------------------------------------------------------------------ checks
    def check_joints(self, n_joints: int, robot_name: str | None = None) -> Dataset:
        """Check that the data have one column per joint of a robot.

        Parameters
        ----------
        n_joints : int
            Joint count of the robot.
        robot_name : str, optional
            Name of the robot, used in the message.

        Returns
        -------
        Dataset
            ``self``, so that calls chain.

        Raises
        ------
        DataError
            E.g. "q has 7 columns; the robot 'ur5' has 6 joints: ...".
        """
        if self.n != int(n_joints):
            robot = f"the robot '{robot_name}'" if robot_name else "the robot"
            raise DataError(
                f"q has {self.n} column{'s' if self.n != 1 else ''}; {robot} has {int(n_joints)} joints: "
                "use the data recorded on that robot, or the model of the robot that recorded them"
            )
        return self

    # ------------------------------------------------------------------ selection and joining
    def select_rows(self, rows: ArrayLike) -> Dataset:
        """Keep the given rows (a sorted selection); run boundaries follow the rows kept.

        Parameters
        ----------
        rows : array_like of int, shape (k,)
            Strictly increasing row indices, ``0 <= rows < m``, ``k >= 2``.

        Returns
        -------
        Dataset
            The selected samples with their original time stamps; ``meta["run_starts"]`` updated.
        """
        idx = np.asarray(rows, dtype=np.intp).ravel()
        if len(idx) < 2:
            raise DataError(
                f"a dataset needs at least 2 samples; the selection keeps {len(idx)}; keep more rows"
            )
        if idx[0] < 0 or idx[-1] >= self.m or np.any(np.diff(idx) <= 0):
            raise DataError(
                f"rows must be strictly increasing indices in 0..{self.m - 1}; got {idx[:5].tolist()}...; "
                "sort them and drop duplicates"
            )
        starts = []
        for run in self.runs:
            k = int(np.searchsorted(idx, run.start))
            if k < len(idx) and idx[k] < run.stop:
                starts.append(k)
        meta = {key: value for key, value in self.meta.items() if key != "run_starts"}
        if len(starts) > 1:
            meta["run_starts"] = starts
        return self._derive(
            t=self.t[idx],
            **{name: None if getattr(self, name) is None else getattr(self, name)[idx] for name in _SIGNALS},
            meta=meta,
        )

    def slice_time(self, t0: float, t1: float) -> Dataset:
        """Samples with ``t0 <= t <= t1`` (s), time stamps unchanged.

        Parameters
        ----------
        t0, t1 : float
            Window bounds (s), ``t0 < t1``.

        Returns
        -------
        Dataset
            The samples inside the window (at least 2).
        """
        if not t1 > t0:
            raise DataError(f"slice_time needs t0 < t1; got t0 = {t0:g} s, t1 = {t1:g} s; swap or widen them")
        i0 = int(np.searchsorted(self.t, t0, side="left"))
        i1 = int(np.searchsorted(self.t, t1, side="right"))
        if i1 - i0 < 2:
            raise DataError(
                f"slice_time({t0:g}, {t1:g}) keeps {max(i1 - i0, 0)} sample(s) of a dataset spanning "
                f"{self.t[0]:.6g}..{self.t[-1]:.6g} s; choose a window inside it"
            )
        return self.select_rows(np.arange(i0, i1))

    @classmethod
    def concat(cls, datasets: Iterable[Dataset]) -> Dataset:
        """Join runs one after the other.

        Time is re-stamped so that each run starts one step (its predecessor's :attr:`dt`) after the end of
        the previous run; the first run keeps its stamps.  ``meta["run_starts"]`` records where each run
        (including runs inside the parts) begins, so that filtering never crosses a boundary.

        Parameters
        ----------
        datasets : iterable of Dataset
            Runs with the same joint count and the same optional signals (``dq``, ``ddq``).

        Returns
        -------
        Dataset
            The joined data.  Its ``meta`` keeps the keys whose values agree across the parts and lists each
            part's own ``meta`` under ``"parts"``.
        """
        parts = list(datasets)
        if not parts:
            raise DataError("Dataset.concat needs at least one dataset; got none; pass a list of datasets")
        first = parts[0]
        for k, part in enumerate(parts[1:], start=1):
            if not isinstance(part, Dataset):
                raise DataError(f"Dataset.concat takes Datasets; item {k} is a {type(part).__name__}")
            if part.n != first.n:
                raise DataError(
                    f"dataset {k} has {part.n} joints but dataset 0 has {first.n}; "
                    "join runs of the same robot"
                )
            for name in _OPTIONAL:
                if (getattr(part, name) is None) != (getattr(first, name) is None):
                    has, lacks = (0, k) if getattr(part, name) is None else (k, 0)
                    raise DataError(
                        f"dataset {has} has {name} but dataset {lacks} has not; join datasets with the same "
                        f"signals (drop it with dataclasses.replace(ds, {name}=None))"
                    )
        times, starts, offset_rows = [], [], 0
        t_next = float(first.t[0])
        for part in parts:
            times.append(part.t - part.t[0] + t_next)
            t_next = float(times[-1][-1]) + part.dt
            starts += [s.start + offset_rows for s in part.runs]
            offset_rows += part.m
        metas = [{key: value for key, value in p.meta.items() if key != "run_starts"} for p in parts]
        common = {}
        for key, value in metas[0].items():
            try:
                same = all(key in other and bool(other[key] == value) for other in metas[1:])
            except (TypeError, ValueError):
                same = False
            if same:
                common[key] = value
        meta: dict[str, Any] = {**common, "parts": metas}
        if len(starts) > 1:
            meta["run_starts"] = starts
        return cls(
            np.concatenate(times),
            np.concatenate([p.q for p in parts]),
            np.concatenate([p.tau for p in parts]),
            dq=None if first.dq is None else np.concatenate([p.dq for p in parts]),  # type: ignore[misc]
            ddq=None if first.ddq is None else np.concatenate([p.ddq for p in parts]),  # type: ignore[misc]
            meta=meta,
        )

    def _derive(self, **changes: Any) -> Dataset:
        """New dataset with some fields replaced (no degrees warning repeated: the check already ran)."""
        fields = {name: getattr(self, name) for name in ("t", *_SIGNALS, "meta")}
        fields.update(changes)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DataWarning)
            return Dataset(
                fields["t"],
                fields["q"],
                fields["tau"],
                dq=fields["dq"],
                ddq=fields["ddq"],
                meta=fields["meta"],
            )

    # ------------------------------------------------------------------ columns
    def to_columns(self) -> dict[str, NDArray[np.float64]]:
        """Columns by file name (``t``, ``q_1``, ..., ``tau_n``, ...), each a view of shape (m,)."""
        cols = {"t": self.t}
        for name in _SIGNALS:
            a = getattr(self, name)
            if a is not None:
                cols.update({f"{name}_{j + 1}": a[:, j] for j in range(self.n)})
        return cols

    @classmethod
    def from_columns(
        cls,
        columns: Mapping[str, ArrayLike],
        *,
        n_joints: int | None = None,
        robot_name: str | None = None,
        source: str = "the data",
        meta: Mapping[str, Any] | None = None,
    ) -> Dataset:
        """Dataset from columns named as in a dataset file.

        Parameters
        ----------
        columns : mapping of str to array_like of shape (m,)
            ``t``, ``q_1..q_n``, ``tau_1..tau_n`` and optionally all of ``dq_1..dq_n`` and ``ddq_1..ddq_n``.
            Other names are ignored and listed in ``meta["ignored_columns"]``.
        n_joints : int, optional
            Expected joint count.
        robot_name : str, optional
            Robot name for messages.
        source : str
            What the columns came from (a file name), used in messages.
        meta : mapping, optional
            Initial ``meta``.

        Returns
        -------
        Dataset
        """
        numbered: dict[str, dict[int, str]] = {name: {} for name in _SIGNALS}
        ignored = []
        for key in columns:
            match = _COLUMN.match(key)
            if match is None or int(match.group(2)) < 1:
                if key != "t":
                    ignored.append(key)
                continue
            numbered[match.group(1)][int(match.group(2))] = key
        if "t" not in columns:
            raise DataError(f"{source} has no column 't'; {_CONTRACT}")
        n = max(numbered["q"], default=0)
        if n == 0:
            raise DataError(f"{source} has no column 'q_1'; {_CONTRACT}")
        for name in _SIGNALS:
            present = numbered[name]
            if name in _OPTIONAL and not present:
                continue
            for j in range(1, n + 1):
                if j not in present:
                    hint = _CONTRACT if name in ("q", "tau") else f"give all of {name}_1..{name}_{n} or none"
                    raise DataError(f"{source} has no column '{name}_{j}'; {hint}")
            extra = sorted(j for j in present if j > n)
            if extra:
                raise DataError(
                    f"{source} has column '{name}_{extra[0]}' but only {n} joint angle columns q_1..q_{n}; "
                    f"{_CONTRACT}"
                )

        t = _as_float("t", columns["t"]).ravel()

        def stack(name: str) -> NDArray[np.float64] | None:
            if not numbered[name]:
                return None
            cols = []
            for j in range(1, n + 1):
                col = _as_float(f"{name}_{j}", columns[numbered[name][j]]).ravel()
                if len(col) != len(t):
                    raise DataError(
                        f"{source}: column '{name}_{j}' has {len(col)} values but t has {len(t)}; "
                        "give every column one value per time stamp"
                    )
                cols.append(col)
            return np.column_stack(cols)

        full_meta = dict(meta or {})
        if ignored:
            full_meta["ignored_columns"] = ignored
        try:
            return cls(
                t,
                stack("q"),  # type: ignore[arg-type]
                stack("tau"),  # type: ignore[arg-type]
                dq=stack("dq"),
                ddq=stack("ddq"),
                meta=full_meta,
                n_joints=n_joints,
                robot_name=robot_name,
            )
        except DataError as err:
            if source == "the data":
                raise
            raise DataError(f"{source}: {err}") from None


# ---------------------------------------------------------------------- files
_EXTENSIONS = (".csv", ".npz")


def _check_extension(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix not in _EXTENSIONS:
        raise DataError(
            f"{path.name}: unknown extension '{path.suffix}'; a dataset file ends in .csv or .npz, or is a "
            "ROS 2 recording (.mcap, or a rosbag2 folder) (see 'Dataset files' in the README)"
        )
    return suffix


_SEPARATORS = {";": "semicolons", "\t": "tabs", "|": "vertical bars"}


def _read_text(path: Path) -> str:
    """Text of a CSV file: UTF-8, a byte-order mark skipped; a :class:`DataError` for a binary file."""
    raw = path.read_bytes()
    if raw.startswith(b"PK\x03\x04"):
        raise DataError(
            f"{path.name} is a zip archive, not comma-separated text; if it is an .npz dataset, name it .npz"
        )
    if b"\x00" in raw[:65536]:
        raise DataError(
            f"{path.name} is a binary file (it holds zero bytes), not comma-separated text; give a CSV "
            "text file with a header t,q_1..q_n,tau_1..tau_n"
        )
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise DataError(
            f"{path.name} is not UTF-8 text (byte 0x{raw[err.start]:02x} at offset {err.start}); give a "
            "comma-separated text file in UTF-8 (or ASCII) with a header t,q_1..q_n,tau_1..tau_n"
        ) from None
    return text


def _first_bad_line(lines: list[str], width: int) -> str:
    """Where the body of a CSV first fails to hold ``width`` comma-separated numbers (for the message)."""
    for number, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        cells = line.split(",")
        if len(cells) != width:
            return f"line {number} holds {len(cells)} comma-separated values, the header names {width}"
        for k, cell in enumerate(cells):
            try:
                float(cell)
            except ValueError:
                shown = cell.strip()[:20]
                return f"line {number}, column {k + 1} holds '{shown}', not a number"
    return "a line could not be read"


def _read_csv(path: Path) -> dict[str, NDArray[np.float64]]:
    text = _read_text(path)
    lines = text.splitlines()
    if not lines or not lines[0].strip():
        raise DataError(f"{path.name} is empty; a dataset CSV starts with a header line t,q_1,...,tau_n")
    header = lines[0]
    if "," not in header:
        found = next((name for sep, name in _SEPARATORS.items() if sep in header), None)
        if found is None and len(header.split()) > 1:
            found = "spaces"
        if found is not None:
            raise DataError(
                f"{path.name} is separated by {found}, but dynid reads comma-separated CSV; export it "
                "with commas between values and a point as decimal mark"
            )
    names = [name.strip().strip("\"'").strip() for name in header.split(",")]
    try:
        float(names[0])
    except ValueError:
        pass
    else:
        raise DataError(
            f"{path.name} has no header: its first line holds numbers; add a first line naming "
            "the columns t,q_1..q_n,tau_1..tau_n"
        )
    duplicates = sorted({name for name in names if names.count(name) > 1})
    if duplicates:
        raise DataError(f"{path.name} names column '{duplicates[0]}' twice; give each column once")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # numpy warns on an empty body; handled below
            table = np.loadtxt(io.StringIO(text), delimiter=",", dtype=np.float64, ndmin=2, skiprows=1)
    except ValueError:
        where = _first_bad_line(lines, len(names))
        raise DataError(
            f"{path.name} could not be read as numbers ({where}); every line after the header needs "
            f"{len(names)} comma-separated numbers"
        ) from None
    if table.size == 0:
        raise DataError(f"{path.name} has a header but no data rows; record or export the samples")
    if table.shape[1] != len(names):
        raise DataError(
            f"{path.name} has {len(names)} names in its header but {table.shape[1]} values a row; "
            "make the header and the rows agree"
        )
    return {name: table[:, k] for k, name in enumerate(names)}


def _read_npz(path: Path) -> tuple[dict[str, NDArray[np.float64]], dict[str, Any]]:
    if not zipfile.is_zipfile(path):
        head = path.read_bytes()[:512]
        try:
            looks_text = b"\x00" not in head and bool(head.decode("utf-8-sig").strip())
        except UnicodeDecodeError:
            looks_text = False
        what = "a text file" if looks_text else "not a zip archive"
        fix = (
            "if it is a CSV dataset, name it .csv" if looks_text else "write it with save_dataset or np.savez"
        )
        raise DataError(f"{path.name} is {what}, not an .npz archive of numeric arrays; {fix}")
    try:
        archive = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError, zipfile.BadZipFile) as err:
        raise DataError(
            f"{path.name} is not a readable .npz archive ({err}); write it with save_dataset"
        ) from None
    with archive:
        columns: dict[str, NDArray[np.float64]] = {}
        meta: dict[str, Any] = {}
        for key in archive.files:
            try:
                value = archive[key]
            except ValueError as err:
                if "allow_pickle" in str(err) or "Object arrays" in str(err):
                    raise DataError(
                        f"{path.name} holds '{key}' as Python objects, but dynid reads numeric arrays only; "
                        f"save it with np.savez(..., {key}=np.asarray({key}, dtype=float))"
                    ) from None
                raise DataError(
                    f"{path.name}: the array '{key}' could not be read ({err}); write it with save_dataset"
                ) from None
            except (OSError, EOFError, zipfile.BadZipFile, KeyError) as err:
                raise DataError(
                    f"{path.name}: the array '{key}' could not be read ({err}); the archive is damaged, "
                    "write it again with save_dataset"
                ) from None
            if not isinstance(value, np.ndarray):
                continue  # a member that is not a .npy array: not data
            if key == "meta":
                try:
                    meta = dict(json.loads(str(value)))
                except (ValueError, TypeError):
                    meta = {}
            elif key in _SIGNALS and value.ndim == 2:  # stacked (m, n) array, as np.savez(q=q) writes
                columns.update({f"{key}_{j + 1}": value[:, j] for j in range(value.shape[1])})
            else:
                columns[key] = value
    return columns, meta


def _drop_logged_twice(
    columns: dict[str, NDArray[np.float64]], source: str
) -> tuple[dict[str, NDArray[np.float64]], int]:
    """Drop rows identical to the row before (time included): a sample logged twice.  Returns the count."""
    try:
        arrays = [_as_float(key, value).ravel() for key, value in columns.items()]
    except DataError:
        return columns, 0  # non-numeric columns: the dataset's own checks name them
    if not arrays or len({len(a) for a in arrays}) != 1 or len(arrays[0]) < 2:
        return columns, 0
    table = np.column_stack(arrays)
    repeat = np.zeros(len(table), dtype=bool)
    repeat[1:] = np.all(table[1:] == table[:-1], axis=1)
    count = int(repeat.sum())
    if count == 0:
        return columns, 0
    first = int(np.argmax(repeat))
    warnings.warn(
        f"{source}: {count} row{'s repeat' if count > 1 else ' repeats'} the row before exactly (first: row "
        f"{first}), a sample logged twice; dropped",
        DataWarning,
        stacklevel=3,
    )
    keep = ~repeat
    return {key: a[keep] for key, a in zip(columns, arrays, strict=True)}, count


def _check_units(ds: Dataset, source: str, degrees: bool) -> Dataset:
    """Time in seconds and magnitudes a robot arm can reach; degrees converted when asked."""
    dt = float(np.median(np.diff(ds.t)))
    if dt >= MAX_TIME_STEP:
        raise DataError(
            f"{source}: the median time step is {dt:.6g}, but t must be in seconds and a robot is sampled "
            f"faster than every {MAX_TIME_STEP:g} s; convert t to seconds (milliseconds / 1e3, "
            "nanoseconds / 1e9)"
        )
    if degrees:
        scale = np.pi / 180.0
        ds = ds._derive(
            q=ds.q * scale,
            dq=None if ds.dq is None else ds.dq * scale,
            ddq=None if ds.ddq is None else ds.ddq * scale,
            meta={**ds.meta, "converted_from_degrees": True},
        )
    else:
        peak = np.abs(ds.q).max(axis=0)
        if peak.max() > DEGREES_THRESHOLD:
            j = int(np.argmax(peak))
            raise DataError(
                f"{source}: q_{j + 1} reaches {peak[j]:.4g}, more than {DEGREES_THRESHOLD:g} rad, so the angles "
                "look like degrees, but dynid reads radians; pass --degrees (load_dataset(..., degrees=True)) "
                "to convert q, dq and ddq"
            )
    units = {"tau": "N m", "dq": "rad/s", "ddq": "rad/s^2"}
    for name, limit in MAX_MAGNITUDE.items():
        a = getattr(ds, name)
        if a is None:
            continue
        big = np.abs(a) > limit
        if big.any():
            row, j = (int(i) for i in np.argwhere(big)[0])
            raise DataError(
                f"{source}: {name}_{j + 1} is {a[row, j]:.4g} at row {row}, beyond {limit:g} {units[name]} that "
                f"no robot arm reaches; check the column's units ({units[name]}) and the export"
            )
    return ds


def _torque_scale(robot: Any, samples: int = 256) -> NDArray[np.float64]:
    """Largest |tau_j| (N m) the robot's model gives over random states within its limits (fixed seed)."""
    import pinocchio as pin

    model = robot.pin_model
    data = model.createData()
    rng = np.random.default_rng(0)
    n = robot.n
    q = rng.uniform(robot.q_min, robot.q_max, size=(samples, n))
    dq = rng.uniform(-1.0, 1.0, size=(samples, n)) * robot.dq_max
    ddq = rng.uniform(-1.0, 1.0, size=(samples, n)) * robot.ddq_max
    tau = np.array([pin.rnea(model, data, q[k], dq[k], ddq[k]) for k in range(samples)])
    return np.abs(tau).max(axis=0) + np.abs(np.asarray(robot.armature) * robot.ddq_max)


def check_torque_scale(ds: Dataset, robot: Any, *, source: str = "the data") -> Dataset:
    """Refuse torques no model of this robot can explain.

    The robot's torque scale per joint is the largest ``|tau_j|`` its own model (rigid bodies and
    armature, no friction) gives over 256 random states within its position, velocity and acceleration
    limits; joint ``j`` may reach :data:`TORQUE_RATIO` times ``max(scale_j, 0.1 max(scale))``, room for
    friction, a payload and nominal parameters that are off.  Beyond it the torque is in other units
    (mN m, motor current) or was recorded on another robot.  A description without masses (kinematics
    only, for identification) has no scale and is not checked.

    Parameters
    ----------
    ds : Dataset
        The data.
    robot : RobotModel
        The robot the data should come from.
    source : str
        What the data came from (a file name), used in the message.

    Returns
    -------
    Dataset
        ``ds``, so that calls chain.

    Raises
    ------
    DataError
        A torque beyond the bound; the message names the joint, the row and the bound.
    """
    if not np.any(np.asarray(robot.params)):
        return ds
    scale = _torque_scale(robot)
    bound = TORQUE_RATIO * np.maximum(scale, 0.1 * scale.max())
    over = np.abs(ds.tau) > bound
    if not over.any():
        return ds
    row, j = (int(i) for i in np.argwhere(over)[0])
    raise DataError(
        f"{source}: tau_{j + 1} is {ds.tau[row, j]:.4g} N m at row {row}, more than {TORQUE_RATIO:g} times the "
        f"{scale[j]:.3g} N m the model of '{robot.name}' gives within its limits; give torques in N m "
        "(not mN m or motor current) recorded on that robot"
    )


def load_dataset(
    path: str | os.PathLike[str],
    n_joints: int | None = None,
    *,
    robot_name: str | None = None,
    degrees: bool = False,
    robot: Any = None,
    topic: str | None = None,
    joint_names: Sequence[str] | None = None,
) -> Dataset:
    """Read a dataset file (``.csv`` or ``.npz``), or a ROS 2 recording, checking it by the one rule of this module.

    Parameters
    ----------
    path : str or path-like
        A CSV file (UTF-8, comma-separated) with a header ``t,q_1..q_n,tau_1..tau_n[,dq_1..dq_n]
        [,ddq_1..ddq_n]`` (any column order; other columns are ignored), or an ``.npz`` archive holding
        numeric arrays of shape (m,) under the same names (stacked arrays ``q``, ``tau``, ``dq``, ``ddq``
        of shape (m, n) are accepted too).
    n_joints : int, optional
        Joint count of the robot the data must fit.
    robot_name : str, optional
        Robot name for messages.
    degrees : bool
        The file's ``q``, ``dq`` and ``ddq`` are in degrees (deg, deg/s, deg/s^2): convert them to radians
        (every joint; ``meta["converted_from_degrees"]`` records it).  Without it, angles above
        :data:`DEGREES_THRESHOLD` are refused as degrees.
    robot : RobotModel, optional
        The robot the data come from: sets ``n_joints`` and ``robot_name`` when they are not given, and
        refuses torques beyond :func:`check_torque_scale`.
    topic : str, optional
        For a ROS 2 recording (an ``.mcap`` or ``.db3`` file, or a rosbag2 folder with ``metadata.yaml``),
        the ``sensor_msgs/msg/JointState`` topic to read; needed when the bag holds more than one.  Ignored
        for ``.csv`` and ``.npz`` files.  A bag is read by :func:`dynid.identify.rosbag.read_rosbag`
        (positions in rad, efforts in N m, mapped to the robot's joint order, resampled when the stamps
        are irregular) and then checked like a file.
    joint_names : sequence of str, optional
        The robot's joint names in its joint order, to map a ROS 2 recording's joints (default
        ``robot.joint_names``; a bag without either is refused).

    Returns
    -------
    Dataset
        With ``meta["source"]`` set to the file path (and ``meta["dropped_repeats"]`` when rows logged
        twice were dropped).

    Raises
    ------
    DataError
        Missing file, unknown extension, binary or non-UTF-8 text, another separator than commas, an
        ``.npz`` that is not a zip of numeric arrays, missing column, non-numeric or non-finite values,
        time not strictly increasing or not in seconds, angles in degrees, impossible magnitudes, wrong
        joint count.  The message starts with the file name.

    Warns
    -----
    DataWarning
        When rows identical to the row before (a sample logged twice) were dropped.
    """
    from dynid.identify.rosbag import is_rosbag, read_rosbag

    path = Path(path)
    if is_rosbag(path):
        names = joint_names if joint_names is not None else getattr(robot, "joint_names", None)
        if names is None:
            raise DataError(
                f"{path.name} is a ROS 2 recording, whose joints are known by name, but no robot was given to "
                "put them in order; pass robot= (or joint_names=), or --robot / a model on the command line"
            )
        name = robot_name if robot_name is not None else getattr(robot, "name", None)
        ds = read_rosbag(path, names, topic=topic, robot_name=name)
        if n_joints is not None:
            ds.check_joints(n_joints, name)
        ds = _check_units(ds, path.name, degrees)
        return ds if robot is None else check_torque_scale(ds, robot, source=path.name)
    suffix = _check_extension(path)
    if robot is not None:
        n_joints = robot.n if n_joints is None else n_joints
        robot_name = robot.name if robot_name is None else robot_name
    if not path.exists():
        raise DataError(f"no dataset file at {path}; check the path")
    if path.is_dir():
        raise DataError(
            f"{path} is a folder; give the path of a .csv or .npz dataset file (a ROS 2 rosbag2 folder holds "
            "a metadata.yaml)"
        )
    meta: dict[str, Any] = {}
    try:
        if suffix == ".csv":
            columns = _read_csv(path)
        else:
            columns, meta = _read_npz(path)
    except PermissionError:
        raise DataError(f"{path} cannot be read (permission denied); make it readable") from None
    columns, dropped = _drop_logged_twice(columns, path.name)
    meta["source"] = str(path)
    if dropped:
        meta["dropped_repeats"] = dropped
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*look like degrees", category=DataWarning)
        ds = Dataset.from_columns(
            columns, n_joints=n_joints, robot_name=robot_name, source=path.name, meta=meta
        )
    ds = _check_units(ds, path.name, degrees)
    return ds if robot is None else check_torque_scale(ds, robot, source=path.name)


def _write_csv(ds: Dataset, f: Any) -> None:
    columns = ds.to_columns()
    f.write(",".join(columns) + "\n")
    np.savetxt(f, np.column_stack(list(columns.values())), delimiter=",", fmt="%.17g")


def _write_npz(ds: Dataset, f: Any) -> None:
    columns = ds.to_columns()
    meta = dumps_json(ds.meta, indent=None, default=str)  # anything JSON cannot hold as its text
    np.savez(f, **columns, meta=np.array(meta))


def save_dataset(ds: Dataset, path: str | os.PathLike[str]) -> Path:
    """Write a dataset to ``.csv`` or ``.npz``, all or nothing.

    The data go to a temporary file in the target folder, which then replaces ``path`` in one step
    (:func:`os.replace`): an interrupted or failed write leaves no partial file and an older file intact.
    Values are written with 17 significant digits, so a CSV reads back bit for bit.  The CSV holds the
    columns only; the ``.npz`` also keeps ``meta`` (as JSON), including the run boundaries.

    Parameters
    ----------
    ds : Dataset
        The data.
    path : str or path-like
        Target file; its extension (``.csv`` or ``.npz``) chooses the format.  Its folder must exist.

    Returns
    -------
    Path
        The path written.
    """
    path = Path(path)
    suffix = _check_extension(path)
    if not isinstance(ds, Dataset):
        raise DataError(
            f"save_dataset takes a Dataset; got {type(ds).__name__}; build one with Dataset(t, q, tau)"
        )
    folder = path.parent
    if not folder.is_dir():
        raise DataError(f"cannot write {path.name}: the folder {folder} does not exist; create it first")
    with atomic_path(path) as tmp:
        if suffix == ".csv":
            with open(tmp, "w", encoding="utf-8", newline="\n") as f:
                _write_csv(ds, f)
        else:
            with open(tmp, "wb") as f:
                _write_npz(ds, f)
    return path
