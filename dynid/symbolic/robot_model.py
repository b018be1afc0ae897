"""The canonical kinematic tree every robot description is reduced to: :class:`RobotModel`.

A list of single-DOF joints (:class:`Joint`) with their placement in the parent joint frame, the standard
inertial parameters of the body each joint carries, the armature (rotor inertia) and the tool frame.  The
numeric Pinocchio model and the symbolic CasADi functions are both built from that one tree, so they cannot
disagree.  Loading one: :func:`dynid.symbolic.robot.load_robot`.

Standard parameters are Pinocchio's: per joint ``[m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]``
with ``m c`` the first moment and the inertia about the joint frame origin, in the joint frame (SI).
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from dynid.exceptions import RobotModelError, ShapeError
from dynid.symbolic.transmission import check_transmission

__all__ = ["DEFAULT_DDQ_MAX", "PARAM_NAMES", "Joint", "RobotModel"]

PARAM_NAMES = ("m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")
"""Names of the 10 standard parameters of a link, in Pinocchio's order."""

DEFAULT_DDQ_MAX = 10.0
"""Acceleration limit (rad/s^2 or m/s^2) used when a model states none (URDF has no such field)."""


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
            R = check_transmission(self.transmission, n, f"the robot '{self.name}'")
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
