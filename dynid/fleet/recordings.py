"""A fleet's recordings: which files, which robot recorded each, and when.

The recordings are the files (and ROS 2 bag folders) a glob pattern matches: ``.csv``, ``.npz``,
``.mcap``, and folders holding a rosbag2 ``metadata.yaml``; anything else the pattern matches (a
simulator's ``.truth.json`` sidecar, a README) is not a recording and is passed over.

Robot and time come from one of two places:

* **a manifest**: a CSV file with the columns ``path``, ``robot`` and ``time`` (other columns are
  kept as they are not); ``path`` is relative to the manifest's folder or absolute.  Every recording the
  pattern matches must have its row;
* **the path** (no manifest): ``<robot>/<time>.<ext>``, the robot is the name of the folder holding
  the recording and the time is the file's name without its extension: an ISO date or date-time
  (``2026-03-01``, ``2026-03-01T08-30``, ``2026-03-01_083000``) or a whole number (``0``, ``001``,
  ``rec_12`` uses its trailing number).

Times are compared within a robot only: each robot's recordings are put in time order and numbered
from 0 (``order``); two recordings of one robot at the same time are refused, and so are a robot's
recordings timed partly by date and partly by index (the two do not order).  A manifest that names a
recording twice, or a file that does not exist, is refused, naming its line.
"""

from __future__ import annotations

import csv
import glob
import os
import re
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

from dynid.exceptions import UsageError

__all__ = ["RECORDING_SUFFIXES", "Recording", "find_recordings", "parse_time"]

RECORDING_SUFFIXES = (".csv", ".npz", ".mcap")
"""File extensions read as recordings (and rosbag2 folders, which hold a ``metadata.yaml``)."""

_ISO = re.compile(
    r"(\d{4})-(\d{2})-(\d{2})(?:[T_ ](\d{2})[-:]?(\d{2})(?:[-:]?(\d{2}))?)?"
)
_INDEX = re.compile(r"(\d+)$")


@dataclass(frozen=True)
class Recording:
    """One recording of the fleet.

    Attributes
    ----------
    path : str
        The file (or rosbag2 folder).
    robot : str
        The robot that recorded it.
    time : str
        When, as given (an ISO date or date-time, or an index).
    key : float
        ``time`` as a number that orders a robot's recordings (seconds since 1970 for a date, else the index).
    order : int
        Its place among the robot's recordings, from 0.
    """

    path: str
    robot: str
    time: str
    key: float
    order: int = 0


def parse_time(text: str) -> float | None:
    """A recording's time as a sortable number: POSIX seconds (UTC) for an ISO date, else a trailing index.

    Parameters
    ----------
    text : str
        ``2026-03-01``, ``2026-03-01T08:30:00``, ``2026-03-01_083000``, ``12``, ``rec_12``...

    Returns
    -------
    float or None
        None when the text holds neither a date nor a trailing number.
    """
    text = text.strip()
    match = _ISO.search(text)
    if match:
        parts = [int(g) if g else 0 for g in match.groups()]
        try:
            stamp = datetime(*parts[:3], parts[3], parts[4], parts[5])
        except ValueError:
            return None
        return (stamp - datetime(1970, 1, 1)).total_seconds()
    match = _INDEX.search(text)
    return float(match.group(1)) if match else None


def _is_recording(path: Path) -> bool:
    if path.is_dir():
        return (path / "metadata.yaml").is_file()
    return path.suffix.lower() in RECORDING_SUFFIXES and not path.name.endswith(".truth.json")


def _expand(pattern: str) -> list[Path]:
    matched = sorted({Path(p) for p in glob.glob(os.path.expanduser(pattern), recursive=True)})
    found = [p for p in matched if _is_recording(p)]
    # a recording inside a rosbag2 folder the pattern also matched is that bag's, not one of its own
    bags = [p for p in found if p.is_dir()]
    return [p for p in found if not any(b in p.parents for b in bags)]


def _time_kind(text: str) -> str:
    """``"date"`` for a time holding an ISO date, else ``"index"``."""
    return "date" if _ISO.search(text.strip()) else "index"


def _read_manifest(manifest: str | os.PathLike[str]) -> dict[str, tuple[str, str, int]]:
    """Real path -> (robot, time, line) of each row of a manifest, its rows checked."""
    path = Path(manifest)
    if not path.is_file():
        what = "is a folder" if path.is_dir() else "does not exist"
        raise UsageError(f"the manifest '{path}' {what}; give a CSV file with the columns path, robot, time.")
    try:
        with open(path, encoding="utf-8-sig", newline="") as f:
            rows = list(csv.DictReader(f))
    except (UnicodeDecodeError, csv.Error) as exc:
        raise UsageError(
            f"the manifest '{path}' is not a readable CSV file ({exc}); give UTF-8 text with the columns path, "
            "robot, time."
        ) from None
    header = set(rows[0]) if rows else set()
    missing = [c for c in ("path", "robot", "time") if c not in header]
    if missing or not rows:
        raise UsageError(
            f"the manifest '{path}' has {'no rows' if not rows else 'no column ' + ', '.join(missing)}; it needs "
            "one row per recording with the columns path, robot, time."
        )
    out: dict[str, tuple[str, str, int]] = {}
    for k, row in enumerate(rows, start=2):
        name, robot, time = (str(row.get(c) or "").strip() for c in ("path", "robot", "time"))
        if not name or not robot or not time:
            raise UsageError(
                f"line {k} of the manifest '{path}' leaves path, robot or time empty; fill in all three."
            )
        target = Path(name) if Path(name).is_absolute() else path.parent / name
        if not target.exists():
            raise UsageError(
                f"line {k} of the manifest '{path}' names the recording '{name}', but there is no such file "
                f"(looked for '{target}'); correct its path (relative to the manifest's folder) or drop the row."
            )
        key = os.path.realpath(target)
        if key in out:
            raise UsageError(
                f"line {k} of the manifest '{path}' names the recording '{name}' again (line {out[key][2]} names it "
                "already); give each recording one row."
            )
        out[key] = (robot, time, k)
    return out


