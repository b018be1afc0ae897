"""Dataset files: the one reader every command uses (CSV, npz, ROS 2 recordings) and the writer.

Files follow the contract of docs/commands.md ('Dataset files'): a CSV file whose header names the columns ``t``, ``q_1..q_n``,
``tau_1..tau_n`` and optionally ``dq_1..dq_n``, ``ddq_1..ddq_n`` (joints numbered from 1 in the model's
joint order), or an ``.npz`` archive with the same names.  :func:`save_dataset` writes a temporary file
in the target folder and renames it, so a file is either complete or absent.  A ROS 2 recording is read by
:func:`dynid.data.rosbag.read_rosbag`; :func:`load_dataset` chooses the reader by the path.

:func:`load_dataset` applies one rule to every file: it reads the file as it is or refuses it with a
:class:`DataError` of one sentence (what was expected, what came, the fix).  The single exception is a
sample logged twice (a row identical to the row before it, time stamp included): it is dropped with a
:class:`DataWarning`.  Nothing is ever sorted: time that repeats with other values or steps backwards is
refused, naming the rows.  In detail:

* encoding: UTF-8 text (a byte-order mark is skipped); a binary file is refused;
* separator: commas (a file separated by semicolons, tabs or spaces is refused, naming the separator);
  lines starting with ``#`` are comments, above the header as in the body;
* values: numbers, finite (the first bad cell is named by column and row);
* time: seconds, strictly increasing; a median step of :data:`MAX_TIME_STEP` (1 s) or more is refused
  as time in milliseconds or finer units;
* magnitudes: ``|q|`` above :data:`~dynid.data.dataset.DEGREES_THRESHOLD` (10 rad) is refused as degrees
  unless ``degrees=True`` converts ``q``, ``dq`` and ``ddq`` to radians; ``|tau|``, ``|dq|``, ``|ddq|``
  above :data:`MAX_MAGNITUDE` (no robot arm reaches them) are refused as wrong units or corrupt cells;
  given the robot (``robot=``), a torque above :data:`TORQUE_RATIO` times what the robot's own model
  can produce within its limits is refused too (:func:`check_torque_scale`), and angles that leave the
  robot's joint limits by more than :data:`RANGE_WARN` of a joint's range are warned about
  (:func:`check_joint_range`);
* dead sensors: a torque column that never changes is refused; one stuck at a value over
  :data:`STUCK_FRACTION` of the rows while the arm moves is warned about, naming the joint.
"""

from __future__ import annotations

import codecs
import json
import os
import warnings
import zipfile
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynid._io import atomic_path, dumps_json
from dynid.data.dataset import DEGREES_THRESHOLD, SIGNALS, Dataset
from dynid.data.rosbag import is_rosbag, read_rosbag
from dynid.exceptions import DataError, DataWarning

__all__ = [
    "MAX_MAGNITUDE",
    "MAX_TIME_STEP",
    "RANGE_WARN",
    "STUCK_FRACTION",
    "TORQUE_RATIO",
    "check_joint_range",
    "check_torque_scale",
    "load_dataset",
    "save_dataset",
    "simulated_on",
    "truth_sidecar",
]

#: A median time step (s) at or above this makes :func:`load_dataset` refuse the time column as not in seconds.
MAX_TIME_STEP = 1.0

#: Largest magnitude :func:`load_dataset` accepts per signal: torque (N m), velocity (rad/s), acceleration
#: (rad/s^2).  No robot arm joint reaches them; a value beyond is a unit or export error.
MAX_MAGNITUDE: dict[str, float] = {"tau": 1e6, "dq": 1e3, "ddq": 1e6}

#: A measured torque above this many times the robot's own torque scale (see :func:`check_torque_scale`)
#: is refused as a unit error (mN m, raw motor current) or a dataset of another robot.
TORQUE_RATIO = 20.0

#: Angles beyond a joint's limits by more than this fraction of the joint's range (q_max - q_min) are
#: warned about (:func:`check_joint_range`): a joint offset, a calibration or another robot's data.
RANGE_WARN = 0.2

#: A torque column holding one value, unchanged, over at least this fraction of the rows while the arm
#: moves is warned about as a sensor that stuck (one that never changes at all is refused).
STUCK_FRACTION = 0.2

_EXTENSIONS = (".csv", ".npz")


