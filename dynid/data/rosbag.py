"""ROS 2 recordings as datasets: ``sensor_msgs/msg/JointState`` read from a rosbag2 folder or an MCAP file.

A robot under ROS 2 publishes its joint states as ``sensor_msgs/msg/JointState`` messages (names,
positions in rad, velocities in rad/s, efforts in N m), and ``ros2 bag record`` stores them in a rosbag2
folder (``metadata.yaml`` beside ``.db3`` or ``.mcap`` storage files) or in a bare ``.mcap`` file.
:func:`read_rosbag` turns one such topic into a :class:`~dynid.data.dataset.Dataset` in the robot's
joint order; :func:`~dynid.data.files.load_dataset` calls it for every path that
:func:`is_rosbag` recognises, so every command's ``--data`` and ``--heldout`` accept bags.  The bag
is read with the pure-Python ``rosbags`` package (``pip install "dynid[ros]"``), imported only here and
only when a bag is read.

The rules, each said once (a :class:`~dynid.exceptions.DataWarning`) when it applies:

* topic: the one ``JointState`` topic of the bag, or the one named by ``topic`` (``--topic``); several
  ``JointState`` topics and no choice, a topic the bag does not hold, or one of another type are
  refused;
* joints: each message's ``name`` list is mapped to the robot's joint names (any order, which may change
  from message to message; a prefix common to all of them, such as ``ur5_`` or ``left/``, is allowed
  when only one fits, and said); joints the robot does not have (fingers, a gripper) are ignored, and
  messages holding none of the robot's joints are skipped; a robot joint missing from a message is
  refused, and so is a message whose ``position``, ``velocity`` or ``effort`` length differs from its
  ``name`` list (an empty ``velocity`` means not measured; ``effort`` is required);
* time: the header stamps (s, from the first message); when the stamps are zero (a driver that leaves them
  unset) the bag's receive times are used instead.  Messages are put in stamp order (the bag stores
  them in the order they arrived), and a message whose stamp repeats an earlier one is dropped;
* sampling: stamps that are not uniform (to a relative 1e-6) are resampled onto a uniform grid whose
  step is their median interval rounded to the microsecond (:func:`dynid.data.preprocess.resample`):
  linear interpolation of ``q`` and ``tau``, and of ``dq`` only when every message carries velocities
  (otherwise ``dq`` is left out and derived from ``q`` later, as for a CSV without ``dq`` columns).  A gap in the stamps is
  treated as for any file: it splits the data into separate runs and is never interpolated across.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynid._extras import install_hint
from dynid.data.dataset import Dataset
from dynid.data.preprocess import GAP_SECONDS, GAP_STEPS, resample
from dynid.exceptions import DataError, DataWarning

__all__ = ["JOINT_STATE", "ROSBAG_SUFFIXES", "is_rosbag", "read_rosbag"]

#: The message type read.
JOINT_STATE = "sensor_msgs/msg/JointState"

#: File extensions read as ROS 2 storage files (a rosbag2 folder is recognised by its ``metadata.yaml``).
ROSBAG_SUFFIXES = (".mcap", ".db3")



def is_rosbag(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` names a ROS 2 recording: an ``.mcap`` or ``.db3`` file or a rosbag2 folder.

    Parameters
    ----------
    path : str or path-like
        A dataset path (it need not exist for a file name ending in ``.mcap`` or ``.db3``).

    Returns
    -------
    bool
    """
    path = Path(path)
    if path.suffix.lower() in ROSBAG_SUFFIXES:
        return True
    return path.is_dir() and (path / "metadata.yaml").is_file()


def _rosbags() -> tuple[Any, Any, Any]:
    """The rosbags reader class, its error classes and a type store knowing ``JointState``."""
    try:
        from rosbags.rosbag2 import Reader, ReaderError
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise DataError(
            "reading a ROS 2 recording needs the 'rosbags' package, which is not installed; install it "
            f"with {install_hint('ros')}"
        ) from None
    errors: tuple[type[BaseException], ...] = (ReaderError,)
    try:
        from rosbags.serde import SerdeError

        errors = (*errors, SerdeError)
    except ImportError:  # pragma: no cover - older rosbags
        pass
    return Reader, errors, get_typestore(Stores.LATEST)


