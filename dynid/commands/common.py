"""Options shared by several subcommands."""

from __future__ import annotations

import argparse
import os
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dynid.exceptions import RobotModelError, UsageError

__all__ = [
    "Output",
    "add_degrees_argument",
    "add_json_argument",
    "add_robot_arguments",
    "add_topic_argument",
    "check_data_fits_model",
    "check_outputs",
    "check_period_option",
    "is_training_data",
    "model_files",
    "output",
    "read_dataset",
    "read_recordings",
    "robot_file",
    "robot_from_args",
    "same_file",
    "training_match",
    "write_figures",
]


def add_robot_arguments(
    parser: argparse.ArgumentParser, *, default: str | None = None, required: bool = True
) -> None:
    """``--robot`` and the joint-limit overrides (``required=False``: ``--robot`` may be left out, as when a
    command takes a model instead)."""
    parser.add_argument(
        "--robot",
        default=default,
        required=required and default is None,
        help="built-in name (ur5, ur10, panda), a URDF file or a modified-DH .toml table"
        + (f" (default {default})" if default else ""),
    )
    for name, unit in (("q-min", "rad"), ("q-max", "rad"), ("dq-max", "rad/s"), ("ddq-max", "rad/s^2")):
        parser.add_argument(
            f"--{name}",
            metavar="V[,V...]",
            help=f"override the model's {name.replace('-', ' ')} limit ({unit}): one value for all joints or one per joint",
        )
    parser.add_argument("--tool", help="URDF frame used as the tool frame (default: the robot's flange)")


def add_degrees_argument(parser: argparse.ArgumentParser) -> None:
    """``--degrees``: the dataset's angles are in degrees (converted to rad when read)."""
    parser.add_argument(
        "--degrees",
        action="store_true",
        help="the dataset's angles (and angular rates) are in degrees: convert them to rad when reading",
    )


def add_topic_argument(parser: argparse.ArgumentParser) -> None:
    """``--topic``: the JointState topic to read from a ROS 2 recording."""
    parser.add_argument(
        "--topic",
        metavar="NAME",
        help="for a ROS 2 recording (.mcap, or a rosbag2 folder), the sensor_msgs/JointState topic to read "
        "(needed when the bag holds several; ignored for .csv and .npz)",
    )


def read_dataset(path: str | os.PathLike[str], n_joints: int | None = None, *, robot_name: str | None = None,
                 degrees: bool = False, topic: str | None = None, joint_names: Sequence[str] | None = None,
                 robot: Any = None, model_path: str | os.PathLike[str] | None = None, option: str = "data"):
    """Read a dataset file for a command, with ``--degrees`` and ``--topic`` passed to the reader.

    Given the robot the data come from, the data are checked against it as
    :func:`dynid.data.files.load_dataset` checks them with ``robot=``: torques beyond the robot's scale
    (mN m, motor current) are refused; with ``model_path`` (the data are to be scored by a model of that
    robot), angles more than half a joint's range outside its limits are refused as
    :func:`check_data_fits_model` does; angles beyond :data:`dynid.data.files.RANGE_WARN` of the range are
    warned about.  Data of another joint count are left to the command, which names both counts.

    Parameters
    ----------
    path : str or path-like
        The dataset file.
    n_joints : int, optional
        Joint count the data must have.
    robot_name : str, optional
        Robot name for messages.
    degrees : bool
        Whether the file's angles are in degrees.
    topic : str, optional
        The JointState topic of a ROS 2 recording.
    joint_names : sequence of str, optional
        The robot's joint names in its order, which map a ROS 2 recording's joints to columns (default
        ``robot.joint_names``).
    robot : RobotModel, optional
        The robot the data come from.
    model_path : str or path-like, optional
        The model file the data are to be scored with (for the half-range refusal and its message).
    option : str
        The option that named the data (``data``, ``heldout``), for the messages.

    Returns
    -------
    Dataset
    """
    import inspect

    from dynid.data.files import check_joint_range, check_torque_scale, load_dataset, simulated_on

    kwargs: dict[str, Any] = {}
    if robot is not None and joint_names is None:
        joint_names = robot.joint_names
    if robot_name is not None:
        kwargs["robot_name"] = robot_name
    if "degrees" in inspect.signature(load_dataset).parameters:
        kwargs["degrees"] = degrees
    elif degrees:
        raise UsageError("--degrees is not available with this dataset reader; give the angles in rad.")
    if topic is not None:
        kwargs["topic"] = topic
    if joint_names is not None:
        kwargs["joint_names"] = tuple(joint_names)
    from dynid._progress import stage

    with stage(f"reading {path}"):
        data = load_dataset(path, n_joints, **kwargs)
    if robot is not None and data.n == robot.n:
        source = Path(path).name
        other = simulated_on(robot, data)
        if other is not None:  # identify, diagnose and export read it as the robot's own otherwise
            raise UsageError(
                f"--{option} {source} was simulated on '{other}' (its {source}.truth.json says so), not on "
                f"'{robot.name}'; give data of '{robot.name}', or the robot the data were simulated on."
            )
        check_torque_scale(data, robot, source=source)
        if model_path is not None:
            _check_fits_robot(robot, data, model_path=model_path, data_option=option)
        check_joint_range(data, robot, source=source)
    return data


