"""URDF and MuJoCo (MJCF) descriptions read through Pinocchio's parsers into a :class:`RobotModel`.

Before the parser sees a URDF, what it would take silently or crash on is refused (mimic joints, loops,
limits that are not limits), continuous joints become revolute ones of :data:`CONTINUOUS_RANGE`; after it,
joint placements within :data:`SNAP_RAD` of a right angle and offsets below :data:`SNAP_M` are snapped to
what CAD meant, so that the base parameters are those of the exact arm.
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
import tempfile
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np

from dynid.exceptions import RobotModelError, RobotModelWarning
from dynid.symbolic.robot_model import DEFAULT_DDQ_MAX, Joint, RobotModel

__all__ = [
    "CONTINUOUS_RANGE",
    "SNAP_M",
    "SNAP_RAD",
    "load_mjcf",
    "load_urdf",
    "pin_model_from_urdf",
    "snapped_angle",
    "warn_snapped",
]

_JOINT_TYPES = {
    "JointModelRX": "RX",
    "JointModelRY": "RY",
    "JointModelRZ": "RZ",
    "JointModelRUBX": "RX",  # continuous joints: one angle, no wrap-around in identification
    "JointModelRUBY": "RY",
    "JointModelRUBZ": "RZ",
    "JointModelPX": "PX",
    "JointModelPY": "PY",
    "JointModelPZ": "PZ",
    "JointModelRevoluteUnaligned": "RU",
    "JointModelPrismaticUnaligned": "PU",
}


SNAP_RAD = 1e-4
"""A joint placement or axis within this angle (rad) of a right-angle orientation is snapped to it."""
SNAP_M = 1e-6
"""A joint offset component below this length (m) is snapped to 0."""
_QUIET_SNAP_RAD = 1e-6  # snaps smaller than this (pi/2 written as 1.5707963) need no warning
# Below these the value is exact as written (float noise of a file's 9 decimals, 5e-10 rad at most): left as it
# is, so that a robot's key, and the model files identified on it, do not change
_EXACT_RAD = 1e-7
_EXACT_M = 1e-9


def snapped_angle(value: float) -> tuple[float, float]:
    """An angle (rad) and the change: snapped to the nearest multiple of pi/2 when within :data:`SNAP_RAD`
    of it (a datasheet's 1.5708), else as given (float noise of an exact value, below 1e-7 rad, included).

    Parameters
    ----------
    value : float
        The angle as written.

    Returns
    -------
    angle : float
    change : float
        ``|angle - value|`` (0 when left as given).
    """
    right = (math.pi / 2) * round(float(value) / (math.pi / 2))
    off = abs(float(value) - right)
    return (right, off) if _EXACT_RAD < off <= SNAP_RAD else (float(value), 0.0)


def _snap_rotation(R: np.ndarray) -> tuple[np.ndarray, float]:
    """The nearest right-angle orientation (a signed permutation, det +1) and the angle to it (rad).

    Returns ``(R, 0.0)`` unchanged when no such orientation lies within :data:`SNAP_RAD`.
    """
    S = np.round(R)
    if not (np.all(np.abs(S).sum(axis=0) == 1) and np.all(np.abs(S).sum(axis=1) == 1)) or np.linalg.det(S) < 0.5:
        return R, 0.0
    A = S.T @ R  # the rotation from the right-angle orientation to R; its angle, accurate when tiny:
    skew = np.array([A[2, 1] - A[1, 2], A[0, 2] - A[2, 0], A[1, 0] - A[0, 1]])
    angle = float(np.arctan2(np.linalg.norm(skew) / 2.0, (np.trace(A) - 1.0) / 2.0))
    if angle <= _EXACT_RAD or angle > SNAP_RAD:  # exact as written (float noise), or no right angle meant
        return R, 0.0
    return S, angle


def _snap_axis(axis: np.ndarray) -> tuple[np.ndarray, float]:
    """The nearest principal direction of a unit axis and the angle to it, within :data:`SNAP_RAD`."""
    a = np.asarray(axis, dtype=float)
    k = int(np.argmax(np.abs(a)))
    e = np.zeros(3)
    e[k] = np.sign(a[k])
    off = np.delete(a, k)
    angle = float(np.arctan2(np.linalg.norm(off), abs(a[k])))
    if angle <= _EXACT_RAD or angle > SNAP_RAD:
        return a, 0.0
    return e, angle


def _snapped(joints: list[Joint], source: str) -> list[Joint]:
    """Joints as CAD meant them: rounded right angles and sub-micrometre offsets snapped, with a warning.

    A CAD export writes pi/2 as 1.5708: the joint axes are then 3.7e-6 rad off parallel or
    perpendicular, the regressor's columns that are dependent on the exact arm are only nearly so, and
    the base parameters become huge, ill-determined combinations (1,110 kg m^2 on a 10 N m arm).
    Snapping keeps the exact arm's base parameters; the change is far below any arm's real tolerance.
    """
    out, moved = [], []
    for j in joints:
        R, a_rot = _snap_rotation(j.rotation)
        axis, a_axis = _snap_axis(j.axis) if j.kind in ("RU", "PU") else (j.axis, 0.0)
        t = np.where((np.abs(j.translation) < SNAP_M) & (np.abs(j.translation) > _EXACT_M), 0.0, j.translation)
        if R is not j.rotation or axis is not j.axis or not np.array_equal(t, j.translation):
            moved.append((j.name, max(a_rot, a_axis)))  # an offset alone: 0 rad
            j = replace(j, rotation=R, axis=axis, translation=t)
        out.append(j)
    warn_snapped(source, [name for name, _ in moved], max((a for _, a in moved), default=0.0))
    return out


def warn_snapped(source: str, joints: list[str], worst: float, *, offsets: bool = True, by: str = "CAD exports") -> None:
    """The one warning of a description whose rounded right angles (and, with ``offsets``, sub-micrometre
    offsets) were snapped: the joints, the largest change (rad) and what to write instead.  Silent when the
    largest change is at most 1e-6 rad (values written to 7 decimals or better are the exact
    ones).

    Parameters
    ----------
    source : str
        The description's path (named once, absolute, when it is a file) or name.
    joints : list of str
        The joints snapped.
    worst : float
        The largest change (rad).
    offsets : bool
        Whether offsets were snapped too (a URDF's; a DH table's angles alone).
    by : str
        Who writes such values (CAD exports, datasheets).
    """
    if worst <= _QUIET_SNAP_RAD:
        return
    if os.path.isfile(source):  # one path per file (a model and its --compare name it from two folders)
        source = os.path.normpath(os.path.abspath(source))
    zero = f" or {SNAP_M:g} m of zero" if offsets else ""
    warnings.warn(
        f"the robot description '{source}' places joint(s) {', '.join(joints)} within {SNAP_RAD:g} rad of a "
        f"right angle{zero} (rounded values, as {by} write them; largest change {worst:.2g} rad); dynid snapped "
        "them, so that the base parameters are those of the exact arm. Write the exact values in the file to "
        "silence this.",
        RobotModelWarning,
        stacklevel=5,
    )


def _from_pin_model(model, *, name: str, source: str, tool: str | None, ddq_max) -> RobotModel:
    """Canonical tree of a numeric Pinocchio model (URDF import)."""
    import pinocchio as pin

    if model.nq != model.nv:
        raise RobotModelError(
            f"the model '{source}' has nq != nv; dynid handles arms with single-DOF joints only."
        )
    joints = []
    params = []
    for i in range(1, model.njoints):
        short = model.joints[i].shortname()
        kind = _JOINT_TYPES.get(short)
        if kind is None:
            raise RobotModelError(
                f"joint '{model.names[i]}' of '{source}' is a {short}; dynid supports revolute, continuous "
                "and prismatic joints, make the others fixed."
            )
        axis = np.array([0.0, 0.0, 1.0])
        if kind in ("RU", "PU"):
            axis = np.array(model.joints[i].extract().axis, dtype=float)
        placement = model.jointPlacements[i]
        joints.append(
            Joint(
                name=model.names[i],
                kind=kind,
                parent=int(model.parents[i]),
                rotation=np.array(placement.rotation),
                translation=np.array(placement.translation),
                axis=axis,
            )
        )
        params.append(np.array(model.inertias[i].toDynamicParameters()))
    joints = _snapped(joints, source)
    n = len(joints)
    # Tool frame: the named frame, else the last frame in the model.
    frame_id = None
    if tool is not None and not model.existFrame(tool):
        kinds = (pin.FrameType.BODY, pin.FrameType.OP_FRAME)
        names = [f.name for f in model.frames if f.type in kinds and f.name != "universe"]
        shown = ", ".join(names[-16:]) + (f" (and {len(names) - 16} more)" if len(names) > 16 else "")
        raise RobotModelError(
            f"the model '{source}' has no frame '{tool}'; give --tool one of its frames: {shown}."
        )
    if tool is not None:
        frame_id = model.getFrameId(tool)
    elif tool is None and len(model.frames) > 1:
        frame_id = len(model.frames) - 1
    if frame_id is not None:
        frame = model.frames[frame_id]
        tool_name, tool_parent = frame.name, int(frame.parentJoint)
        tool_rot, tool_pos = np.array(frame.placement.rotation), np.array(frame.placement.translation)
    else:
        tool_name, tool_parent, tool_rot, tool_pos = "tool", n, np.eye(3), np.zeros(3)
    q_min = np.array(model.lowerPositionLimit, dtype=float)
    q_max = np.array(model.upperPositionLimit, dtype=float)
    # Missing limits (a URDF's continuous joints arrive as revolute ones of +-CONTINUOUS_RANGE): half a turn
    # either way.
    unbounded = ~np.isfinite(q_min) | ~np.isfinite(q_max) | (q_min >= q_max) | (np.abs(q_min) > 1e10)
    q_min[unbounded], q_max[unbounded] = -math.pi, math.pi
    dq_max = np.array(model.velocityLimit, dtype=float)
    dq_max[~np.isfinite(dq_max) | (dq_max <= 0) | (dq_max > 1e10)] = math.pi
    ddq = np.full(n, DEFAULT_DDQ_MAX) if ddq_max is None else np.asarray(ddq_max, dtype=float)
    armature = np.array(model.armature, dtype=float) if len(model.armature) == n else np.zeros(n)
    del pin
    return RobotModel(
        name=name,
        source=source,
        joints=tuple(joints),
        params=np.concatenate(params),
        armature=armature,
        gravity=np.array(model.gravity.linear, dtype=float),
        tool_name=tool_name,
        tool_parent=tool_parent,
        tool_rotation=tool_rot,
        tool_translation=tool_pos,
        q_min=q_min,
        q_max=q_max,
        dq_max=dq_max,
        ddq_max=ddq,
    )


class _Captured:
    text = ""


@contextlib.contextmanager
def _captured_stderr() -> Iterator[_Captured]:
    """Catch what C++ libraries print on file descriptor 2 (urdfdom's parse errors)."""
    said = _Captured()
    try:
        fd = sys.stderr.fileno()
    except (AttributeError, OSError, ValueError):  # no real stderr (e.g. captured by a host)
        yield said
        return
    sys.stderr.flush()
    saved = os.dup(fd)
    with tempfile.TemporaryFile(mode="w+b") as tmp:
        os.dup2(tmp.fileno(), fd)
        try:
            yield said
        finally:
            os.dup2(saved, fd)
            os.close(saved)
            tmp.seek(0)
            said.text = tmp.read().decode(errors="replace")


def load_urdf(path: Path, *, name: str, source: str, lock=(), tool=None, ddq_max=None) -> RobotModel:
    """A URDF file read by Pinocchio's parser, the joints in ``lock`` fixed, ``tool`` the tool frame (default the
    last frame), ``ddq_max`` the acceleration limits (default :data:`DEFAULT_DDQ_MAX`); inertias unchecked."""
    import pinocchio as pin

    if not path.is_file():
        raise RobotModelError(
            f"the URDF file '{path}' does not exist; give the path of an existing .urdf file."
        )
    _check_urdf_xml(path, lock)
    text = _continuous_as_revolute(path, lock)
    try:
        with _captured_stderr() as said:
            model = pin.buildModelFromUrdf(str(path)) if text is None else pin.buildModelFromXML(text)
    except (ValueError, RuntimeError) as exc:
        lines = [ln.strip() for ln in (said.text or str(exc)).splitlines() if ln.strip().startswith("Error")]
        first = lines[0].removeprefix("Error:").strip() if lines else str(exc).strip().splitlines()[0]
        raise RobotModelError(
            f"the URDF file '{path}' could not be read ({first}); check that it is a well-formed URDF."
        ) from None
    if lock:
        ids = [model.getJointId(j) for j in lock]
        model = pin.buildReducedModel(model, ids, pin.neutral(model))
    if model.nv == 0:
        raise RobotModelError(f"the URDF file '{path}' has no movable joint; give an arm with at least one.")
    return _from_pin_model(model, name=name, source=source, tool=tool, ddq_max=ddq_max)


CONTINUOUS_RANGE = 2 * math.pi
"""The position range (rad, each way) a continuous joint is identified with: one full turn."""


def pin_model_from_urdf(path: str | os.PathLike[str]):
    """Pinocchio's model of a URDF as dynid reads it: continuous joints as revolute joints (one angle
    each, :data:`CONTINUOUS_RANGE`), no warning (for files dynid wrote or has read already)."""
    import pinocchio as pin

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RobotModelWarning)
        text = _continuous_as_revolute(Path(path))
    return pin.buildModelFromUrdf(str(path)) if text is None else pin.buildModelFromXML(text)


def _continuous_as_revolute(path: Path, lock=()) -> str | None:
    """The URDF's text with its continuous joints as revolute joints of range +-:data:`CONTINUOUS_RANGE`
    (their velocity and effort limits kept), with a warning; None when it has none.

    Pinocchio models a continuous joint by the cosine and sine of its angle (two configuration numbers
    for one velocity); the identification needs one angle per joint, which a revolute joint without a
    meaningful stop is.
    """
    try:
        tree = ET.parse(path)
    except (ET.ParseError, OSError):
        return None
    names = []
    for joint in tree.getroot().iter("joint"):
        if joint.get("type") != "continuous" or joint.get("name") in lock:
            continue
        names.append(joint.get("name", "?"))
        joint.set("type", "revolute")
        limit = joint.find("limit")
        if limit is None:
            limit = ET.SubElement(joint, "limit", {"effort": "0", "velocity": str(math.pi)})
        limit.set("lower", repr(-CONTINUOUS_RANGE))
        limit.set("upper", repr(CONTINUOUS_RANGE))
    if not names:
        return None
    warnings.warn(
        f"the URDF file '{path}' has the continuous joint(s) {', '.join(names)}: dynid identifies them as "
        f"revolute joints with a range of +-{CONTINUOUS_RANGE:.4g} rad (one turn each way) for the "
        "excitation and the range checks; give them <limit lower upper> of their own (type revolute) for "
        "another range.",
        RobotModelWarning,
        stacklevel=3,
    )
    return ET.tostring(tree.getroot(), encoding="unicode")


def load_mjcf(path: Path, *, name: str, source: str, tool=None) -> RobotModel:
    """A MuJoCo MJCF read by Pinocchio's parser (bodies, joints, limits, armature)."""
    import pinocchio as pin

    if not path.is_file():
        raise RobotModelError(
            f"the MJCF file '{path}' does not exist; give the path of an existing MuJoCo .xml file."
        )
    try:
        with _captured_stderr() as said:
            model = pin.buildModelFromMJCF(str(path))
    except (ValueError, RuntimeError) as exc:
        lines = [ln.strip() for ln in (said.text or str(exc)).splitlines() if ln.strip()]
        first = lines[0] if lines else type(exc).__name__
        raise RobotModelError(
            f"the file '{path}' could not be read as a MuJoCo MJCF ({first}); give a MuJoCo model of the arm."
        ) from None
    if model.nv == 0:
        raise RobotModelError(f"the MJCF file '{path}' has no movable joint; give an arm with at least one.")
    return _from_pin_model(model, name=name, source=source, tool=tool, ddq_max=None)


def _check_urdf_xml(path: Path, lock=()) -> None:
    """Refuse what Pinocchio's URDF parser would take silently, or crash on, before it sees the file.

    * a movable joint that mimics another (dynid does not model them);
    * a link tree that is not a tree: a joint whose child is the root link or one of its own ancestors
      (a loop; Pinocchio's parser crashes on it), a link that is the child of two joints;
    * limits that are not limits: ``lower`` above ``upper``, a ``velocity`` that is zero, negative or not
      finite (Pinocchio's import would replace them with +-pi and pi rad/s, where a TOML table or the
      command line refuse the same values).
    """
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError):
        return  # the URDF parser names the problem
    parent_of: dict[str, tuple[str, str]] = {}  # child link -> (joint, parent link)
    for joint in root.iter("joint"):
        name = joint.get("name", "?")
        kind = joint.get("type")
        parent, child = joint.find("parent"), joint.find("child")
        if parent is not None and child is not None:
            child_link, parent_link = child.get("link", ""), parent.get("link", "")
            if child_link in parent_of:
                raise RobotModelError(
                    f"link '{child_link}' of the URDF file '{path}' is the child of two joints, "
                    f"'{parent_of[child_link][0]}' and '{name}'; a URDF is a tree, so give each link one "
                    "parent joint."
                )
            parent_of[child_link] = (name, parent_link)
        if kind == "fixed" or name in lock:
            continue
        mimic = joint.find("mimic")
        if mimic is not None:
            raise RobotModelError(
                f"joint '{name}' of the URDF file '{path}' mimics joint '{mimic.get('joint', '?')}', but "
                "dynid models independent joints only; make the mimic joint fixed, or remove its <mimic> tag "
                "to identify it as a joint of its own."
            )
        _check_urdf_limit(joint.find("limit"), name, kind, path)
        axis = joint.find("axis")
        if axis is not None and kind in ("revolute", "continuous", "prismatic"):
            try:
                values = [float(v) for v in (axis.get("xyz") or "1 0 0").split()]
            except ValueError:
                values = []
            if len(values) != 3 or not all(math.isfinite(v) for v in values) or max(map(abs, values)) == 0:
                raise RobotModelError(
                    f"joint '{name}' of the URDF file '{path}' has the axis xyz=\"{axis.get('xyz')}\"; give a "
                    "non-zero direction of three numbers in its <axis> tag (e.g. xyz=\"0 0 1\")."
                )
    for child_link, (name, parent_link) in parent_of.items():
        seen = {child_link}
        link = parent_link
        while link in parent_of:
            if link in seen:
                raise RobotModelError(
                    f"joint '{name}' of the URDF file '{path}' closes a loop: its child link '{child_link}' "
                    f"is also an ancestor of its parent link '{parent_link}'; a URDF is a tree, so remove the "
                    "joint or give it another child link."
                )
            seen.add(link)
            link = parent_of[link][1]


def _check_urdf_limit(limit: ET.Element | None, joint: str, kind: str | None, path: Path) -> None:
    """Refuse a ``<limit>`` whose lower bound exceeds its upper one, or whose velocity is not positive."""
    if limit is None:
        return
    unit = "m" if kind == "prismatic" else "rad"

    def number(key: str) -> float | None:
        text = limit.get(key)
        if text is None:
            return None
        try:
            return float(text)
        except ValueError:
            return None  # the URDF parser names the problem

    lower, upper, velocity = number("lower"), number("upper"), number("velocity")
    if kind != "continuous" and lower is not None and upper is not None and lower > upper:
        raise RobotModelError(
            f"joint '{joint}' of the URDF file '{path}' has the lower limit {lower:g} {unit} above its upper "
            f"limit {upper:g} {unit}; give lower < upper in its <limit> tag (swap them if they were exchanged)."
        )
    if velocity is not None and not (math.isfinite(velocity) and velocity > 0):
        raise RobotModelError(
            f"joint '{joint}' of the URDF file '{path}' has the velocity limit {velocity:g} {unit}/s; give a "
            f"positive velocity in its <limit> tag (the joint's top speed in {unit}/s)."
        )