def _pick_topic(connections: Sequence[Any], topic: str | None, name: str) -> str:
    """The JointState topic to read: ``topic`` checked, or the only one."""
    types: dict[str, set[str]] = {}
    for conn in connections:
        types.setdefault(conn.topic, set()).add(conn.msgtype)
    joint_topics = sorted(t for t, msgtypes in types.items() if JOINT_STATE in msgtypes)
    listed = ", ".join(joint_topics) if joint_topics else "none"
    if topic is not None:
        if topic in joint_topics:
            return topic
        if topic in types:
            raise DataError(
                f"{name}: the topic {topic} holds {', '.join(sorted(types[topic]))}, not {JOINT_STATE}; "
                f"pick a JointState topic with --topic (the bag's: {listed})"
            )
        raise DataError(
            f"{name} has no topic {topic}; its {JOINT_STATE} topics are: {listed}; "
            "give one of them with --topic (topic= in Python)"
        )
    if not joint_topics:
        held = ", ".join(f"{t} ({', '.join(sorted(m))})" for t, m in sorted(types.items())) or "no topics"
        raise DataError(
            f"{name} holds no {JOINT_STATE} messages (it holds {held}); record the robot's joint states "
            "(e.g. ros2 bag record /joint_states)"
        )
    if len(joint_topics) > 1:
        raise DataError(
            f"{name} holds {len(joint_topics)} {JOINT_STATE} topics ({listed}); pick one with --topic NAME "
            "(topic= in Python)"
        )
    return joint_topics[0]


def _stamp_ns(msg: Any) -> int:
    stamp = msg.header.stamp
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def read_rosbag(
    path: str | os.PathLike[str],
    joint_names: Sequence[str],
    *,
    topic: str | None = None,
    robot_name: str | None = None,
) -> Dataset:
    """Read the ``JointState`` messages of a ROS 2 recording as a dataset in the robot's joint order.

    Parameters
    ----------
    path : str or path-like
        A rosbag2 folder (``metadata.yaml`` with ``.db3`` or ``.mcap`` storage), or one ``.mcap`` or
        ``.db3`` storage file.
    joint_names : sequence of str, length n
        The robot's joint names in its joint order (``RobotModel.joint_names``); column ``j`` of the
        dataset is the joint named ``joint_names[j]``.
    topic : str, optional
        The ``JointState`` topic to read; needed when the bag holds more than one.
    robot_name : str, optional
        Robot name for messages.

    Returns
    -------
    Dataset
        ``t`` (s, from the first stamp), ``q`` (rad), ``tau`` (N m, the messages' efforts) and ``dq``
        (rad/s) when every message carries velocities; uniform in time.  ``meta`` records ``source``,
        ``topic``, ``joint_names``, ``stamps`` (``"header"`` or ``"receive"``), ``t0_ns`` (the first
        stamp, ns), ``messages``, and when they apply ``ignored_joints``, ``skipped_messages``,
        ``dropped_repeats``, ``reordered`` and ``resampled``.

    Raises
    ------
    DataError
        ``rosbags`` not installed; a path that is not a readable bag; no, several (without ``topic``) or
        the wrong ``JointState`` topic; a robot joint missing from a message; a message whose arrays do
        not match its names; no efforts; fewer than 2 messages.

    Warns
    -----
    DataWarning
        Joints ignored, receive times used, messages out of order or repeated, stamps resampled, gaps.
    """
    path = Path(path)
    name = path.name or str(path)
    wanted = [str(j) for j in joint_names]
    robot = f"the robot '{robot_name}'" if robot_name else "the robot"
    rosbags = _rosbags()
    _check_bag_path(path)
    read = _read_joint_states(rosbags, path, name, topic, wanted, robot)
    _check_joint_rows(read, name, wanted, robot)
    meta, notes = _joint_notes(read, path, wanted, robot)
    timeline = _timeline(read, name)
    meta = {**meta, **timeline.meta, "t0_ns": int(timeline.ns[0])}
    notes = [*notes, *timeline.notes]
    t = (timeline.ns - timeline.ns[0]).astype(np.float64) * 1e-9
    try:
        ds = Dataset(t, timeline.q, timeline.tau, dq=timeline.dq, meta=meta)
    except DataError as err:
        raise DataError(f"{name}: {err}") from None
    if not ds.is_uniform:
        ds, note = _resample(ds)
        notes.append(note)
    if notes:
        warnings.warn(f"{name} ({read.topic}): " + "; ".join(notes), DataWarning, stacklevel=3)
    return ds