def read_recordings(paths: Sequence[str | os.PathLike[str]], n_joints: int | None = None, **read: Any):
    """The recordings of ``--data`` as one dataset of runs, and each as read (``(data, ())`` for one file).

    Each file is read by :func:`read_dataset` (``n_joints`` and ``read`` passed on).  Several are joined
    with :meth:`dynid.data.dataset.Dataset.concat`: filters and derivatives never cross from one into the
    next, and recordings at different rates are resampled onto one grid by the preprocessing, as an
    irregular recording is.  Refused in one sentence: a file named twice, before any is read (its samples
    would count twice in the fit and halve its standard deviations), and recordings with different
    signals (a measured velocity or acceleration in one and not in another), naming both files.

    Parameters
    ----------
    paths : sequence of path-like
        The files given.
    n_joints : int, optional
        Joint count the data must have.
    **read
        Keyword arguments of :func:`read_dataset`.

    Returns
    -------
    data : Dataset
        The recording, or the recordings joined.
    parts : tuple of Dataset
        The recordings as read when several were given, else empty.
    """
    from dynid.data.dataset import Dataset

    for i, a in enumerate(paths):
        for b in paths[i + 1 :]:
            if same_file(a, b):
                named = f"'{a}'" if str(a) == str(b) else f"('{a}', '{b}')"
                raise UsageError(f"--data names one file twice {named}; each recording counts once: give it once.")
    parts = [read_dataset(path, n_joints, **read) for path in paths]
    if len(parts) == 1:
        return parts[0], ()
    labels = {"dq": "measured velocities (dq_i)", "ddq": "measured accelerations (ddq_i)"}
    has = [{name for name in labels if getattr(p, name) is not None} for p in parts]
    richest = max(range(len(parts)), key=lambda i: len(has[i]))
    for k, signals in enumerate(has):
        missing = has[richest] - signals
        if missing:
            what = " and ".join(labels[name] for name in labels if name in missing)
            raise UsageError(
                f"--data: '{paths[richest]}' has {what} and '{paths[k]}' has not; recordings identified "
                "together need the same signals: give them in every recording or in none."
            )
    return Dataset.concat(parts), tuple(parts)


def check_data_fits_model(model: Any, data: Any, *, model_path: Any, data_option: str) -> None:
    """Refuse data that cannot come from the robot a model was identified for.

    The rule: no joint's angles may leave the model robot's limits by more than half the joint's
    range (a joint without finite limits is not checked; another joint count is left to the
    evaluation, which names both counts).  Data of another robot, or angles in degrees, fail it; a
    recording that strays a little past the limits does not.

    Parameters
    ----------
    model : IdentifiedModel
        The model, with the robot it was identified for.
    data : Dataset
        The data it is to be evaluated on.
    model_path : str or path-like
        The model file, for the message.
    data_option : str
        The option that named the data (``data``, ``heldout``), for the message.

    Raises
    ------
    UsageError
        One sentence naming the joint, the range found and the limits.
    """
    _check_fits_robot(model.robot, data, model_path=model_path, data_option=data_option)