def find_recordings(
    pattern: str, manifest: str | os.PathLike[str] | None = None, *, out: str | os.PathLike[str] | None = None
) -> list[Recording]:
    """The recordings a glob pattern matches, each with its robot and time, in (robot, time) order.

    Parameters
    ----------
    pattern : str
        A glob pattern (``**`` matches folders at any depth), e.g. ``recordings/**/*.csv``; or one path.
    manifest : str or path-like, optional
        CSV file with the columns ``path``, ``robot``, ``time`` (see the module's docstring); without it
        robot and time come from the path.
    out : str or path-like, optional
        The folder the fleet run writes: what the pattern matches inside it (an earlier run's
        ``drift.csv``) is no recording.

    Returns
    -------
    list of Recording

    Raises
    ------
    UsageError
        Nothing matches; a recording missing from the manifest; a manifest row naming a file that does not
        exist or a recording named by a row before; a path or time that does not follow the rule; two
        recordings of a robot at the same time; a robot's recordings timed partly by date, partly by index.
    """
    paths = _expand(str(pattern))
    if manifest is not None:  # a manifest beside its recordings is no recording
        paths = [p for p in paths if os.path.realpath(p) != os.path.realpath(manifest)]
    if out is not None:  # nor is the run's own output folder, when the pattern reaches into it
        inside = os.path.realpath(out).rstrip(os.sep) + os.sep
        paths = [p for p in paths if not os.path.realpath(p).startswith(inside)]
    if not paths:
        raise UsageError(
            f"no recording matches '{pattern}'; give a glob pattern that matches .csv, .npz or .mcap files or "
            "rosbag2 folders (quote it so the shell does not expand it), e.g. 'recordings/**/*.csv'."
        )
    table = None if manifest is None else _read_manifest(manifest)
    found: list[Recording] = []
    for path in paths:
        if table is not None:
            entry = table.get(os.path.realpath(path))
            if entry is None:
                raise UsageError(
                    f"the recording '{path}' is not in the manifest '{manifest}'; add a row for it (path, robot, "
                    "time) or narrow the pattern."
                )
            robot, time, _line = entry
        else:
            robot = path.resolve().parent.name
            time = path.name if path.is_dir() else path.stem
        key = parse_time(time)
        if key is None:
            where = f"the manifest '{manifest}'" if table is not None else "its name"
            raise UsageError(
                f"the time of the recording '{path}' ('{time}', from {where}) is neither an ISO date nor an index; "
                "name recordings <robot>/<YYYY-MM-DD or number>.<ext>, or give --manifest with a time column."
            )
        found.append(Recording(str(path), robot, time, key))
    _check_one_kind_of_time(found, table, manifest)
    found.sort(key=lambda r: (r.robot, r.key, r.path))
    out: list[Recording] = []
    for rec in found:
        previous = out[-1] if out and out[-1].robot == rec.robot else None
        if previous is not None and previous.key == rec.key:
            raise UsageError(
                f"the robot '{rec.robot}' has two recordings at the time '{rec.time}' ('{previous.path}' and "
                f"'{rec.path}'); give each recording its own time."
            )
        order = 0 if previous is None else previous.order + 1
        out.append(Recording(rec.path, rec.robot, rec.time, rec.key, order))
    return out


def _check_one_kind_of_time(
    found: list[Recording], table: dict[str, tuple[str, str, int]] | None, manifest: str | os.PathLike[str] | None
) -> None:
    """Refuse a robot whose recordings are timed partly by ISO date and partly by index: the two do not order."""
    first: dict[tuple[str, str], Recording] = {}
    for rec in found:
        kind = _time_kind(rec.time)
        first.setdefault((rec.robot, kind), rec)
        other = first.get((rec.robot, "index" if kind == "date" else "date"))
        if other is None:
            continue

        def where(r: Recording) -> str:
            if table is None:
                return f"'{r.path}'"
            return f"line {table[os.path.realpath(r.path)][2]} of the manifest '{manifest}'"

        date, index = (rec, other) if kind == "date" else (other, rec)
        raise UsageError(
            f"the robot '{rec.robot}' has recordings timed by ISO date ({where(date)}: '{date.time}') and by index "
            f"({where(index)}: '{index.time}'), which do not order; time all of one robot's recordings by date, or "
            "all by index."
        )
