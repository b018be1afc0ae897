"""Robot models: built-in names, URDF files and modified-DH tables.

Every description is reduced to one canonical kinematic tree (:class:`RobotModel`): a list of
single-DOF joints with their placement in the parent joint frame, the standard inertial parameters of
the body each joint carries, the armature (rotor inertia) and the tool frame.  The numeric Pinocchio
model and the symbolic CasADi functions are both built from that one tree, so they cannot disagree.

Standard parameters are Pinocchio's: per joint ``[m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]``
with ``m c`` the first moment and the inertia about the joint frame origin, in the joint frame (SI).
"""

from __future__ import annotations

import contextlib
import hashlib
import math
import os
import sys
import tempfile
import tomllib
import warnings
import xml.etree.ElementTree as ET
from collections import Counter
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path

import numpy as np

from dynid.exceptions import RobotModelError, RobotModelWarning, ShapeError

__all__ = [
    "BUILTIN_ROBOTS",
    "CONTINUOUS_RANGE",
    "DEFAULT_DDQ_MAX",
    "INERTIA_TOLERANCE",
    "PARAM_NAMES",
    "SNAP_RAD",
    "RobotModel",
    "check_inertias",
    "check_simulable",
    "load_robot",
    "load_transmission",
    "pin_model_from_urdf",
]

PARAM_NAMES = ("m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")
"""Names of the 10 standard parameters of a link, in Pinocchio's order."""

DEFAULT_DDQ_MAX = 10.0
"""Acceleration limit (rad/s^2 or m/s^2) used when a model states none (URDF has no such field)."""

INERTIA_TOLERANCE = 0.01
"""Largest violation of the triangle inequality a loaded description may have, as a fraction of the trace
of the link's inertia: beyond it the description is refused, below it (rounded inertias of published
URDFs) :func:`check_inertias` warns."""

# Built-in robots: URDF inside the installed example-robot-data package, joints to lock, tool frame,
# acceleration limits (rad/s^2).  Panda: Franka's datasheet limits; UR: none published, the default.
BUILTIN_ROBOTS: dict[str, dict] = {
    "ur5": {
        "urdf": "ur_description/urdf/ur5_robot.urdf",
        "lock": (),
        "tool": "tool0",
        "ddq_max": None,
    },
    "ur10": {
        "urdf": "ur_description/urdf/ur10_robot.urdf",
        "lock": (),
        "tool": "tool0",
        "ddq_max": None,
    },
    "panda": {
        "urdf": "panda_description/urdf/panda.urdf",
        "lock": ("panda_finger_joint1", "panda_finger_joint2"),
        "tool": "panda_hand_tcp",
        "ddq_max": (15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0),
    },
}

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


@dataclass(frozen=True, eq=False)
class Joint:
    """One single-DOF joint of the canonical tree.

    Parameters
    ----------
    name : str
        Joint name.
    kind : str
        ``RX RY RZ PX PY PZ`` (axis of the joint frame) or ``RU PU`` (unaligned ``axis``).
    parent : int
        Index of the parent joint, 0 for the base, joints numbered from 1.
    rotation, translation : ndarray, shape (3, 3) and (3,)
        Placement of the joint frame in the parent joint frame at q = 0 (m).
    axis : ndarray, shape (3,)
        Unit axis for ``RU`` / ``PU`` joints.
    """

    name: str
    kind: str
    parent: int
    rotation: np.ndarray
    translation: np.ndarray
    axis: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))

    @property
    def revolute(self) -> bool:
        return self.kind.startswith("R")