def _check_fits_robot(robot: Any, data: Any, *, model_path: Any, data_option: str) -> None:
    """:func:`check_data_fits_model` on the model's robot."""
    import numpy as np

    q = np.asarray(data.q, dtype=float)
    if q.ndim != 2 or q.shape[1] != robot.n or q.shape[0] == 0:
        return  # another joint count: the evaluation itself refuses it, naming both counts
    q_min, q_max = np.asarray(robot.q_min, dtype=float), np.asarray(robot.q_max, dtype=float)
    low, high = np.nanmin(q, axis=0), np.nanmax(q, axis=0)
    for j in range(robot.n):
        if not (np.isfinite(q_min[j]) and np.isfinite(q_max[j])):
            continue
        margin = 0.5 * (q_max[j] - q_min[j])
        if low[j] < q_min[j] - margin or high[j] > q_max[j] + margin:
            raise UsageError(
                f"--{data_option} moves joint {j + 1} over [{low[j]:.4g}, {high[j]:.4g}], more than half its range "
                f"outside the limits [{q_min[j]:.4g}, {q_max[j]:.4g}] of '{robot.name}', the robot {model_path} "
                "was identified for; give data recorded on that robot with angles in rad (--degrees converts "
                "degrees), or the model identified on the robot that recorded them."
            )


def check_period_option(period: float | None, option: str = "--period") -> None:
    """Refuse a ``--period`` that is not a positive, finite number of seconds (None: not given)."""
    import math

    if period is not None and not (period > 0 and math.isfinite(period)):
        raise UsageError(f"{option} is {period}; give the period of the motion in seconds (> 0).")


def is_training_data(model: Any, data: Any) -> bool:
    """Whether ``data`` are, sample for sample, data ``model`` was identified on (:func:`training_match`)."""
    return training_match(model, data) is not None


def training_match(model: Any, data: Any) -> str | None:
    """Whether ``data`` are, sample for sample, the data ``model`` was identified on: ``"whole"`` (its
    training recording), ``"part"`` (one of the recordings it was identified on together) or None.

    A model file records the sha256 of its training recording's time stamps, angles and torques
    (``data_sha256``, :func:`dynid.identify.model.data_fingerprint`), and of each recording it was
    identified on together (``data_parts_sha256``, ``dynid identify --data A.csv B.csv``).  Files
    written before it: what the fit saw, the samples kept (``n_samples``) and the range of the torque as
    fitted (``torque_range``, per joint); the data, prepared as the model prepares them, give both again
    (to 1e-9) in practice only when they are the training data (a payload identified later widens the
    range, and such a model is not matched).

    Parameters
    ----------
    model : IdentifiedModel
        The model (a simulator's description, which was not fitted, never matches).
    data : Dataset
        The data to score it on.

    Returns
    -------
    str or None
    """
    import numpy as np

    from dynid.exceptions import DynidError

    info = getattr(model, "info", None) or {}
    if isinstance(info.get("data_sha256"), str):
        from dynid.identify.model import data_fingerprint

        fingerprint = data_fingerprint(data)
        if info["data_sha256"] == fingerprint:
            return "whole"
        return "part" if fingerprint in (info.get("data_parts_sha256") or []) else None
    seen, count = info.get("torque_range"), info.get("n_samples")
    if seen is None or count is None or data.n != model.robot.n:
        return None
    try:
        prep = model.prepare(data)
    except DynidError:
        return None
    if len(prep.rows) != int(count):
        return None
    tau = prep.tau_reference
    now = np.stack([tau.min(axis=0), tau.max(axis=0)], axis=1)
    seen = np.asarray(seen, dtype=float)
    same = now.shape == seen.shape and bool(np.allclose(now, seen, rtol=1e-9, atol=1e-12))
    return "whole" if same else None


def robot_file(args: argparse.Namespace) -> str | None:
    """The file ``--robot`` names (a URDF or a table), or None for a built-in name."""
    robot = getattr(args, "robot", None)
    return robot if robot is not None and Path(robot).is_file() else None


def add_json_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", metavar="FILE", help="also write the figures as JSON to FILE")


def write_figures(path: str | os.PathLike[str] | None, figures: Any) -> None:
    """Write a command's figures to ``--json FILE`` (strict JSON, atomically), if a file was given.

    Parameters
    ----------
    path : str, path-like or None
        The ``--json`` file; None writes nothing.
    figures : Any
        The figures; non-finite numbers are written as ``null``.

    Raises
    ------
    UsageError
        If the folder of ``path`` does not exist.
    """
    if path is None:
        return
    from dynid._io import write_json

    path = Path(path)
    if not path.parent.is_dir():
        raise UsageError(f"the folder '{path.parent}' does not exist; create it or write elsewhere.")
    write_json(path, figures)


def _floats(option: str, text: str | None):
    if text is None:
        return None
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise RobotModelError(
            f"--{option} is '{text}'; give numbers separated by commas, e.g. --{option} 2.0 or --{option} 1,1,2,2,3,3."
        ) from None
    return values[0] if len(values) == 1 else values


