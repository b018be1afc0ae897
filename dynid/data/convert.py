"""A recording as it comes, turned into dynid's dataset: a table with its own column names and units.

Robot controllers log CSV with their own names (``timestamp``, ``position_1``, ``effort_1``), their own
separator (commas, semicolons, tabs, spaces) and their own units (time in ms or ns, angles in degrees,
torque in mN m or as motor current).  :func:`convert_table` reads such a table by the columns named for
each signal (names, or one pattern with ``*`` expanded in the file's column order), converts the units
and returns a :class:`~dynid.data.dataset.Dataset`, which :func:`~dynid.data.files.save_dataset`
writes in dynid's format (``dynid convert`` does both).  Lines starting with ``#`` are comments.
"""

from __future__ import annotations

import fnmatch
import io
import math
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from dynid.data.dataset import Dataset
from dynid.exceptions import DataError, UsageError

__all__ = ["TIME_UNITS", "columns_of", "convert_table", "read_table"]

TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
"""Time units a table's time column may be in, and their size in seconds."""

_SEPARATORS = (",", ";", "\t", "|")


def _separator(header: str) -> str | None:
    """The header's separator: the one of :data:`_SEPARATORS` it holds most, else None (white space)."""
    counts = {sep: header.count(sep) for sep in _SEPARATORS}
    sep = max(counts, key=lambda k: counts[k])
    return sep if counts[sep] else None


def read_table(path: str | os.PathLike[str]) -> tuple[list[str], NDArray[np.float64]]:
    """A delimited text table with a header: its column names and its numbers.

    Parameters
    ----------
    path : str or path-like
        The file (UTF-8; ``#`` comment lines and blank lines skipped; a decimal point, not a comma).

    Returns
    -------
    names : list of str
    table : ndarray, shape (m, len(names))

    Raises
    ------
    DataError
        A file that is missing, not text, without a header, or with a cell that is not a number.
    """
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path} does not exist or is not a file; give the recording's table")
    try:
        text = path.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError:
        raise DataError(
            f"{path.name} is not UTF-8 text; export the recording as a text table (CSV)"
        ) from None
    lines = [
        (k + 1, line)
        for k, line in enumerate(text.splitlines())
        if line.strip() and not line.lstrip().startswith("#")
    ]
    if not lines:
        raise DataError(f"{path.name} holds no lines but comments; give a table with a header line")
    header_no, header = lines[0]
    sep = _separator(header)

    def split(line: str) -> list[str]:
        cells = line.split(sep) if sep is not None else line.split()
        return [c.strip().strip("\"'").strip() for c in cells]

    names = split(header)
    try:
        float(names[0])
    except ValueError:
        pass
    else:
        raise DataError(
            f"{path.name} has no header: line {header_no} holds numbers; add a line naming the columns"
        )
    body = "\n".join(line for _, line in lines[1:])
    try:
        table = np.loadtxt(io.StringIO(body), delimiter=sep, dtype=np.float64, ndmin=2, quotechar='"')
    except ValueError:
        table = None  # the slow way below names the bad line
    if table is not None and table.size and table.shape[1] == len(names):
        return names, table
    rows = []
    for number, line in lines[1:]:
        cells = split(line)
        if len(cells) != len(names):
            raise DataError(
                f"{path.name}, line {number}: {len(cells)} values where the header names {len(names)} columns; "
                "make every row as long as the header"
            )
        try:
            rows.append([float(c) for c in cells])
        except ValueError:
            bad = next(c for c in cells if not _is_number(c))
            raise DataError(
                f"{path.name}, line {number}: '{bad[:20]}' is not a number; give numbers with a decimal point"
            ) from None
    if not rows:
        raise DataError(f"{path.name} has a header but no data rows")
    return names, np.asarray(rows, dtype=np.float64)