@dataclass(frozen=True, eq=False)
class RobotModel:
    """A serial or tree-structured arm with n single-DOF joints.

    Build one with :func:`load_robot`.  Limits are arrays of shape (n,) in rad, rad/s, rad/s^2
    (m, m/s, m/s^2 for prismatic joints).

    Attributes
    ----------
    name : str
        Short name ("ur5", the file stem of a URDF or table).
    source : str
        Where the model came from (built-in name, URDF path, TOML path).
    joints : tuple of Joint
        The canonical tree, in the model's joint order.
    params : ndarray, shape (10 n,)
        Standard inertial parameters, Pinocchio's order per joint (see :data:`PARAM_NAMES`).
    armature : ndarray, shape (n,)
        Rotor inertia reflected to the joint (kg m^2), added to the diagonal of M.
    gravity : ndarray, shape (3,)
        Gravity in the base frame (m/s^2).
    tool_name, tool_parent, tool_rotation, tool_translation
        Tool frame: its placement in the frame of joint ``tool_parent`` (1-based).
    q_min, q_max, dq_max, ddq_max : ndarray, shape (n,)
        Joint limits.
    transmission : ndarray, shape (n, n), or None
        Coupled transmission: the motor of joint i turns, in joint units, by ``(R q)_i`` (unit
        diagonal; e.g. the TX40's wrist, where motor 6 also turns with joint 5: ``R[5, 4] = 1``).  Its
        armature and friction then act on ``R q`` (:mod:`dynid.identify.columns`).  None: every motor
        drives its own joint.  Not part of :attr:`key` (the rigid body is the same).
    """

    name: str
    source: str
    joints: tuple[Joint, ...]
    params: np.ndarray
    armature: np.ndarray
    gravity: np.ndarray
    tool_name: str
    tool_parent: int
    tool_rotation: np.ndarray
    tool_translation: np.ndarray
    q_min: np.ndarray
    q_max: np.ndarray
    dq_max: np.ndarray
    ddq_max: np.ndarray
    transmission: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = len(self.joints)
        if n == 0:
            raise RobotModelError(
                f"the robot '{self.name}' has no movable joint; give an arm with at least one."
            )
        if self.transmission is not None:
            R = _check_transmission(self.transmission, n, f"the robot '{self.name}'")
            object.__setattr__(self, "transmission", None if np.array_equal(R, np.eye(n)) else R)
        for label, size in (
            ("params", 10 * n),
            ("armature", n),
            ("q_min", n),
            ("q_max", n),
            ("dq_max", n),
            ("ddq_max", n),
        ):
            value = np.asarray(getattr(self, label), dtype=float)
            if value.shape != (size,):
                raise ShapeError(
                    f"{label} of the robot '{self.name}' has shape {value.shape}; expected ({size},) for "
                    f"{n} joints."
                )
            if not np.all(np.isfinite(value)):
                raise RobotModelError(
                    f"{label} of the robot '{self.name}' holds non-finite values; fix the model."
                )
            value.setflags(write=False)
            object.__setattr__(self, label, value)
        if np.any(self.q_min >= self.q_max):
            bad = int(np.argmax(self.q_min >= self.q_max)) + 1
            raise RobotModelError(
                f"joint {bad} of the robot '{self.name}' has q_min {self.q_min[bad - 1]:g} >= q_max "
                f"{self.q_max[bad - 1]:g}; give a lower limit below the upper one."
            )
        for label in ("dq_max", "ddq_max"):
            value = getattr(self, label)
            if np.any(value <= 0):
                bad = int(np.argmax(value <= 0)) + 1
                raise RobotModelError(
                    f"{label} of joint {bad} of the robot '{self.name}' is {value[bad - 1]:g}; limits must be "
                    "positive, override it with a positive value."
                )

    # ------------------------------------------------------------------ sizes and names
    @property
    def n(self) -> int:
        """Number of joints."""
        return len(self.joints)

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    @property
    def param_names(self) -> tuple[str, ...]:
        """Names of the 10 n standard parameters: ``m1, mx1, ..., Izz1, m2, ...``."""
        return tuple(f"{p}{j + 1}" for j in range(self.n) for p in PARAM_NAMES)

    # ------------------------------------------------------------------ canonical text and keys
    @cached_property
    def spec(self) -> str:
        """The canonical tree as text, read by the symbolic generator (one record per line)."""

        def num(values) -> str:
            return " ".join(repr(float(v)) for v in np.ravel(values))

        lines = ["dynid-spec 1", f"gravity {num(self.gravity)}"]
        for i, joint in enumerate(self.joints):
            lines.append(
                f"joint {_token(joint.name)} {joint.kind} {joint.parent} {num(joint.rotation)} "
                f"{num(joint.translation)} {num(joint.axis)}"
            )
            lines.append(f"inertia {num(self.params[10 * i : 10 * i + 10])}")
            lines.append(f"armature {num([self.armature[i]])}")
        lines.append(
            f"tool {_token(self.tool_name)} {self.tool_parent} {num(self.tool_rotation)} "
            f"{num(self.tool_translation)}"
        )
        return "\n".join(lines) + "\n"

    @cached_property
    def key(self) -> str:
        """Content hash of the canonical tree (kinematics, inertias, armature, tool; not limits)."""
        return hashlib.sha256(self.spec.encode()).hexdigest()[:16]

    # ------------------------------------------------------------------ numeric Pinocchio
    @cached_property
    def pin_model(self):
        """The numeric ``pinocchio.Model`` built from the canonical tree."""
        import pinocchio as pin

        model = pin.Model()
        model.name = self.name
        for i, joint in enumerate(self.joints):
            jmodel = _pin_joint(pin, joint)
            placement = pin.SE3(np.array(joint.rotation), np.array(joint.translation))
            jid = model.addJoint(joint.parent, jmodel, placement, joint.name)
            inertia = _pin_inertia(pin, self.params[10 * i : 10 * i + 10], self.name, i + 1)
            if inertia is not None:
                model.appendBodyToJoint(jid, inertia, pin.SE3.Identity())
        model.armature = np.array(self.armature)
        model.gravity.linear = np.array(self.gravity)
        model.lowerPositionLimit = np.array(self.q_min)
        model.upperPositionLimit = np.array(self.q_max)
        model.velocityLimit = np.array(self.dq_max)
        return model

    # ------------------------------------------------------------------ changes
    def with_limits(
        self,
        *,
        q_min: Sequence[float] | float | None = None,
        q_max: Sequence[float] | float | None = None,
        dq_max: Sequence[float] | float | None = None,
        ddq_max: Sequence[float] | float | None = None,
    ) -> RobotModel:
        """Return a copy with some joint limits overridden (a scalar applies to every joint)."""
        changes = {}
        for label, value in (("q_min", q_min), ("q_max", q_max), ("dq_max", dq_max), ("ddq_max", ddq_max)):
            if value is None:
                continue
            arr = np.broadcast_to(np.asarray(value, dtype=float), (self.n,)) if np.ndim(value) == 0 else value
            arr = np.asarray(arr, dtype=float)
            if arr.shape != (self.n,):
                raise ShapeError(
                    f"{label} has {arr.size} values; the robot '{self.name}' has {self.n} joints, give {self.n} "
                    "values or one for all."
                )
            changes[label] = arr.copy()
        return replace(self, **changes)

    def with_transmission(self, transmission) -> RobotModel:
        """Return a copy with a coupled transmission ``R`` (n, n; see :attr:`transmission`), or None."""
        return replace(
            self, transmission=None if transmission is None else np.array(transmission, dtype=float)
        )

    def with_params(self, params: np.ndarray | None = None, armature: np.ndarray | None = None) -> RobotModel:
        """Return a copy with other standard parameters and/or armature (e.g. a perturbed truth)."""
        out = replace(
            self,
            params=np.array(self.params if params is None else params, dtype=float),
            armature=np.array(self.armature if armature is None else armature, dtype=float),
        )
        return out

    # ------------------------------------------------------------------ checks
    def check_state(self, label: str, value, *, batch: bool = True) -> np.ndarray:
        """Return ``value`` as float array of shape (m, n) (or (n,) if ``batch`` is False), or raise.

        Raises
        ------
        ShapeError
            With a message naming the robot and the expected size.
        """
        arr = np.asarray(value, dtype=float)
        if arr.ndim == 1 and batch:
            arr = arr[None, :]
        ok = arr.ndim == 2 and arr.shape[1] == self.n if batch else arr.shape == (self.n,)
        if not ok:
            cols = arr.shape[-1] if arr.ndim else 1
            raise ShapeError(
                f"{label} has {cols} {'columns' if batch else 'values'}; the robot '{self.name}' has "
                f"{self.n} joints, give {'an (m, ' + str(self.n) + ') array' if batch else str(self.n) + ' values'}."
            )
        return arr

    def __repr__(self) -> str:
        return f"RobotModel(name={self.name!r}, n={self.n}, source={self.source!r})"