@dataclass(frozen=True)
class _JointRows:
    """The rows read from a bag's JointState topic, and what mapping their names found."""

    topic: str
    stamps: list[int]
    received: list[int]
    q: list[NDArray[np.float64]]
    tau: list[NDArray[np.float64]]
    dq: list[NDArray[np.float64] | None]
    name_lists: list[tuple[str, ...]]
    ignored: list[str]
    prefixes: list[str]
    skipped: int


@dataclass(frozen=True)
class _Timeline:
    """The samples in stamp order (ns) and the meta entries and notes putting them there gave."""

    ns: NDArray[np.int64]
    q: NDArray[np.float64]
    tau: NDArray[np.float64]
    dq: NDArray[np.float64] | None
    meta: dict[str, Any]
    notes: list[str]

    def take(self, index: NDArray[Any], meta: dict[str, Any], note: str) -> _Timeline:
        """The samples at ``index`` (an order or a mask), with one more meta entry and note."""
        return _Timeline(
            self.ns[index],
            self.q[index],
            self.tau[index],
            None if self.dq is None else self.dq[index],
            {**self.meta, **meta},
            [*self.notes, note],
        )


def _check_bag_path(path: Path) -> None:
    """Refuse a path that does not exist or a folder that is not a rosbag2 recording."""
    if not path.exists():
        raise DataError(f"no ROS 2 recording at {path}; check the path")
    if path.is_dir() and not (path / "metadata.yaml").is_file():
        raise DataError(
            f"{path} is a folder without metadata.yaml, not a rosbag2 recording; give the bag folder "
            "ros2 bag record wrote, or its .mcap file"
        )


def _read_joint_states(
    rosbags: tuple[Any, Any, Any], path: Path, name: str, topic: str | None, wanted: list[str], robot: str
) -> _JointRows:
    """Read the chosen JointState topic's messages as rows in the robot's joint order."""
    Reader, errors, store = rosbags
    stamps: list[int] = []
    received: list[int] = []
    rows_q: list[NDArray[np.float64]] = []
    rows_tau: list[NDArray[np.float64]] = []
    rows_dq: list[NDArray[np.float64] | None] = []
    maps: dict[tuple[str, ...], tuple[NDArray[np.intp], tuple[str, ...], str] | None] = {}
    ignored: dict[str, None] = {}
    prefixes: dict[str, None] = {}
    skipped = 0
    try:
        with Reader(path) as reader:
            chosen = _pick_topic(reader.connections, topic, name)
            conns = [c for c in reader.connections if c.topic == chosen and c.msgtype == JOINT_STATE]
            for k, (conn, received_ns, raw) in enumerate(reader.messages(connections=conns)):
                msg = store.deserialize_cdr(raw, conn.msgtype)
                names = tuple(str(n) for n in msg.name)
                if names not in maps:
                    maps[names] = _joint_map(names, wanted, name, chosen, k, robot)
                mapping = maps[names]
                if mapping is None:  # none of the robot's joints: a gripper's own message
                    skipped += 1
                    continue
                index, extra, prefix = mapping
                ignored.update(dict.fromkeys(extra))
                prefixes.update(dict.fromkeys([prefix] if prefix else []))
                position, velocity, effort = (np.asarray(a, dtype=np.float64) for a in
                                              (msg.position, msg.velocity, msg.effort))
                _check_lengths(name, chosen, k, names, position, velocity, effort)
                stamps.append(_stamp_ns(msg))
                received.append(int(received_ns))
                rows_q.append(position[index])
                rows_tau.append(effort[index])
                rows_dq.append(velocity[index] if len(velocity) else None)
    except DataError:
        raise
    except (*errors, OSError, KeyError, ValueError) as err:
        said = (str(err).strip().splitlines() or ["-"])[0]  # a YAML error's first line: no pointer lines
        raise DataError(
            f"{name} could not be read as a ROS 2 recording ({type(err).__name__}: {said}); "
            "give a rosbag2 folder (with metadata.yaml) or an .mcap file written by ros2 bag record"
        ) from None
    return _JointRows(
        chosen, stamps, received, rows_q, rows_tau, rows_dq, list(maps), list(ignored), list(prefixes), skipped
    )


