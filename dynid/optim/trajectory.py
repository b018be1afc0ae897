"""Trajectory types and files.

:class:`FourierTrajectory` is the excitation of the method (METHOD.md, section 3):

    q_i(t) = c_i + sum_{l=1..N} [ a_{l,i} / (wf l) sin(wf l t) - b_{l,i} / (wf l) cos(wf l t) ],  wf = 2 pi ff

with analytic velocity and acceleration.  :class:`SampledTrajectory` holds any trajectory on a time
grid (e.g. an approach, the excitation and a retreat joined together) and interpolates it.

Files: JSON (coefficients and metadata, or samples) and CSV sampled at a controller rate with the
columns ``t, q_1..q_n, dq_1..dq_n, ddq_1..ddq_n``.
"""

from __future__ import annotations

import csv
import json
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np

from dynid._io import dumps_json, write_text
from dynid.exceptions import ModelFileError, ShapeError

__all__ = [
    "FourierTrajectory",
    "SampledTrajectory",
    "Trajectory",
    "load_trajectory",
]


class Trajectory(Protocol):
    """Anything that gives joint positions, velocities and accelerations over time."""

    n: int
    duration: float

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...


def _write_file(path: str | Path, text: str) -> None:
    """Write a trajectory file atomically (never half written) into an existing folder."""
    path = Path(path)
    if not path.parent.exists():
        raise ModelFileError(f"the folder '{path.parent}' does not exist; create it or write elsewhere.")
    write_text(path, text)