# ---------------------------------------------------------------------------- helpers
def _token(name: str) -> str:
    """A whitespace-free rendering of a name for the specification text."""
    return "".join(ch if not ch.isspace() else "_" for ch in name) or "_"


def _pin_joint(pin, joint: Joint):
    simple = {
        "RX": pin.JointModelRX,
        "RY": pin.JointModelRY,
        "RZ": pin.JointModelRZ,
        "PX": pin.JointModelPX,
        "PY": pin.JointModelPY,
        "PZ": pin.JointModelPZ,
    }
    if joint.kind in simple:
        return simple[joint.kind]()
    if joint.kind == "RU":
        return pin.JointModelRevoluteUnaligned(np.array(joint.axis))
    return pin.JointModelPrismaticUnaligned(np.array(joint.axis))


def _pin_inertia(pin, v: np.ndarray, robot: str, j: int):
    """Inertia of a body from its 10 standard parameters; None for an empty body."""
    v = np.asarray(v, dtype=float)
    if v[0] > 0:
        return pin.Inertia.FromDynamicParameters(v)
    if v[0] < 0 or np.any(v[1:4] != 0):
        raise RobotModelError(
            f"link {j} of the robot '{robot}' has mass {v[0]:g} and first moment {v[1:4]}; a body needs a "
            "positive mass (or zero mass and zero first moment)."
        )
    if np.any(v[4:] != 0):
        return pin.Inertia(0.0, np.zeros(3), pin.Symmetric3(v[4:]))
    return None


def _site_roots() -> list[Path]:
    return [Path(p) for p in sys.path if p]


def example_robot_data_dir() -> Path:
    """Folder ``robots/`` of the installed example-robot-data package."""
    for root in _site_roots():
        candidate = root / "cmeel.prefix" / "share" / "example-robot-data" / "robots"
        if candidate.is_dir():
            return candidate
    raise RobotModelError(
        "the built-in robots need the package example-robot-data, which was not found on sys.path; "
        "install it with 'pip install example-robot-data'."
    )


SNAP_RAD = 1e-4
"""A joint placement or axis within this angle (rad) of a right-angle orientation is snapped to it."""
SNAP_M = 1e-6
"""A joint offset component below this length (m) is snapped to 0."""
_QUIET_SNAP_RAD = 1e-6  # snaps smaller than this (pi/2 written as 1.5707963) need no warning
# Below these the value is exact as written (float noise of a file's 9 decimals, 5e-10 rad at most): left as it
# is, so that a robot's key, and the model files identified on it, do not change
_EXACT_RAD = 1e-7
_EXACT_M = 1e-9


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
    worst = max((a for _, a in moved), default=0.0)
    if worst > _QUIET_SNAP_RAD:  # values written to 7 decimals or better are the exact ones, silently
        warnings.warn(
            f"the robot description '{source}' places joint(s) {', '.join(name for name, _ in moved)} within "
            f"{SNAP_RAD:g} rad of a right angle or {SNAP_M:g} m of zero (rounded values, as CAD exports write "
            f"them; largest change {worst:.2g} rad); dynid snapped them, so that the base parameters are "
            "those of the exact arm. Write the exact values in the file to silence this.",
            RobotModelWarning,
            stacklevel=4,
        )
    return out


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


def _load_urdf(path: Path, *, name: str, source: str, lock=(), tool=None, ddq_max=None) -> RobotModel:
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


def _load_mjcf(path: Path, *, name: str, source: str, tool=None) -> RobotModel:
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


