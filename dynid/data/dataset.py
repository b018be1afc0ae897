"""Measured (or simulated) robot data: the :class:`Dataset` type.

A dataset holds, for ``m`` time stamps and ``n`` joints, the time ``t`` (s), the joint angles ``q`` (rad),
the joint torques ``tau`` (N m) and optionally the joint velocities ``dq`` (rad/s) and accelerations
``ddq`` (rad/s^2).  It checks itself when made: finite values, strictly increasing time, consistent shapes,
and (optionally) the joint count of a robot.

Several recordings can be joined with :meth:`Dataset.concat`; the join records where each run starts
(``meta["run_starts"]``) so that filtering and differentiation never cross from one run into the next.

A :class:`Dataset` built from arrays checks structure only (shapes, finite values, increasing time) and
warns about angles that look like degrees, so that arrays in any test units can still be built.  Its files
(CSV, npz, ROS 2 recordings) and the stricter rules a file must pass (units, magnitudes) are
:mod:`dynid.data.files`.
"""

from __future__ import annotations

import itertools
import re
import warnings
from collections.abc import Iterable, Mapping
from dataclasses import KW_ONLY, InitVar, dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynid.exceptions import DataError, DataWarning

__all__ = ["DEGREES_THRESHOLD", "SIGNALS", "Dataset"]

#: An angle larger than this (rad) in magnitude makes :class:`Dataset` warn that the angles look like degrees
#: (and :func:`dynid.data.files.load_dataset` refuse them unless asked to convert).
DEGREES_THRESHOLD = 10.0

#: The signals of a dataset beside the time, each of shape (m, n) (``dq``, ``ddq`` optional).
SIGNALS = ("q", "tau", "dq", "ddq")
_OPTIONAL = ("dq", "ddq")
_CONTRACT = "a dataset needs t, q_1..q_n and tau_1..tau_n (see 'Dataset files' in docs/commands.md)"
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
        for name in SIGNALS:
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
        for name in SIGNALS:
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
            **{name: None if getattr(self, name) is None else getattr(self, name)[idx] for name in SIGNALS},
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
        fields = {name: getattr(self, name) for name in ("t", *SIGNALS, "meta")}
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
        for name in SIGNALS:
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
        numbered: dict[str, dict[int, str]] = {name: {} for name in SIGNALS}
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
        for name in SIGNALS:
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