@dataclass(frozen=True, eq=False)
class FourierTrajectory:
    """A finite Fourier series per joint (METHOD.md, section 3).

    Parameters
    ----------
    a, b : ndarray, shape (N, n)
        Sine and cosine coefficients of the velocity (rad/s): ``dq_i = sum a cos + b sin``.
    c : ndarray, shape (n,)
        Position offsets (rad).
    base_freq : float
        Base frequency ff (Hz); the period is 1 / ff.
    periods : int
        Number of periods the trajectory lasts.
    meta : dict
        Free metadata (robot, criterion, condition number, ...), written to the JSON file.
    """

    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    base_freq: float
    periods: int = 1
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        a = np.atleast_2d(np.asarray(self.a, dtype=float))
        b = np.atleast_2d(np.asarray(self.b, dtype=float))
        c = np.asarray(self.c, dtype=float).ravel()
        if a.shape != b.shape or a.shape[1] != c.size:
            raise ShapeError(
                f"Fourier coefficients a {a.shape}, b {b.shape} and c {c.shape} do not match; a and b must be "
                "(harmonics, joints) and c (joints,)."
            )
        if not (self.base_freq > 0 and math.isfinite(self.base_freq)):
            raise ShapeError(f"base_freq is {self.base_freq}; give a positive frequency in Hz.")
        if int(self.periods) < 1:
            raise ShapeError(f"periods is {self.periods}; give at least 1.")
        for name, value in (("a", a), ("b", b), ("c", c)):
            if not np.all(np.isfinite(value)):
                raise ShapeError(f"Fourier coefficients {name} hold non-finite values; give finite numbers.")
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    @property
    def n(self) -> int:
        return self.c.size

    @property
    def harmonics(self) -> int:
        return self.a.shape[0]

    @property
    def wf(self) -> float:
        """Base angular frequency (rad/s)."""
        return 2.0 * math.pi * self.base_freq

    @property
    def period(self) -> float:
        return 1.0 / self.base_freq

    @property
    def duration(self) -> float:
        return self.periods * self.period

    def evaluate(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q, dq, ddq at times ``t`` (s): each of shape (len(t), n)."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        lw = self.wf * np.arange(1, self.harmonics + 1)  # (N,)
        phase = np.outer(t, lw)  # (m, N)
        s, co = np.sin(phase), np.cos(phase)
        q = self.c + (s / lw) @ self.a - (co / lw) @ self.b
        dq = co @ self.a + s @ self.b
        ddq = (-s * lw) @ self.a + (co * lw) @ self.b
        return q, dq, ddq

    def sample(self, rate: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(t, q, dq, ddq) on a uniform grid at ``rate`` Hz over the whole duration, ends included."""
        t = uniform_grid(self.duration, rate)
        return (t, *self.evaluate(t))

    def to_dict(self) -> dict:
        return {
            "type": "fourier",
            "n_joints": self.n,
            "harmonics": self.harmonics,
            "base_freq": self.base_freq,
            "periods": int(self.periods),
            "a": self.a.tolist(),
            "b": self.b.tolist(),
            "c": self.c.tolist(),
            "meta": self.meta,
        }

    @classmethod
    def from_dict(cls, data: dict, *, source: str = "the Fourier trajectory") -> FourierTrajectory:
        """The trajectory a dict of :meth:`to_dict` (a trajectory file) describes, its fields checked.

        Parameters
        ----------
        data : dict
            ``a``, ``b``, ``c``, ``base_freq`` and optionally ``periods``, ``meta``, and ``harmonics`` and
            ``n_joints``, which must agree with the coefficient arrays when present.
        source : str
            What the dict came from (``the trajectory file 'T.json'``), for the messages.

        Raises
        ------
        ModelFileError
            A missing field, coefficients that are not tables of numbers, or ``harmonics`` / ``n_joints``
            that contradict them.
        """
        missing = [key for key in ("a", "b", "c", "base_freq") if key not in data]
        if missing:
            raise ModelFileError(f"{source} has no field '{missing[0]}'; it needs a, b, c and base_freq.")
        arrays = {}
        for key in ("a", "b", "c"):
            try:
                arrays[key] = np.asarray(data[key], dtype=float)
            except (TypeError, ValueError):
                raise ModelFileError(
                    f"the field '{key}' of {source} is not a table of numbers (rows of equal length); write the "
                    "file again with dynid excite."
                ) from None
        a, c = np.atleast_2d(arrays["a"]), arrays["c"].ravel()
        stated = {"harmonics": (a.shape[0], "rows of a and b (one per harmonic)"),
                  "n_joints": (c.size, "values of c (one per joint)")}  # fmt: skip
        for key, (count, what) in stated.items():
            if key not in data:
                continue
            value = data[key]
            if isinstance(value, bool) or not isinstance(value, int | float) or value != count:
                raise ModelFileError(
                    f"{source} states {key} = {value!r}, but its coefficients hold {count} {what}; correct "
                    f"{key} to {count} or write the file again with dynid excite."
                )
        try:
            return cls(
                a=arrays["a"],
                b=arrays["b"],
                c=arrays["c"],
                base_freq=float(data["base_freq"]),
                periods=int(data.get("periods", 1)),
                meta=dict(data.get("meta", {})),
            )
        except (TypeError, ValueError) as exc:
            if isinstance(exc, ShapeError):
                raise ModelFileError(f"{source}: {exc}") from None
            raise ModelFileError(
                f"{source} holds a base_freq, periods or meta that is not of its kind ({exc}); base_freq is a "
                "number (Hz), periods a whole number and meta a table: write the file again with dynid excite."
            ) from None

    def save(self, path: str | Path) -> None:
        """Write the coefficients and metadata as JSON."""
        _write_file(path, dumps_json(self.to_dict()))


@dataclass(frozen=True, eq=False)
class SampledTrajectory:
    """A trajectory on a time grid, interpolated linearly between samples.

    Parameters
    ----------
    t : ndarray, shape (m,)
        Strictly increasing times (s).
    q, dq, ddq : ndarray, shape (m, n)
        Positions (rad), velocities (rad/s), accelerations (rad/s^2).
    """

    t: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        t = np.asarray(self.t, dtype=float).ravel()
        arrays = [np.atleast_2d(np.asarray(v, dtype=float)) for v in (self.q, self.dq, self.ddq)]
        if any(a.shape != arrays[0].shape or a.shape[0] != t.size for a in arrays):
            raise ShapeError(
                f"t has {t.size} samples, q {arrays[0].shape}, dq {arrays[1].shape}, ddq {arrays[2].shape}; "
                "give one row per time stamp and the same joints in each."
            )
        if t.size < 2 or np.any(np.diff(t) <= 0):
            raise ShapeError(
                "the time stamps of a sampled trajectory must be at least two and strictly increasing."
            )
        object.__setattr__(self, "t", t)
        for name, value in zip(("q", "dq", "ddq"), arrays, strict=True):
            object.__setattr__(self, name, value)

    @property
    def n(self) -> int:
        return self.q.shape[1]

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])

    def evaluate(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.atleast_1d(np.asarray(t, dtype=float)) + self.t[0]
        out = []
        for arr in (self.q, self.dq, self.ddq):
            out.append(np.column_stack([np.interp(t, self.t, arr[:, j]) for j in range(self.n)]))
        return out[0], out[1], out[2]

    def to_csv(self, path: str | Path) -> None:
        """Write ``t, q_1..q_n, dq_1..dq_n, ddq_1..ddq_n``."""
        write_trajectory_csv(path, self.t, self.q, self.dq, self.ddq)


def uniform_grid(duration: float, rate: float) -> np.ndarray:
    """Times 0, 1/rate, ..., duration (the end included when it falls on the grid)."""
    if not rate > 0:
        raise ShapeError(f"the sampling rate is {rate}; give a positive rate in Hz.")
    steps = round(duration * rate)
    return np.arange(steps + 1) / rate


def write_trajectory_csv(path, t, q, dq, ddq) -> None:
    """Write a sampled trajectory as CSV with a header."""
    n = q.shape[1]
    header = ["t"] + [f"{k}_{j + 1}" for k in ("q", "dq", "ddq") for j in range(n)]
    rows = np.column_stack([t, q, dq, ddq])
    lines = [",".join(header)]
    lines += [",".join(repr(float(v)) for v in row) for row in rows]
    _write_file(path, "\n".join(lines) + "\n")


def load_trajectory(path: str | Path) -> FourierTrajectory | SampledTrajectory:
    """Read a trajectory file: JSON (Fourier coefficients) or CSV (``t, q_i, dq_i, ddq_i``)."""
    path = Path(path)
    if not path.is_file():
        raise ModelFileError(
            f"the trajectory file '{path}' does not exist; give the file written by dynid excite."
        )
    if path.suffix.lower() == ".json":
        try:
            data = json.loads(path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise ModelFileError(
                f"the trajectory file '{path}' is not valid JSON ({exc}); rewrite it."
            ) from None
        if not isinstance(data, dict) or data.get("type") != "fourier":
            raise ModelFileError(
                f'the trajectory file \'{path}\' is not a dynid Fourier trajectory (no "type": "fourier"); '
                "give a file written by dynid excite."
            )
        return FourierTrajectory.from_dict(data, source=f"the trajectory file '{path}'")
    if path.suffix.lower() == ".csv":
        with open(path, newline="") as handle:
            reader = csv.reader(handle)
            header = next(reader, [])
        n = sum(1 for h in header if h.startswith("q_"))
        need = ["t"] + [f"{k}_{j + 1}" for k in ("q", "dq", "ddq") for j in range(n)]
        missing = [h for h in need if h not in header]
        if n == 0 or missing:
            raise ModelFileError(
                f"the trajectory file '{path}' lacks the columns {', '.join(missing) or 'q_1..q_n'}; a sampled "
                "trajectory needs t, q_i, dq_i and ddq_i."
            )
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)  # numpy warns on an empty body; refused below
                data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
        except ValueError as exc:
            raise ModelFileError(
                f"the trajectory file '{path}' could not be read as numbers ({exc}); every line after the header "
                f"needs {len(header)} comma-separated numbers."
            ) from None
        if data.size == 0:
            raise ModelFileError(
                f"the trajectory file '{path}' has a header but no rows; write it again with dynid excite --csv."
            )
        if data.shape[1] != len(header):
            raise ModelFileError(
                f"the trajectory file '{path}' has {len(header)} names in its header but {data.shape[1]} values a "
                "row; make the header and the rows agree."
            )
        idx = {h: i for i, h in enumerate(header)}

        def cols(prefix: str) -> np.ndarray:
            return data[:, [idx[f"{prefix}_{j + 1}"] for j in range(n)]]

        return SampledTrajectory(t=data[:, idx["t"]], q=cols("q"), dq=cols("dq"), ddq=cols("ddq"))
    raise ModelFileError(
        f"the trajectory file '{path}' has the extension '{path.suffix}'; give a .json or .csv file."
    )