def _check_lengths(
    name: str,
    chosen: str,
    k: int,
    names: tuple[str, ...],
    position: NDArray[np.float64],
    velocity: NDArray[np.float64],
    effort: NDArray[np.float64],
) -> None:
    """Refuse a message whose position, velocity or effort length differs from its name list."""
    for field, values, required in (("position", position, True), ("velocity", velocity, False),
                                    ("effort", effort, True)):
        if len(values) == len(names) or (not required and len(values) == 0):
            continue
        fix = ("efforts are the joint torques dynid identifies from; record them"
               if field == "effort" and len(values) == 0
               else "every message must give one value per name")
        raise DataError(
            f"{name}: message {k} on {chosen} names {len(names)} joints but holds {len(values)} "
            f"{field} values; {fix}"
        )


def _check_joint_rows(read: _JointRows, name: str, wanted: list[str], robot: str) -> None:
    """Refuse a topic none of whose messages names the robot's joints, or with fewer than 2 rows."""
    if not read.stamps and read.name_lists:
        seen = sorted({n for names in read.name_lists for n in names})
        raise DataError(
            f"{name}: no message on {read.topic} names a joint of {robot} (they name {', '.join(seen)}; {robot} "
            f"has {', '.join(wanted)}); give the robot (--robot) the bag was recorded on"
        )
    if len(read.stamps) < 2:
        raise DataError(
            f"{name}: the topic {read.topic} holds {len(read.stamps)} JointState message(s) with the joints of "
            f"{robot}; a dataset needs at least 2 samples, record a longer run"
        )


def _joint_notes(read: _JointRows, path: Path, wanted: list[str], robot: str) -> tuple[dict[str, Any], list[str]]:
    """The dataset's first meta entries and the notes on prefixed names, ignored joints and skipped messages."""
    notes: list[str] = []
    meta: dict[str, Any] = {
        "source": str(path), "topic": read.topic, "joint_names": wanted, "messages": len(read.stamps)
    }
    prefixes, ignored = read.prefixes, read.ignored
    if prefixes:
        meta["joint_prefix"] = list(prefixes) if len(prefixes) > 1 else next(iter(prefixes))
        shown = ", ".join(f"'{p}'" for p in prefixes)
        notes.append(
            f"the joint names carry the prefix {shown} ({next(iter(prefixes))}{wanted[0]} is {wanted[0]})"
        )
    if ignored:
        meta["ignored_joints"] = list(ignored)
        notes.append(
            f"joint {next(iter(ignored))} is not a joint of {robot} and is ignored"
            if len(ignored) == 1
            else f"joints {', '.join(ignored)} are not joints of {robot} and are ignored"
        )
    if read.skipped:
        meta["skipped_messages"] = read.skipped
        notes.append(f"{_count(read.skipped, 'message')} naming none of the robot's joints skipped")
    return meta, notes


def _timeline(read: _JointRows, name: str) -> _Timeline:
    """The rows as arrays on their time stamps, in stamp order and without repeated stamps."""
    timeline = _stack_rows(read)
    timeline = _in_stamp_order(timeline)
    timeline, messages = _drop_repeats(timeline)
    if len(timeline.ns) < 2:
        raise DataError(
            f"{name}: the {messages} JointState messages on {read.topic} all carry one stamp "
            f"({timeline.ns[0] * 1e-9:.9g} s), so they make 1 sample, not a run in time; record with a driver that stamps "
            "each message (a driver that leaves the stamps at zero is read by the bag's receive times)"
        )
    return timeline


def _stack_rows(read: _JointRows) -> _Timeline:
    """The rows as arrays on the header stamps, or on the receive times when header stamps are zero."""
    notes: list[str] = []
    meta: dict[str, Any] = {}
    ns = np.asarray(read.stamps, dtype=np.int64)
    zero = int((ns == 0).sum())
    if zero:
        ns = np.asarray(read.received, dtype=np.int64)
        meta["stamps"] = "receive"
        which = "the header stamps are" if zero == len(ns) else f"{zero} of {len(ns)} header stamps are"
        notes.append(f"{which} zero, so the bag's receive times are used as the time")
    else:
        meta["stamps"] = "header"
    q, tau = np.array(read.q), np.array(read.tau)
    dq = None if any(v is None for v in read.dq) else np.array(read.dq)
    if dq is None and any(v is not None for v in read.dq):
        notes.append("some messages carry no velocities, so dq is left out (it is derived from q)")
    return _Timeline(ns, q, tau, dq, meta, notes)