def _check_extension(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix not in _EXTENSIONS:
        raise DataError(
            f"{path.name}: unknown extension '{path.suffix}'; a dataset file ends in .csv or .npz, or is a "
            "ROS 2 recording (.mcap, or a rosbag2 folder) (see 'Dataset files' in docs/commands.md)"
        )
    return suffix


_SEPARATORS = {";": "semicolons", "\t": "tabs", "|": "vertical bars"}


def _check_text(path: Path) -> None:
    """A :class:`DataError` for a file that is not UTF-8 text (a zip archive, zero bytes, another encoding)."""
    with path.open("rb") as fh:
        head = fh.read(65536)
    if head.startswith(b"PK\x03\x04"):
        raise DataError(
            f"{path.name} is a zip archive, not comma-separated text; if it is an .npz dataset, name it .npz"
        )
    if b"\x00" in head:
        raise DataError(
            f"{path.name} is a binary file (it holds zero bytes), not comma-separated text; give a CSV "
            "text file with a header t,q_1..q_n,tau_1..tau_n"
        )


def _not_utf8(path: Path) -> DataError:
    """The refusal of a file that does not decode as UTF-8, naming the first bad byte (read a block at a time)."""
    decoder = codecs.getincrementaldecoder("utf-8")()
    offset = 0
    with path.open("rb") as fh:
        while block := fh.read(1 << 20):
            try:
                decoder.decode(block)
            except UnicodeDecodeError as err:
                at = offset + err.start
                return DataError(
                    f"{path.name} is not UTF-8 text (byte 0x{block[err.start]:02x} at offset {at}); give a "
                    "comma-separated text file in UTF-8 (or ASCII) with a header t,q_1..q_n,tau_1..tau_n"
                )
            offset += len(block)
    return DataError(f"{path.name} is not UTF-8 text; give a comma-separated text file in UTF-8 (or ASCII)")


def _first_bad_line(lines: Iterable[str], width: int) -> str:
    """Where the body of a CSV first fails to hold ``width`` comma-separated numbers (for the message)."""
    header = True
    for number, line in enumerate(lines, start=1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        if header:
            header = False
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
    """The columns of a dataset CSV, read a block of lines at a time (memory in the numbers, not the text)."""
    _check_text(path)
    try:
        with path.open(encoding="utf-8-sig", newline="") as fh:
            header = fh.readline().rstrip("\r\n")
            comment = ""
            while header.lstrip().startswith("#"):  # comment lines above the header, as loadtxt skips below
                comment, header = header, fh.readline().rstrip("\r\n")
            names = _csv_names(path, header, comment)
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", UserWarning)  # numpy warns on an empty body; handled below
                    table = np.loadtxt(fh, delimiter=",", dtype=np.float64, ndmin=2)
            except ValueError:
                with path.open(encoding="utf-8-sig", newline="") as again:
                    where = _first_bad_line(again, len(names))
                raise DataError(
                    f"{path.name} could not be read as numbers ({where}); every line after the header needs "
                    f"{len(names)} comma-separated numbers"
                ) from None
    except UnicodeDecodeError:
        raise _not_utf8(path) from None
    if table.size == 0:
        raise DataError(f"{path.name} has a header but no data rows; record or export the samples")
    if table.shape[1] != len(names):
        raise DataError(
            f"{path.name} has {len(names)} names in its header but {table.shape[1]} values a row; "
            "make the header and the rows agree"
        )
    return {name: table[:, k] for k, name in enumerate(names)}


def _csv_names(path: Path, header: str, comment: str = "") -> list[str]:
    """The column names of a CSV header line, or a :class:`DataError` saying what the line is instead
    (``comment``: the last comment line above it, if any)."""
    if not header.strip():
        what = "holds only comment lines" if comment else "is empty"
        raise DataError(f"{path.name} {what}; a dataset CSV starts with a header line t,q_1,...,tau_n")
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
        if "," in comment:
            raise DataError(
                f"{path.name} has its header commented out ('{comment.strip()[:40]}'), so its first line holds "
                "numbers; remove the '#' (np.savetxt(..., comments='') writes the header without it)"
            )
        raise DataError(
            f"{path.name} has no header: its first line holds numbers; add a first line naming "
            "the columns t,q_1..q_n,tau_1..tau_n"
        )
    duplicates = sorted({name for name in names if names.count(name) > 1})
    if duplicates:
        raise DataError(f"{path.name} names column '{duplicates[0]}' twice; give each column once")
    return names


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
            elif key in SIGNALS and value.ndim == 2:  # stacked (m, n) array, as np.savez(q=q) writes
                columns.update({f"{key}_{j + 1}": value[:, j] for j in range(value.shape[1])})
            else:
                columns[key] = value
    return columns, meta


def _drop_logged_twice(
    columns: dict[str, NDArray[np.float64]], source: str
) -> tuple[dict[str, NDArray[np.float64]], int]:
    """Drop rows identical to the row before (time included): a sample logged twice.  Returns the count."""
    try:
        arrays = [np.array(value, dtype=np.float64, copy=True).ravel() for value in columns.values()]
    except (TypeError, ValueError):
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
        peak = float(np.abs(ds.q).max(initial=0.0))
        if 0.0 < peak <= 2 * np.pi:  # every angle within one turn, as radians are: 57 times too small if so
            warnings.warn(
                f"{source}: degrees were asked for (--degrees), but every angle lies within +-{peak:.3g}, as "
                "angles in radians do; if the file is in radians, drop --degrees (its angles would be read 57 "
                "times too small)",
                DataWarning,
                stacklevel=4,
            )
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
    if ds.m >= MIN_ROWS_DEAD_SENSOR:
        dead = np.ptp(ds.tau, axis=0) == 0
        if dead.any():
            j = int(np.argmax(dead))
            more = f" (and {int(dead.sum()) - 1} more)" if dead.sum() > 1 else ""
            raise DataError(
                f"{source}: tau_{j + 1}{more} holds {ds.tau[0, j]:g} N m in every one of its {ds.m} rows, which no "
                "working torque sensor reads on a moving arm; check that the sensor was logged (a dead or "
                "unplugged channel) and record again"
            )
        _warn_stuck(ds, source)
    return ds


def _warn_stuck(ds: Dataset, source: str) -> None:
    """Warn about a torque column stuck at one value over :data:`STUCK_FRACTION` of the rows while the arm moves.

    A resting arm holds its torque (a noise-free simulation even exactly): only a stretch during which
    some joint moves by more than a milliradian counts.
    """
    need = max(MIN_ROWS_DEAD_SENSOR, int(np.ceil(STUCK_FRACTION * ds.m)))
    for j in range(ds.n):
        column = ds.tau[:, j]
        change = np.flatnonzero(column[1:] != column[:-1]) + 1
        starts = np.concatenate([[0], change])
        stops = np.concatenate([change, [ds.m]])
        k = int(np.argmax(stops - starts))
        a, b = int(starts[k]), int(stops[k])
        if b - a < need or float(np.ptp(ds.q[a:b], axis=0).max()) <= 1e-3:
            continue
        warnings.warn(
            f"{source}: tau_{j + 1} holds {column[a]:g} N m unchanged over rows {a}..{b - 1} ({100 * (b - a) / ds.m:.0f} % "
            "of the recording) while the arm moves, as a torque sensor that stuck does; check joint "
            f"{j + 1}'s channel, and cut those rows out or record again",
            DataWarning,
            stacklevel=4,
        )


MIN_ROWS_DEAD_SENSOR = 20
"""Rows from which a torque column that never changes is refused as a dead sensor."""


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


def _check_robot(ds: Dataset, robot: Any, source: str) -> Dataset:
    """The checks of data against the robot they come from: torque scale (refused), joint range (warned)."""
    return check_joint_range(check_torque_scale(ds, robot, source=source), robot, source=source)


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
    ds.check_joints(robot.n, robot.name)
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


def check_joint_range(ds: Dataset, robot: Any, *, source: str = "the data") -> Dataset:
    """Warn when angles leave the robot's joint limits by more than :data:`RANGE_WARN` of a joint's range.

    A recording strays a little past the limits a description states (its limits are a controller's, set
    inside the mechanical ones); far beyond them the angles carry an offset, a calibration error or come
    from another robot, and the identified model is extrapolated there.  Joints whose limits are not finite
    are not checked.

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

    Warns
    -----
    DataWarning
        One sentence naming the joint that strays furthest, its range, the limits and the other joints.
    """
    if ds.n != robot.n:
        return ds
    q_min, q_max = np.asarray(robot.q_min, dtype=float), np.asarray(robot.q_max, dtype=float)
    span = q_max - q_min
    low, high = ds.q.min(axis=0), ds.q.max(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        beyond = np.maximum(q_min - low, high - q_max) / span
    beyond[~(np.isfinite(span) & (span > 0))] = 0.0
    far = np.flatnonzero(beyond > RANGE_WARN)
    if far.size == 0:
        return ds
    j = int(far[np.argmax(beyond[far])])
    others = [f"q_{k + 1}" for k in far if k != j]
    more = f" (so do {', '.join(others)})" if others else ""
    warnings.warn(
        f"{source}: q_{j + 1} moves over [{low[j]:.4g}, {high[j]:.4g}], {100 * beyond[j]:.0f} % of its range beyond "
        f"the limits [{q_min[j]:.4g}, {q_max[j]:.4g}] of '{robot.name}'{more}; check the joint's offset and "
        "units (rad, m) and that the data were recorded on that robot",
        DataWarning,
        stacklevel=3,
    )
    return ds


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
        The robot the data come from: sets ``n_joints`` and ``robot_name`` when they are not given,
        refuses torques beyond :func:`check_torque_scale` and warns about angles beyond
        :func:`check_joint_range`.
    topic : str, optional
        For a ROS 2 recording (an ``.mcap`` or ``.db3`` file, or a rosbag2 folder with ``metadata.yaml``),
        the ``sensor_msgs/msg/JointState`` topic to read; needed when the bag holds more than one.  Ignored
        for ``.csv`` and ``.npz`` files.  A bag is read by :func:`dynid.data.rosbag.read_rosbag`
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
        When rows identical to the row before (a sample logged twice) were dropped, a torque column
        stuck at one value over :data:`STUCK_FRACTION` of the rows while the arm moves, angles beyond
        :func:`check_joint_range`.
    """
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
        return ds if robot is None else _check_robot(ds, robot, path.name)
    if path.is_dir():  # before the extension: a folder has none to speak of
        raise DataError(
            f"{path} is a folder; give the path of a .csv or .npz dataset file (a ROS 2 rosbag2 folder holds "
            "a metadata.yaml)"
        )
    if path.suffix.lower() not in _EXTENSIONS and not path.exists():  # a mistyped name, a rosbag2 folder not there
        raise DataError(
            f"no file or folder at {path}; give a dataset file (.csv, .npz) or a ROS 2 recording (.mcap, or a "
            "rosbag2 folder) that exists"
        )
    suffix = _check_extension(path)
    if robot is not None:
        n_joints = robot.n if n_joints is None else n_joints
        robot_name = robot.name if robot_name is None else robot_name
    if not path.exists():
        raise DataError(f"no dataset file at {path}; check the path")
    if not path.is_file():  # a device (/dev/zero), a FIFO or a socket: reading it may never end
        raise DataError(
            f"{path} is not a regular file but a device, pipe or socket, which dynid does not read (it may "
            "never end); save the recording to a .csv or .npz file and give that file"
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
    return ds if robot is None else _check_robot(ds, robot, path.name)


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


def truth_sidecar(data: Dataset) -> dict[str, Any] | None:
    """The simulator's record beside a simulated dataset's file (``<data>.truth.json``), or None.

    Parameters
    ----------
    data : Dataset
        The data, read from a file (``meta["source"]``).

    Returns
    -------
    dict or None
        The record (``robot``, ``source``, ``joint_names``, the truth, ...); None without one.
    """
    source = data.meta.get("source")
    if not source:
        return None
    path = Path(str(source))
    sidecar = path.with_name(path.name + ".truth.json")
    if not sidecar.is_file():
        return None
    try:
        doc = json.loads(sidecar.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return doc if isinstance(doc, dict) else None


def simulated_on(robot: Any, data: Dataset) -> str | None:
    """The robot a simulated dataset's sidecar (:func:`truth_sidecar`) names when it is not ``robot``, else
    None (no sidecar, or the same robot).

    Another robot: the sidecar's description differs by its source and its name, and by its joint names
    or its nominal bodies (``params.nominal``). A copy of the description under another file and robot
    name (``arm.urdf``, the UR5's) is the same robot; a UR10 for data simulated on a UR5 (the same joint
    names) or a Kinova's data for an SO-101 are not.

    Parameters
    ----------
    robot : RobotModel
        The robot the data are given for.
    data : Dataset
        The data, read from a file (``meta["source"]``).

    Returns
    -------
    str or None
    """
    side = truth_sidecar(data)
    if side is None:
        return None
    source, name = side.get("source"), side.get("robot")
    if source is None or name is None or source == robot.source or name == robot.name:
        return None
    listed = side.get("joint_names")
    params = side.get("params")
    nominal = params.get("nominal") if isinstance(params, dict) else None
    same_joints = not isinstance(listed, list) or list(listed) == list(robot.joint_names)
    same_bodies = True
    if isinstance(nominal, list):
        mine = np.asarray(robot.params, dtype=np.float64).ravel()
        theirs = np.asarray(nominal, dtype=np.float64).ravel()
        same_bodies = theirs.shape == mine.shape and bool(np.allclose(theirs, mine, rtol=1e-6, atol=1e-9))
    if same_joints and same_bodies:
        return None
    return str(name)