def _numbers(values) -> str:
    """A short list of numbers for a message: ``[0.05, 0.06, 0.2]`` (6 significant digits)."""
    return "[" + ", ".join(f"{float(v) + 0.0:.6g}" for v in np.ravel(values)) + "]"


def _principal_moments(v: np.ndarray) -> np.ndarray:
    """Principal moments (kg m^2) about the centre of mass of a link from its 10 standard parameters."""
    m = float(v[0])
    c = v[1:4] / m if m > 0 else np.zeros(3)
    inertia = np.array([[v[4], v[5], v[7]], [v[5], v[6], v[8]], [v[7], v[8], v[9]]], dtype=float)
    skew = np.array([[0.0, -c[2], c[1]], [c[2], 0.0, -c[0]], [-c[1], c[0], 0.0]])
    return np.linalg.eigvalsh(inertia + m * skew @ skew)


def check_inertias(model: RobotModel) -> RobotModel:
    """Check that every link of a loaded description is a physical body.

    The rule, the same for URDF files, modified-DH tables and built-in robots: a mass is positive, or
    zero with zero first moment (an empty link); the inertia about the centre of mass is positive
    semi-definite (a point mass or a thin rod, idealised, is accepted); each principal moment is at most
    the sum of the other two (the triangle inequality).  A violation of the triangle inequality by at most
    :data:`INERTIA_TOLERANCE` of the trace (published URDFs round their inertias) gives a warning; anything
    else is refused.  Identified or perturbed parameters (:meth:`RobotModel.with_params`) are not checked.

    Parameters
    ----------
    model : RobotModel
        A model as loaded.

    Returns
    -------
    RobotModel
        ``model``, so that calls chain.

    Raises
    ------
    RobotModelError
        Negative mass, first moment without mass, inertia not positive semi-definite, or the triangle
        inequality violated beyond the tolerance.

    Warns
    -----
    RobotModelWarning
        The triangle inequality violated within the tolerance.
    """
    for j, v in enumerate(np.asarray(model.params, dtype=float).reshape(-1, 10), start=1):
        where = f"the link of joint {j} ('{model.joints[j - 1].name}') of the robot '{model.name}'"
        if not v[0] >= 0:
            raise RobotModelError(
                f"{where} has mass {v[0]:g} kg; a mass must be positive (or zero for an empty link): fix it."
            )
        if v[0] == 0 and np.any(v[1:4] != 0):
            raise RobotModelError(
                f"{where} has zero mass but first moment {_numbers(v[1:4])} kg m; a body "
                "needs a positive mass (or zero mass and zero first moment): fix its mass."
            )
        moments = _principal_moments(v)
        trace = float(moments.sum())
        scale = max(float(np.abs(moments).max()), 1e-300)
        if moments.min() < -1e-9 * scale:
            raise RobotModelError(
                f"{where} has principal moments of inertia {_numbers(moments)} kg m^2 about its "
                "centre of mass; an inertia has none negative (it is positive semi-definite): fix Ixx..Iyz."
            )
        excess = moments - (trace - moments)
        k = int(np.argmax(excess))
        if excess[k] <= 1e-9 * scale:
            continue
        others = np.delete(moments, k)
        said = (
            f"{where} has principal moments of inertia {_numbers(moments)} kg m^2 about its centre "
            f"of mass, and {moments[k]:.6g} exceeds the sum of the other two ({others.sum():.6g})"
        )
        if excess[k] > INERTIA_TOLERANCE * trace:
            raise RobotModelError(
                f"{said}, which no body can have (the triangle inequality); fix Ixx, Iyy, Izz so that each is "
                "at most the sum of the other two."
            )
        warnings.warn(
            f"{said} by {excess[k] / trace:.2%} of the trace, within the {INERTIA_TOLERANCE:.0%} allowed for "
            "rounded inertias; used as given.",
            RobotModelWarning,
            stacklevel=3,
        )
    return model


def check_simulable(model: RobotModel) -> RobotModel:
    """Check that every joint moves something, so that the robot can be simulated.

    A joint carries nothing when every link from it to the tip (its subtree) has zero mass and zero
    inertia and the joint has no armature: its row of the mass matrix is zero, its torque is zero whatever
    the motion, and a simulated controller cannot track it.  Such a description is fine for designing an
    excitation and for identification (they use the regressor only), so only the simulator refuses it.

    Parameters
    ----------
    model : RobotModel
        The robot to simulate.

    Returns
    -------
    RobotModel
        ``model``, so that calls chain.

    Raises
    ------
    RobotModelError
        When a joint carries nothing; the message names the first.
    """
    params = np.asarray(model.params, dtype=float).reshape(-1, 10)
    empty = [not np.any(params[j]) for j in range(model.n)]
    carries = [False] * model.n
    for j in reversed(range(model.n)):
        carries[j] = carries[j] or not empty[j] or model.armature[j] != 0
        parent = model.joints[j].parent - 1
        if parent >= 0 and carries[j]:
            carries[parent] = True
    if all(carries):
        return model
    j = carries.index(False)
    raise RobotModelError(
        f"joint {j + 1} ('{model.joints[j].name}') of the robot '{model.name}' carries no mass, inertia or "
        "armature, so its torque is zero whatever the motion and it cannot be simulated; give its link "
        "(or a link beyond it) a mass and inertia, or the joint an armature."
    )