def robot_from_args(args: argparse.Namespace):
    """Load the robot named by ``--robot`` with the limit overrides applied."""
    from dynid.symbolic.robot import load_robot

    return load_robot(
        args.robot,
        q_min=_floats("q-min", args.q_min),
        q_max=_floats("q-max", args.q_max),
        dq_max=_floats("dq-max", args.dq_max),
        ddq_max=_floats("ddq-max", args.ddq_max),
        tool=args.tool,
    )


# ---------------------------------------------------------------------------- outputs
@dataclass(frozen=True)
class Output:
    """One output of a command, as :func:`check_outputs` checks it.

    Parameters
    ----------
    option : str
        The option naming it, without dashes (``out``, ``json``, ...).
    path : Path
        The file (or folder) given.
    suffixes : tuple of str
        Extensions accepted (lower case, with the dot); empty accepts any.
    folder : bool
        Whether the output is a folder.
    replace : bool
        Whether that folder is replaced as a whole (it must then hold no input, and, when it exists, be
        empty or a folder this command wrote before: one holding ``marker``).
    marker : str
        For a replaced folder: the file name by which an earlier run of the command is recognised.
    also : tuple of Path
        Other files it writes beside ``path`` (a model's ``.npz``, a dataset's ``.truth.json``).
    hint : str
        What the file is, added to a wrong extension's message (e.g. ``the model is JSON``).
    """

    option: str
    path: Path
    suffixes: tuple[str, ...] = ()
    folder: bool = False
    replace: bool = False
    also: tuple[Path, ...] = ()
    hint: str = ""
    marker: str = ""

    @property
    def writes(self) -> tuple[Path, ...]:
        return (self.path, *self.also)


def output(
    option: str,
    path: str | os.PathLike[str] | None,
    suffixes: Sequence[str] = (),
    *,
    folder: bool = False,
    replace: bool = False,
    also: Sequence[str | os.PathLike[str]] = (),
    hint: str = "",
    marker: str = "",
) -> Output | None:
    """An :class:`Output` for :func:`check_outputs`, or None when the option was not given."""
    if path is None:
        return None
    return Output(
        option,
        Path(path),
        tuple(s.lower() for s in suffixes),
        folder,
        replace,
        tuple(Path(a) for a in also),
        hint,
        marker,
    )


def model_files(path: str | os.PathLike[str]) -> tuple[Path, Path]:
    """The two files of a model: ``M.json`` and its arrays ``M.npz``."""
    path = Path(path)
    return path, path.with_suffix(".npz")


def _real(path: Path) -> str:
    return os.path.normcase(os.path.realpath(path))


def _same(a: Path, b: Path) -> bool:
    """Whether two paths name one file (a symbolic or hard link included)."""
    if _real(a) == _real(b):
        return True
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def same_file(a: str | os.PathLike[str], b: str | os.PathLike[str]) -> bool:
    """Whether two paths name one file (a symbolic or hard link included), existing or not.

    Parameters
    ----------
    a, b : str or path-like
        The paths.
    """
    return _same(Path(a), Path(b))


def _inside(path: Path, folder: Path) -> bool:
    inner, outer = _real(path), _real(folder)
    return inner == outer or inner.startswith(outer.rstrip(os.sep) + os.sep)


def _probe(folder: Path, option: str, target: Path) -> None:
    """Create and remove a temporary file in ``folder``: a place that cannot be written is named now."""
    try:
        fd, name = tempfile.mkstemp(dir=folder, prefix=".dynid-probe.", suffix=".tmp")
    except OSError as err:
        raise UsageError(
            f"cannot write --{option} '{target}': the folder '{folder}' is not writable ({err.strerror or err}); "
            "write elsewhere or make the folder writable."
        ) from None
    os.close(fd)
    Path(name).unlink(missing_ok=True)


def _check_replaced_folder(out: Output) -> None:
    """A folder replaced as a whole must not hold the working folder, nor files this command did not write."""
    path, option = out.path, out.option
    if _inside(Path.cwd(), path):
        raise UsageError(
            f"--{option} '{path}' is replaced as a whole, and it holds the current folder; give a new folder, "
            f"e.g. --{option} {path.name if path.name not in ('', '.', '..') else 'out'}/results."
        )
    entries = sorted(p.name for p in path.iterdir())
    if not entries:
        return
    listed = _listed_files(path / out.marker) if out.marker else None
    foreign = [e for e in entries if listed is None or (e not in listed and e != out.marker)]
    if foreign:
        raise UsageError(
            f"--{option} '{path}' is replaced as a whole, and it holds files this command did not write "
            f"(e.g. '{foreign[0]}'); give a new or empty folder."
        )


