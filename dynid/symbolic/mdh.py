"""Modified-DH tables (Craig's convention, TOML) read into a :class:`RobotModel`.

``[joints]`` alpha, a, d, theta (and type, limits) and ``[links]`` mass, centre of mass and inertia about it
(and armature) per joint, optional gravity, ``[tool]`` and ``[transmission]``.  Values no arm can have
(angles in degrees, lengths in millimetres, negative armatures) are refused with the column and the fix.
"""

from __future__ import annotations

import math
import tomllib
from collections import Counter
from pathlib import Path

import numpy as np

from dynid.exceptions import RobotModelError
from dynid.symbolic.inertia import standard_from_com
from dynid.symbolic.robot_model import DEFAULT_DDQ_MAX, Joint, RobotModel
from dynid.symbolic.transmission import transmission_table

__all__ = ["load_mdh", "mdh_placement"]

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


def _snapped_angles(alpha, theta, path: Path):
    """The table's alpha and theta with rounded right angles snapped, as a URDF's placements are.

    A table written from a datasheet gives pi/2 as 1.5708: the axes are then 3.7e-6 rad off parallel or
    perpendicular, and the base parameters take near-dependent combinations (``Ixy2R = Ixy2 - 3.67e-06*Ixy3``)
    whose values no recording determines.  An angle within :data:`~dynid.symbolic.urdf.SNAP_RAD` of a multiple
    of pi/2 is snapped to it (with the URDF loader's warning, naming the joints), one closer than 1e-7 rad is
    exact as written and left as it is.
    """
    from dynid.symbolic.urdf import snapped_angle, warn_snapped

    out, moved, worst = [], set(), 0.0
    for values in (alpha, theta):
        snapped = []
        for i, x in enumerate(values):
            angle, off = snapped_angle(x)
            snapped.append(angle)
            if off > 0:
                moved.add(i + 1)
                worst = max(worst, off)
        out.append(np.asarray(snapped, dtype=np.float64))
    warn_snapped(str(path), [f"joint_{i}" for i in sorted(moved)], worst, offsets=False, by="datasheets")
    return out[0], out[1]


def load_mdh(path: Path, *, name: str) -> RobotModel:
    """A modified-DH TOML table (module docstring; ``name`` unless the table names the robot); inertias unchecked."""
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
    dh["alpha"], dh["theta"] = _snapped_angles(dh["alpha"], dh["theta"], path)
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
        transmission_table(table["transmission"], n, f"the table '{path}'")
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