def _is_number(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


def columns_of(spec: str, names: Sequence[str], *, option: str) -> list[int]:
    """The column indices named by ``spec``: names separated by commas, or patterns with ``*``.

    Parameters
    ----------
    spec : str
        ``pos_1,pos_2`` or ``pos_*`` (a pattern takes the matching columns in the file's order).
    names : sequence of str
        The table's column names.
    option : str
        The option it came from, for messages (``--q``).
    """
    out: list[int] = []
    for item in (s.strip() for s in spec.split(",") if s.strip()):
        if any(ch in item for ch in "*?["):
            found = [k for k, name in enumerate(names) if fnmatch.fnmatchcase(name, item)]
            if not found:
                raise UsageError(
                    f"{option} '{item}' matches no column of the table; its columns are: {', '.join(names[:20])}"
                )
            out.extend(found)
        elif item in names:
            out.append(list(names).index(item))
        else:
            raise UsageError(
                f"{option} names '{item}', which the table has not; its columns are: {', '.join(names[:20])}"
            )
    if not out:
        raise UsageError(f"{option} names no column; give column names or a pattern such as 'pos_*'")
    return out


def _scale(value: str | float | Sequence[float] | None, n: int, option: str) -> NDArray[np.float64]:
    if value is None:
        return np.ones(n)
    if isinstance(value, str):
        try:
            values = [float(v) for v in value.split(",") if v.strip()]
        except ValueError:
            raise UsageError(
                f"{option} is '{value}'; give one number, or one per joint, separated by commas"
            ) from None
    elif isinstance(value, float | int):
        values = [float(value)]
    else:
        values = [float(v) for v in value]
    if len(values) not in (1, n) or not all(math.isfinite(v) and v != 0 for v in values):
        raise UsageError(f"{option} is {value}; give one non-zero finite number, or {n}, one per joint")
    return np.broadcast_to(np.asarray(values, dtype=np.float64), (n,)).copy()


def convert_table(
    path: str | os.PathLike[str],
    *,
    time: str,
    q: str,
    tau: str,
    dq: str | None = None,
    ddq: str | None = None,
    time_unit: str = "s",
    degrees: bool = False,
    torque_scale: str | float | Sequence[float] | None = None,
) -> Dataset:
    """A recording's table as a dataset: the named columns, in SI units.

    Parameters
    ----------
    path : str or path-like
        The table (:func:`read_table`).
    time : str
        The time column's name.
    q, tau : str
        The angle and torque columns, joint 1 first (:func:`columns_of`: names or a ``*`` pattern).
    dq, ddq : str, optional
        Velocity and acceleration columns, if logged.
    time_unit : {"s", "ms", "us", "ns"}
        Unit of the time column.
    degrees : bool
        Angles (and their derivatives) in degrees.
    torque_scale : float, or str / sequence of one per joint, optional
        Factor to N m (0.001 for mN m; a torque constant times a gear ratio for motor current).

    Raises
    ------
    UsageError
        Columns the table has not, a bad unit or scale, unequal joint counts.
    DataError
        What :class:`Dataset` refuses (time going back, non-finite values, ...).
    """
    if time_unit not in TIME_UNITS:
        raise UsageError(f"--time-unit is '{time_unit}'; choose one of {', '.join(TIME_UNITS)}")
    names, table = read_table(path)
    (t_col,) = columns_of(time, names, option="--time")[:1]
    picks = {"q": columns_of(q, names, option="--q"), "tau": columns_of(tau, names, option="--tau")}
    for key, spec in (("dq", dq), ("ddq", ddq)):
        if spec is not None:
            picks[key] = columns_of(spec, names, option=f"--{key}")
    n = len(picks["q"])
    for key, cols in picks.items():
        if len(cols) != n:
            raise UsageError(
                f"--{key} names {len(cols)} columns and --q {n}; give one column per joint for each signal"
            )
    t = table[:, t_col] * TIME_UNITS[time_unit]
    t = t - t[0]
    angle = math.pi / 180.0 if degrees else 1.0
    signals = {key: table[:, cols] for key, cols in picks.items()}
    signals["tau"] = signals["tau"] * _scale(torque_scale, n, "--torque-scale")
    for key in ("q", "dq", "ddq"):
        if key in signals:
            signals[key] = signals[key] * angle
    big = float(np.abs(signals["q"]).max())
    if not degrees and big > 10.0:
        raise DataError(
            f"the angles reach {big:.4g}, more than 10 rad: they look like degrees; add --degrees"
        )
    if len(t) > 1:  # what every reader refuses is not written (load_dataset's rule)
        from dynid.data.files import MAX_TIME_STEP

        dt = float(np.median(np.diff(t)))
        if dt >= MAX_TIME_STEP:
            guess = next((u for u, f in TIME_UNITS.items() if u != time_unit and dt * f / TIME_UNITS[time_unit] < 0.1), None)
            raise DataError(
                f"the column '{names[t_col]}' read in {time_unit} gives a median time step of {dt:.6g} s, but a robot "
                f"is sampled faster than every {MAX_TIME_STEP:g} s; give its unit with --time-unit"
                + (f" (e.g. --time-unit {guess})" if guess else "")
            )
    meta = {
        "source": Path(path).name,
        "columns": {key: [names[c] for c in cols] for key, cols in picks.items()} | {"t": names[t_col]},
    }
    return Dataset(t, signals["q"], signals["tau"], dq=signals.get("dq"), ddq=signals.get("ddq"), meta=meta)