# ---------------------------------------------------------------------------- modified DH
_DH_COLUMNS = ("alpha", "a", "d", "theta")
_LINK_COLUMNS = ("m", "cx", "cy", "cz", "Ixx", "Iyy", "Izz", "Ixy", "Ixz", "Iyz")


def _rot_x(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rot_z(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def mdh_placement(alpha: float, a: float, d: float, theta: float) -> tuple[np.ndarray, np.ndarray]:
    """Placement of frame i in frame i-1 by the modified DH convention (Craig).

    ``T = RotX(alpha) TransX(a) RotZ(theta) TransZ(d)``.  Returns (rotation (3, 3), translation (3,)).
    """
    rx = _rot_x(alpha)
    rot = rx @ _rot_z(theta)
    trans = np.array([a, 0.0, 0.0]) + rot @ np.array([0.0, 0.0, d])
    return rot, trans


def _column(table: dict, section: str, key: str, n: int | None, path: Path, default=None) -> np.ndarray:
    sec = table.get(section, {})
    if key not in sec:
        if default is not None:
            return np.full(n, default, dtype=float)
        raise RobotModelError(
            f"the table '{path}' has no column '{section}.{key}'; a modified-DH table needs "
            f"[joints] alpha, a, d, theta and [links] {', '.join(_LINK_COLUMNS)} (one value per joint)."
        )
    try:
        value = np.asarray(sec[key], dtype=float)
    except (TypeError, ValueError):
        raise RobotModelError(
            f"column '{section}.{key}' of the table '{path}' is not a list of numbers; write it as [v1, v2, ...]."
        ) from None
    if n is not None and value.shape != (n,):
        raise RobotModelError(
            f"column '{section}.{key}' of the table '{path}' has {value.size} values; the table has {n} joints, "
            f"give one value per joint."
        )
    if not np.all(np.isfinite(value)):
        bad = value.reshape(-1)[~np.isfinite(value.reshape(-1))][0]
        raise RobotModelError(
            f"column '{section}.{key}' of the table '{path}' holds {bad}; give finite numbers (one per joint)."
        )
    return value


_MAX_COUPLING = 1e3
"""Largest coupling ratio (joint units per joint unit) of a transmission: real wrists couple at ratios near 1."""

_MAX_TRANSMISSION_COND = 1e8
"""Largest condition number of a transmission matrix: beyond it motor and joint angles cannot be told apart."""


def _is_number(value) -> bool:
    """A TOML/JSON number: an int or a float, not a bool (``true`` is not joint 1) nor a string."""
    number = isinstance(value, int | float | np.integer | np.floating)
    return number and not isinstance(value, bool | np.bool_)


def _check_transmission(value, n: int, where: str) -> np.ndarray:
    """The matrix R (n, n) of a coupled transmission, checked: numbers, finite, unit diagonal, invertible."""
    if isinstance(value, list | tuple) and not all(
        _is_number(v) for row in value for v in (row if isinstance(row, list | tuple) else [row])
    ):
        R = np.zeros(0)  # strings or booleans as numbers
    else:
        try:
            R = np.array(value, dtype=float)
        except (TypeError, ValueError):
            R = np.zeros(0)
    if R.shape != (n, n) or not np.all(np.isfinite(R)):
        raise RobotModelError(
            f"the transmission of {where} is {R.shape if R.size else 'not a matrix of numbers'}; give an "
            f"({n}, {n}) matrix of finite numbers (motor angles in joint units per joint angle)."
        )
    if not np.allclose(np.diag(R), 1.0):
        raise RobotModelError(
            f"the transmission of {where} has diagonal {np.diag(R).tolist()}; each motor turns with its own "
            "joint at ratio 1 in joint units: give a unit diagonal (fold the gear ratio into the coupling)."
        )
    big = np.abs(R - np.eye(n)) > _MAX_COUPLING
    if np.any(big):
        i, j = np.argwhere(big)[0]
        raise RobotModelError(
            f"the transmission of {where} couples motor {i + 1} to joint {j + 1} at ratio {R[i, j]:g}, beyond "
            f"+-{_MAX_COUPLING:g}; give the ratio in joint units per joint unit (a wrist couples at about 1)."
        )
    cond = np.linalg.cond(R)
    if not cond <= _MAX_TRANSMISSION_COND:
        raise RobotModelError(
            f"the transmission of {where} is singular (condition number {cond:.3g}): two motors turn with the "
            "same combination of joints, so motor and joint angles cannot be told apart; couple each pair of "
            "joints once (motor b with joint a, not also motor a with joint b at the same ratio)."
        )
    R.setflags(write=False)
    return R


def _transmission_table(section, n: int, where: str) -> np.ndarray:
    """R from a ``[transmission]`` table: ``matrix = [[...], ...]`` or ``coupled = [[a, b, r], ...]``
    (motor b also turns by r times joint a, joints numbered from 1)."""
    if not isinstance(section, dict) or not ({"matrix", "coupled"} & set(section)):
        raise RobotModelError(
            f"the [transmission] table of {where} has neither 'matrix' nor 'coupled'; write e.g. "
            "coupled = [[5, 6, 1.0]] (motor 6 also turns with joint 5) or an n x n matrix."
        )
    unknown = sorted(set(section) - {"matrix", "coupled"})
    if unknown:
        raise RobotModelError(
            f"the [transmission] table of {where} has the unknown key '{unknown[0]}'; it holds 'coupled' or "
            "'matrix' only: remove or rename the key."
        )
    if len(section) > 1:
        raise RobotModelError(
            f"the [transmission] table of {where} has both 'matrix' and 'coupled'; give one of them."
        )
    if "matrix" in section:
        return _check_transmission(section["matrix"], n, where)
    coupled = section["coupled"]
    if isinstance(coupled, list) and not coupled:
        raise RobotModelError(
            f"'transmission.coupled' in {where} is empty; list the couplings, e.g. coupled = [[5, 6, 1.0]], or "
            "give no transmission when the joints are not coupled."
        )
    R = np.eye(n)
    seen: set[tuple[int, int]] = set()
    for entry in coupled if isinstance(coupled, list) else [None]:
        ok = isinstance(entry, list) and len(entry) == 3
        if ok:
            a, b, r = entry
            ok = all(_is_number(v) and int(v) == v and 1 <= v <= n for v in (a, b)) and a != b
            ok = ok and _is_number(r) and math.isfinite(r)
        if not ok:
            raise RobotModelError(
                f"the entry {entry!r} of 'transmission.coupled' in {where} is not [a, b, r] with joints a != b "
                f"in 1..{n} and a finite ratio r (numbers, not text or true/false); write e.g. "
                "coupled = [[5, 6, 1.0]]."
            )
        a, b = int(a), int(b)
        if (a, b) in seen:
            raise RobotModelError(
                f"'transmission.coupled' in {where} couples motor {b} to joint {a} twice; give each pair once."
            )
        seen.add((a, b))
        R[b - 1, a - 1] = float(r)
    return _check_transmission(R, n, where)


def load_transmission(path: str | os.PathLike[str], n: int) -> np.ndarray:
    """Read a coupled transmission from a TOML file holding a ``[transmission]`` table.

    Parameters
    ----------
    path : str or path-like
        The file (``[transmission]`` with ``coupled = [[a, b, r], ...]``: motor b also turns by r times
        joint a, joints from 1; or ``matrix``: the n x n matrix ``R`` with ``u = R q``).
    n : int
        Number of joints of the robot.

    Returns
    -------
    ndarray, shape (n, n)

    Raises
    ------
    RobotModelError
        Missing or malformed file or table.
    """
    path = Path(path)
    if not path.is_file():
        raise RobotModelError(
            f"the transmission file '{path}' does not exist; give a .toml file with a [transmission] table."
        )
    try:
        table = tomllib.loads(path.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise RobotModelError(
            f"the transmission file '{path}' is not valid TOML ({exc}); fix its syntax."
        ) from None
    return _transmission_table(table.get("transmission"), n, f"'{path}'")


# Largest magnitude a modified-DH table may hold per column kind: angles (rad; larger ones are degrees),
# lengths (m), masses (kg), inertias (kg m^2).  No robot arm comes near the last three.
_TABLE_SIZES = {"angle": 2 * math.pi, "length": 100.0, "mass": 1e5, "inertia": 1e6}
_TABLE_KIND = {"alpha": "angle", "theta": "angle", "a": "length", "d": "length", "m": "mass"}


def _check_table_sizes(path: Path, columns: dict[str, np.ndarray]) -> None:
    """Refuse table values no arm can have (angles above 2 pi rad are taken for degrees)."""
    for label, values in columns.items():
        key = label.split(".", 1)[1]
        kind = _TABLE_KIND.get(key, "length" if key.startswith("c") else "inertia")
        limit = _TABLE_SIZES[kind]
        big = np.abs(values) > limit
        if not big.any():
            continue
        j = int(np.argmax(big))
        unit = {"angle": "rad", "length": "m", "mass": "kg", "inertia": "kg m^2"}[kind]
        fix = "give radians (the angles look like degrees)" if kind == "angle" else f"give it in {unit}"
        raise RobotModelError(
            f"column '{label}' of the table '{path}' holds {values[j]:g} for joint {j + 1}, beyond the "
            f"{limit:g} {unit} of any arm; {fix}."
        )


def _check_table_physics(
    path: Path, kinds: list[str], *, armature: np.ndarray, q_min: np.ndarray, q_max: np.ndarray, gravity: np.ndarray
) -> None:
    """Refuse a table's armature, joint limits and gravity that no arm has (units mixed up, signs lost).

    Armature is a rotor inertia, 0 or more; a revolute limit lies within two turns either way (4 pi rad,
    beyond it the limits are degrees), a prismatic one within 20 m (beyond it, millimetres); gravity's
    magnitude is 0 to 100 m/s^2 (the Earth's is 9.81).
    """
    bad = np.flatnonzero(armature < 0)
    if bad.size:
        j = int(bad[0])
        raise RobotModelError(
            f"column 'links.armature' of the table '{path}' holds {armature[j]:g} for joint {j + 1}, but an "
            "armature is a rotor inertia reflected to the joint, 0 or more (kg m^2); give its magnitude, or 0."
        )
    for label, values in (("q_min", q_min), ("q_max", q_max)):
        for j, (kind, value) in enumerate(zip(kinds, values, strict=True)):
            revolute = kind == "R"
            limit, unit = (4 * math.pi, "rad (two turns)") if revolute else (20.0, "m")
            if abs(value) > limit:
                fix = "give radians (it looks like degrees)" if revolute else "give metres (it looks like mm)"
                raise RobotModelError(
                    f"column 'joints.{label}' of the table '{path}' holds {value:g} for joint {j + 1}, a "
                    f"{'revolute' if revolute else 'prismatic'} joint, beyond the {limit:.4g} {unit} of any arm; "
                    f"{fix}."
                )
    size = float(np.linalg.norm(gravity))
    if size > 100.0:
        raise RobotModelError(
            f"'gravity' in the table '{path}' is [{', '.join(f'{g:g}' for g in gravity)}], of magnitude {size:.4g} "
            "m/s^2, outside the 0 to 100 m/s^2 an arm is used in; give it in m/s^2 (the Earth's is "
            "[0, 0, -9.81] in a base frame with z up)."
        )


def _joint_count(table: dict) -> int:
    """Joint count of a modified-DH table: the length most of its required columns share.

    Taking it from one column would blame a short ``alpha`` on the next column read.
    """
    lengths = [
        len(value)
        for section, keys in (("joints", _DH_COLUMNS), ("links", _LINK_COLUMNS))
        for key in keys
        if isinstance(value := table.get(section, {}).get(key), list)
    ]
    return Counter(lengths).most_common(1)[0][0] if lengths else 0


def _table_floats(path: Path, label: str, value, size: int) -> np.ndarray:
    """A fixed-size list of numbers from a table (gravity, tool fields), or a one-sentence refusal."""
    try:
        out = np.array(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        out = np.zeros(0)
    if out.shape != (size,) or not np.all(np.isfinite(out)):
        what = "a number" if size == 1 else f"a list of {size} numbers"
        raise RobotModelError(f"'{label}' in the table '{path}' is {value!r}; give {what}.")
    return out


def _load_mdh(path: Path, *, name: str) -> RobotModel:
    if not path.is_file():
        raise RobotModelError(f"the table '{path}' does not exist; give the path of an existing .toml file.")
    try:
        table = tomllib.loads(path.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise RobotModelError(f"the table '{path}' is not valid TOML ({exc}); fix its syntax.") from None
    for section in ("joints", "links"):
        if section in table and not isinstance(table[section], dict):
            raise RobotModelError(
                f"'{section}' in the table '{path}' is a value, not a table; write it as a [{section}] section "
                "with one list per column."
            )
    if "joints" not in table or "alpha" not in table.get("joints", {}):
        raise RobotModelError(
            f"the table '{path}' has no column 'joints.alpha'; a modified-DH table needs [joints] alpha, a, d, "
            f"theta and [links] {', '.join(_LINK_COLUMNS)} (one value per joint)."
        )
    n = _joint_count(table)
    if n == 0:
        raise RobotModelError(
            f"the table '{path}' lists no joint (its columns are empty); give one value per joint in each "
            "column, for an arm with at least one joint."
        )
    dh = {k: _column(table, "joints", k, n, path) for k in _DH_COLUMNS}
    kinds = table["joints"].get("type", ["R"] * n)
    if not isinstance(kinds, list) or len(kinds) != n or any(k not in ("R", "P") for k in kinds):
        raise RobotModelError(
            f"column 'joints.type' of the table '{path}' must hold 'R' or 'P' for each of its {n} joints."
        )
    link = {k: _column(table, "links", k, n, path) for k in _LINK_COLUMNS}
    _check_table_sizes(
        path, {**{f"joints.{k}": v for k, v in dh.items()}, **{f"links.{k}": v for k, v in link.items()}}
    )
    armature = _column(table, "links", "armature", n, path, default=0.0)
    q_min = _column(table, "joints", "q_min", n, path, default=-math.pi)
    q_max = _column(table, "joints", "q_max", n, path, default=math.pi)
    dq_max = _column(table, "joints", "dq_max", n, path, default=math.pi)
    ddq_max = _column(table, "joints", "ddq_max", n, path, default=DEFAULT_DDQ_MAX)
    gravity = _table_floats(path, "gravity", table.get("gravity", [0.0, 0.0, -9.81]), 3)
    _check_table_physics(path, kinds, armature=armature, q_min=q_min, q_max=q_max, gravity=gravity)
    transmission = (
        _transmission_table(table["transmission"], n, f"the table '{path}'")
        if "transmission" in table
        else None
    )
    joints, params = [], []
    for i in range(n):
        # Revolute: RotZ(q) commutes with TransZ(d); prismatic: q adds to the offset d along z.
        # Either way the placement is the DH transform at q = 0, followed by the joint's motion.
        rot, trans = mdh_placement(dh["alpha"][i], dh["a"][i], dh["d"][i], dh["theta"][i])
        joints.append(
            Joint(
                name=f"joint_{i + 1}",
                kind="RZ" if kinds[i] == "R" else "PZ",
                parent=i,
                rotation=rot,
                translation=trans,
            )
        )
        params.append(
            standard_from_com(
                link["m"][i],
                np.array([link["cx"][i], link["cy"][i], link["cz"][i]]),
                np.array(
                    [
                        [link["Ixx"][i], link["Ixy"][i], link["Ixz"][i]],
                        [link["Ixy"][i], link["Iyy"][i], link["Iyz"][i]],
                        [link["Ixz"][i], link["Iyz"][i], link["Izz"][i]],
                    ]
                ),
            )
        )
    tool = table.get("tool", {})
    if not isinstance(tool, dict):
        raise RobotModelError(f"'tool' in the table '{path}' is a value; write it as a [tool] section.")
    t_rot, t_pos = mdh_placement(
        *(float(_table_floats(path, f"tool.{k}", tool.get(k, 0.0), 1)[0]) for k in _DH_COLUMNS)
    )
    return RobotModel(
        name=str(table.get("name", name)),
        source=str(path),
        joints=tuple(joints),
        params=np.concatenate(params),
        armature=armature,
        gravity=gravity,
        tool_name=str(tool.get("name", "tool")),
        tool_parent=n,
        tool_rotation=t_rot,
        tool_translation=t_pos,
        q_min=q_min,
        q_max=q_max,
        dq_max=dq_max,
        ddq_max=ddq_max,
        transmission=transmission,
    )


def standard_from_com(mass: float, com: np.ndarray, inertia_com: np.ndarray) -> np.ndarray:
    """Standard parameters (Pinocchio's order) of a body given its mass, centre of mass and inertia.

    Parameters
    ----------
    mass : float
        Mass (kg).
    com : ndarray, shape (3,)
        Centre of mass in the link frame (m).
    inertia_com : ndarray, shape (3, 3)
        Inertia about the centre of mass, link-frame axes (kg m^2).

    Returns
    -------
    ndarray, shape (10,)
        ``[m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`` with the inertia about the link frame origin.
    """
    c = np.asarray(com, dtype=float)
    skew = np.array([[0.0, -c[2], c[1]], [c[2], 0.0, -c[0]], [-c[1], c[0], 0.0]])
    with np.errstate(over="ignore", invalid="ignore"):  # absurd sizes give inf, refused by RobotModel
        inertia = np.asarray(inertia_com, dtype=float) - mass * skew @ skew
        first = mass * c
    return np.array(
        [
            mass,
            *first,
            inertia[0, 0],
            inertia[0, 1],
            inertia[1, 1],
            inertia[0, 2],
            inertia[1, 2],
            inertia[2, 2],
        ]
    )


# ---------------------------------------------------------------------------- entry point
def load_robot(
    robot: str | Path | RobotModel,
    *,
    q_min=None,
    q_max=None,
    dq_max=None,
    ddq_max=None,
    tool: str | None = None,
    transmission: str | os.PathLike[str] | None = None,
) -> RobotModel:
    """Load a robot from a built-in name, a URDF path or a modified-DH TOML table.

    Parameters
    ----------
    robot : str or Path or RobotModel
        ``"ur5"``, ``"ur10"``, ``"panda"`` (7-DOF arm, hand rigidly attached, fingers locked), a
        ``.urdf`` path, or a ``.toml`` modified-DH table.  A RobotModel is returned as is (with the
        limit overrides applied).  A MuJoCo ``.xml`` (MJCF) is read by Pinocchio's MJCF parser.
    q_min, q_max, dq_max, ddq_max : float or sequence of float, optional
        Override the model's joint limits (one value for all joints, or one per joint).
    tool : str, optional
        Name of the URDF frame used as the tool frame (default: the robot's flange / last frame); a name
        the model does not have is refused, listing its frames.
    transmission : str or path-like, optional
        A TOML file with a ``[transmission]`` table (:func:`load_transmission`): the coupled
        transmission beside a URDF (a table robot may declare it in its own file).

    Raises
    ------
    RobotModelError
        Unknown name, missing or malformed file, unsupported or mimic joint, missing or short table column,
        unknown tool frame, a link that is not a physical body (:func:`check_inertias`).

    Warns
    -----
    RobotModelWarning
        A link's inertia violates the triangle inequality within :data:`INERTIA_TOLERANCE`.
    """
    if isinstance(robot, RobotModel):
        model = robot
    else:
        text = str(robot)
        path = Path(text).expanduser()
        key = text.lower()
        if key in BUILTIN_ROBOTS and not path.exists():
            info = BUILTIN_ROBOTS[key]
            urdf = example_robot_data_dir() / info["urdf"]
            model = check_inertias(
                _load_urdf(
                    urdf,
                    name=key,
                    source=key,
                    lock=info["lock"],
                    tool=tool or info["tool"],
                    ddq_max=info["ddq_max"],
                )
            )
        elif path.suffix.lower() == ".urdf":
            model = check_inertias(_load_urdf(path, name=path.stem, source=str(path), tool=tool))
        elif path.suffix.lower() in (".xml", ".mjcf"):
            model = check_inertias(_load_mjcf(path, name=path.stem, source=str(path), tool=tool))
        elif path.suffix.lower() == ".toml":
            model = check_inertias(_load_mdh(path, name=path.stem))
            if tool is not None and tool != model.tool_name:
                raise RobotModelError(
                    f"the table '{path}' has one tool frame, '{model.tool_name}', not '{tool}'; leave out "
                    "--tool, or name the frame in the table's [tool] section (name = ...)."
                )
        else:
            raise RobotModelError(
                f"unknown robot '{text}'; give a built-in name ({', '.join(BUILTIN_ROBOTS)}), a .urdf file, a "
                "MuJoCo .xml (MJCF) or a modified-DH .toml table."
            )
    if any(v is not None for v in (q_min, q_max, dq_max, ddq_max)):
        model = model.with_limits(q_min=q_min, q_max=q_max, dq_max=dq_max, ddq_max=ddq_max)
    if transmission is not None:
        model = model.with_transmission(load_transmission(transmission, model.n))
    return model