def _listed_files(marker: Path) -> set[str] | None:
    """The file names a command's marker (its manifest or summary JSON) says it wrote; None if it lists none."""
    import json

    try:
        doc = json.loads(marker.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    files = doc.get("files") if isinstance(doc, dict) else None
    if not isinstance(files, list) or not all(isinstance(f, str) for f in files):
        return None
    return set(files)


def _check_one(out: Output) -> None:
    path, option = out.path, out.option
    if out.folder:
        if path.exists() and not path.is_dir():
            raise UsageError(f"--{option} '{path}' is a file; give a folder.")
        if out.replace and path.is_symlink():
            raise UsageError(
                f"--{option} '{path}' is a symbolic link (to '{os.readlink(path)}'), but the folder is replaced "
                f"as a whole, link included; give the folder itself: --{option} {os.path.realpath(path)}."
            )
    else:
        if out.suffixes and path.suffix.lower() not in out.suffixes:
            what = f" ({out.hint})" if out.hint else ""
            raise UsageError(
                f"--{option} '{path}' has the extension '{path.suffix}'; give a file name ending in "
                f"{' or '.join(out.suffixes)}{what}."
            )
        for written in out.writes:
            if written.is_dir():
                name = "is a folder" if written == path else f"writes '{written}', which is a folder"
                raise UsageError(f"--{option} '{path}' {name}; give a file name.")
    parent = path.parent
    if not parent.is_dir():
        raise UsageError(
            f"the folder '{parent}' does not exist, so --{option} '{path}' cannot be written; create it or "
            "write elsewhere."
        )
    _probe(path if out.folder and path.is_dir() else parent, option, path)


def check_outputs(
    outputs: Sequence[Output | None],
    inputs: Mapping[str, str | os.PathLike[str] | Sequence[str | os.PathLike[str]] | None] | None = None,
) -> None:
    """Check every output of a command before any work starts; the one output-path check of dynid.

    An input that is a folder where a file is read (any but a dataset, which may be a rosbag2 folder)
    is refused.  An output is refused when its extension is not one it may have, when a folder is given
    for a file (or a file for a folder), when its folder does not exist or cannot be written (a temporary
    file is created there and removed), when it would overwrite an input of the same command (or, for a
    folder that is replaced, hold one), and when two outputs would write the same file.

    Parameters
    ----------
    outputs : sequence of Output or None
        The command's outputs (None: an option not given).
    inputs : mapping, optional
        Option name (without dashes) -> the file(s) it reads; a model input names both its files.

    Raises
    ------
    UsageError
        One sentence: what is wrong with which option, and the fix.
    """
    given = [o for o in outputs if o is not None]
    files: list[tuple[str, Path]] = []
    for option, value in (inputs or {}).items():
        if value is None:
            continue
        values = [value] if isinstance(value, str | os.PathLike) else list(value)
        for item in values:
            files.extend((option, Path(p)) for p in (model_files(item) if option in _MODEL_INPUTS else (item,)))
            if option not in _DATA_INPUTS and Path(item).is_dir():  # a dataset may be a rosbag2 folder
                raise UsageError(f"--{option} '{item}' is a folder; give the file itself.")
    for out in given:
        _check_one(out)
        for option, source in files:
            if out.folder and out.replace and _inside(source, out.path):
                raise UsageError(
                    f"--{out.option} '{out.path}' is replaced as a whole, and it holds the --{option} file "
                    f"'{source}'; give another folder."
                )
            for written in out.writes:
                if _same(written, source):
                    also = "" if written == out.path else f" (it writes '{written}' too)"
                    raise UsageError(
                        f"--{out.option} '{out.path}' would overwrite the --{option} file '{source}'{also}; "
                        "give the output another name."
                    )
        if out.folder and out.replace and out.path.is_dir():
            _check_replaced_folder(out)
    seen: dict[str, Output] = {}
    for out in given:
        for written in out.writes:
            key = _real(written)
            other = seen.get(key)
            if other is not None and other is not out:
                raise UsageError(
                    f"--{other.option} '{other.path}' and --{out.option} '{out.path}' would both write "
                    f"'{written}'; give them different names."
                )
            seen[key] = out


_MODEL_INPUTS = ("model", "compare")
_DATA_INPUTS = ("data", "heldout", "reference")