def _in_stamp_order(timeline: _Timeline) -> _Timeline:
    """The samples sorted by stamp (stable), said when any was stored after a later one."""
    late = int(np.sum(np.diff(timeline.ns) < 0))
    if not late:
        return timeline
    order = np.argsort(timeline.ns, kind="stable")
    note = (f"{_count(late, 'message')} stamped before the message stored ahead of "
            f"{'it' if late == 1 else 'them'}: the messages are put in stamp order")
    return timeline.take(order, {"reordered": late}, note)


def _drop_repeats(timeline: _Timeline) -> tuple[_Timeline, int]:
    """The samples without those repeating the previous stamp, and how many there were before."""
    keep = np.concatenate(([True], np.diff(timeline.ns) > 0))
    if keep.all():
        return timeline, len(keep)
    dropped = int((~keep).sum())
    note = f"{_count(dropped, 'message')} repeating an earlier stamp dropped"
    return timeline.take(keep, {"dropped_repeats": dropped}, note), len(keep)


def _count(k: int, noun: str) -> str:
    return f"{k} {noun}{'' if k == 1 else 's'}"


def _joint_map(
    names: tuple[str, ...], wanted: list[str], source: str, topic: str, k: int, robot: str
) -> tuple[NDArray[np.intp], tuple[str, ...], str] | None:
    """Index of each robot joint in a message's name list, the names the robot lacks and the prefix of its
    joints' names (None: none of its joints)."""
    if len(set(names)) != len(names):
        twice = sorted({n for n in names if names.count(n) > 1})
        raise DataError(
            f"{source}: message {k} on {topic} names joint '{twice[0]}' twice; each joint must appear once"
        )
    position = {n: i for i, n in enumerate(names)}
    prefix = ""
    if not all(j in position for j in wanted):  # a namespace prefix (ur5_, left/) on every joint of the robot
        fits = {n[: -len(wanted[0])] for n in names if n.endswith(wanted[0]) and n != wanted[0]}
        fits = {p for p in fits if all(p + j in position for j in wanted)}
        if len(fits) > 1:
            raise DataError(
                f"{source}: message {k} on {topic} names the joints of {robot} under "
                f"{len(fits)} prefixes ({', '.join(sorted(fits))}), one arm each; dynid reads one arm: "
                "record each arm on its own topic"
            )
        prefix = fits.pop() if fits else ""
    found = [j for j in wanted if prefix + j in position]
    if not found:
        return None
    missing = [j for j in wanted if prefix + j not in position]
    if missing:
        raise DataError(
            f"{source}: message {k} on {topic} has no joint '{missing[0]}' of {robot} (it names "
            f"{', '.join(names)}; {robot} has {', '.join(wanted)}); record all of the robot's joints, or "
            "give the robot (--robot) the bag was recorded on"
        )
    keys = [prefix + j for j in wanted]
    extra = tuple(n for n in names if n not in set(keys))
    return np.array([position[j] for j in keys], dtype=np.intp), extra, prefix


def _resample(ds: Dataset) -> tuple[Dataset, str]:
    """Uniform grid at the median interval (linear); the note that says so."""
    steps = np.diff(ds.t)
    median = float(np.median(steps))
    dt = round(median, 6) if median >= 1e-4 else median  # to the microsecond: 1000 Hz, not 999.7 Hz
    steps = steps[steps <= max(GAP_STEPS * median, GAP_SECONDS)]  # the sampling, not the gaps
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", DataWarning)
        uniform = resample(ds, dt=dt, method="linear")
    gap_notes = [str(w.message) for w in caught if issubclass(w.category, DataWarning)]
    signals = "q, tau and dq" if ds.dq is not None else "q and tau (no dq: not measured)"
    note = (
        f"the stamps are irregular (intervals {steps.min() * 1e3:.4g} to {steps.max() * 1e3:.4g} ms), so "
        f"{signals} are resampled linearly onto a uniform grid at {1.0 / dt:.6g} Hz (the median interval, "
        f"{dt * 1e3:.6g} ms)"
    )
    if gap_notes:
        note += "; " + "; ".join(gap_notes)
    meta = dict(uniform.meta)
    meta["resampled"] = {**meta.get("resampled", {}), "rate_hz": 1.0 / dt}
    return uniform._derive(meta=meta), note
