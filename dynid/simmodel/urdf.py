"""The identified parameters written into a copy of a URDF.

The copy keeps everything of the template (visuals, collisions, mesh references, limits, transmissions,
comments); it changes only

* the ``<inertial>`` of each moving joint's child link: the whole body the joint carries (that link and
  every link fixed to it, as dynid and Pinocchio merge them) goes on the child link, and the links fixed
  to it lose theirs.  Joints dynid locked (the Panda's fingers) keep their bodies; their share is taken
  out of the body written on the link they hang from, so the locked model is the identified one;
* each moving joint's ``<dynamics damping= friction=>``: viscous (N m s/rad) and Coulomb (N m) friction.

URDF has no field for the armature (Pinocchio's ``model.armature``, MuJoCo's ``armature``): it is written
only in the file's comment.  A robot with no URDF of its own (a modified-DH table) gets one from its
canonical tree (:func:`robot_urdf`: links, joints, limits, bodies; no geometry).  A template is accepted when its moving joints, once dynid's locked joints
are set aside, have the model's names, order, placements and axes (to 1e-9).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from dynid.exceptions import UsageError
from dynid.identify.consistent import is_consistent
from dynid.symbolic.robot import SNAP_M, SNAP_RAD, pin_model_from_urdf

__all__ = ["TemplateMatch", "match_template", "read_template", "robot_urdf", "write_urdf"]

_KINEMATIC_TOL = 1e-9


def read_template(path: str | Path) -> ET.Element:
    """Parse a URDF (comments kept); refuse a file that is not one in one sentence.

    Parameters
    ----------
    path : str or Path
        The URDF file.
    """
    path = Path(path)
    if not path.is_file():
        raise UsageError(f"the template '{path}' does not exist; give the robot's URDF file")
    try:
        parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
        root = ET.parse(path, parser=parser).getroot()
    except (ET.ParseError, UnicodeDecodeError) as err:
        raise UsageError(f"the template '{path}' is not well-formed XML ({err}); give a URDF file") from None
    if root.tag != "robot":
        raise UsageError(
            f"the template '{path}' has the root element <{root.tag}>, not <robot>: it is not a URDF; give the "
            "robot's URDF (an MJCF is written from a URDF with --format mjcf)"
        )
    # A mesh named relative to the template must still be found from wherever the copy is written.
    for mesh in root.iter("mesh"):
        name = mesh.get("filename", "")
        if name and "://" not in name and not Path(name).is_absolute():
            mesh.set("filename", str((path.parent / name).resolve()))
    return root


@dataclass(frozen=True, eq=False)
class TemplateMatch:
    """How a template's links and joints hold a robot model's bodies.

    Attributes
    ----------
    joint_elements : list of Element
        The ``<joint>`` of each model joint, in the model's order.
    child_links : list of str
        Each model joint's child link.
    fixed_links : list of list of str
        The links fixed to each child link (their inertials are merged onto it).
    locked : list of str
        The template's moving joints the model has not (locked at their neutral position).
    locked_share : ndarray, shape (10 n,)
        Standard parameters, in each model joint's frame, of the locked bodies hanging from it.
    template_params : ndarray, shape (10 n,)
        The template's own bodies as the model sees them (locked ones merged).
    template_armature : ndarray, shape (n,)
        The template's armature as Pinocchio reads it (zero for a URDF).
    """

    joint_elements: list[ET.Element]
    child_links: list[str]
    fixed_links: list[list[str]]
    locked: list[str]
    locked_share: NDArray[np.float64]
    template_params: NDArray[np.float64]
    template_armature: NDArray[np.float64]


def _links_by_parent(root: ET.Element) -> dict[str, list[ET.Element]]:
    out: dict[str, list[ET.Element]] = {}
    for j in root.findall("joint"):
        parent = j.find("parent")
        if parent is not None:
            out.setdefault(parent.get("link", ""), []).append(j)
    return out



def _motion_axes(model) -> list[np.ndarray]:
    """Each joint's motion in its own frame (6-vectors, linear then angular), from Pinocchio's joint model.

    A revolute joint about ``a`` gives ``(0, a)``, a prismatic one ``(a, 0)``, whether Pinocchio holds the
    axis in the joint's type (``RZ``) or in the joint (unaligned): the one form that compares both.
    """
    import pinocchio as pin

    data = model.createData()
    q = pin.neutral(model)
    pin.computeJointJacobians(model, data, q)
    out = []
    for k in range(1, model.njoints):
        J = pin.getJointJacobian(model, data, k, pin.ReferenceFrame.LOCAL)
        out.append(np.asarray(J[:, model.joints[k].idx_v], dtype=float).copy())
    return out


def _axis_words(motion: np.ndarray) -> str:
    """A joint's motion as words: 'revolute about (0, 0, 1)'."""
    angular = bool(np.abs(motion[3:]).max() > np.abs(motion[:3]).max())
    axis = motion[3:] if angular else motion[:3]
    return f"{'revolute' if angular else 'prismatic'} about ({', '.join(f'{v:.4g}' for v in axis)})"

def match_template(root: ET.Element, path: str | Path, robot) -> TemplateMatch:
    """Match a template URDF to a robot model: names, order and kinematics.

    Parameters
    ----------
    root : Element
        The parsed template (:func:`read_template`).
    path : str or Path
        Its file (Pinocchio reads it for the kinematics).
    robot : RobotModel
        The model's robot.

    Raises
    ------
    UsageError
        Other joint names, another order, or other placements or axes: a template of another robot.
    """
    import pinocchio as pin

    joints = {j.get("name"): j for j in root.findall("joint")}
    moving = [name for name, j in joints.items() if j.get("type") not in ("fixed", "floating", "planar")]
    missing = [name for name in robot.joint_names if name not in joints]
    if missing:
        raise UsageError(
            f"the template '{path}' has no joint {', '.join(repr(m) for m in missing[:4])} of the model "
            f"(its moving joints: {', '.join(moving[:10])}); give the URDF of the robot the model was "
            "identified for"
        )
    try:
        full = pin_model_from_urdf(path)
    except (ValueError, RuntimeError) as err:
        first = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise UsageError(
            f"Pinocchio cannot read the template '{path}' ({first}); check that it is a valid URDF"
        ) from None
    names = list(full.names)[1:]
    locked = [nm for nm in names if nm not in robot.joint_names]
    reduced = full
    if locked:
        reduced = pin.buildReducedModel(full, [full.getJointId(nm) for nm in locked], pin.neutral(full))
    if list(reduced.names)[1:] != list(robot.joint_names):
        raise UsageError(
            f"the template '{path}' orders its joints {', '.join(list(reduced.names)[1:])}; the model has "
            f"{', '.join(robot.joint_names)}; give the URDF of the robot the model was identified for"
        )
    axes = _motion_axes(reduced), _motion_axes(robot.pin_model)
    # the loader snaps a CAD export's rounded right angles (SNAP_RAD) and sub-micrometre offsets (SNAP_M):
    # its own template, read raw, differs by that much and is the same robot
    move_tol, turn_tol = max(_KINEMATIC_TOL, 1.01 * SNAP_M), max(_KINEMATIC_TOL, 1.01 * SNAP_RAD)
    for i, joint in enumerate(robot.joints):
        M = reduced.jointPlacements[i + 1]
        turned = float(np.abs(np.asarray(M.rotation) - joint.rotation).max())
        moved = float(np.abs(np.asarray(M.translation) - joint.translation).max())
        if moved > move_tol or turned > turn_tol or int(reduced.parents[i + 1]) != joint.parent:
            what = (
                f"its offset differs by {moved:.3g} m"
                if moved > move_tol
                else f"its orientation differs by {turned:.3g}"
                if turned > turn_tol
                else "its parent differs"
            )
            raise UsageError(
                f"the joint '{joint.name}' sits elsewhere in the template '{path}' than in the model ({what}): "
                "the template describes another robot; give the URDF the model was identified for, or one "
                "with the same kinematics"
            )
        about = float(np.abs(axes[0][i] - axes[1][i]).max())
        if about > turn_tol:
            kind = "turns" if joint.revolute else "slides"
            raise UsageError(
                f"the joint '{joint.name}' {kind} about another axis in the template '{path}' than in the model "
                f"(template {_axis_words(axes[0][i])}, model {_axis_words(axes[1][i])}): the template describes "
                "another robot; give the URDF the model was identified for, or one with the same kinematics"
            )
    n = robot.n
    share = np.zeros(10 * n)
    tparams = np.zeros(10 * n)
    for i, name in enumerate(robot.joint_names):
        tparams[10 * i : 10 * i + 10] = reduced.inertias[i + 1].toDynamicParameters()
        own = full.inertias[full.getJointId(name)].toDynamicParameters()
        share[10 * i : 10 * i + 10] = tparams[10 * i : 10 * i + 10] - own
    by_parent = _links_by_parent(root)
    child_links, fixed_links = [], []
    for name in robot.joint_names:
        child = joints[name].find("child")
        link = child.get("link") if child is not None else None
        if link is None:
            raise UsageError(
                f"the joint '{name}' of the template '{path}' has no <child link=...>; fix the URDF"
            )
        child_links.append(link)
        group, stack = [], [link]
        while stack:
            for j in by_parent.get(stack.pop(), []):
                if j.get("type") == "fixed":
                    c = j.find("child")
                    if c is not None:
                        group.append(c.get("link"))
                        stack.append(c.get("link"))
        fixed_links.append(group)
    return TemplateMatch(
        joint_elements=[joints[nm] for nm in robot.joint_names],
        child_links=child_links,
        fixed_links=fixed_links,
        locked=locked,
        locked_share=share,
        template_params=tparams,
        template_armature=np.zeros(n),
    )


def _num(v: float) -> str:
    return repr(float(v))


def _inertial(standard: NDArray[np.float64]) -> ET.Element:
    """A URDF ``<inertial>`` of standard parameters about the link frame."""
    m = float(standard[0])
    c = standard[1:4] / m
    Io = np.array(
        [
            [standard[4], standard[5], standard[7]],
            [standard[5], standard[6], standard[8]],
            [standard[7], standard[8], standard[9]],
        ]
    )
    Ic = Io - m * (float(c @ c) * np.eye(3) - np.outer(c, c))
    el = ET.Element("inertial")
    ET.SubElement(el, "origin", {"xyz": " ".join(_num(a) for a in c), "rpy": "0 0 0"})
    ET.SubElement(el, "mass", {"value": _num(m)})
    ET.SubElement(
        el,
        "inertia",
        {
            "ixx": _num(Ic[0, 0]),
            "ixy": _num(Ic[0, 1]),
            "ixz": _num(Ic[0, 2]),
            "iyy": _num(Ic[1, 1]),
            "iyz": _num(Ic[1, 2]),
            "izz": _num(Ic[2, 2]),
        },
    )
    return el


def _replace_child(parent: ET.Element, new: ET.Element, tag: str) -> None:
    old = parent.find(tag)
    if old is None:
        parent.insert(0, new)
    else:
        index = list(parent).index(old)
        parent.remove(old)
        parent.insert(index, new)


def _rpy(R: NDArray[np.float64]) -> tuple[float, float, float]:
    """URDF roll, pitch, yaw of a rotation matrix (``R = Rz(yaw) Ry(pitch) Rx(roll)``)."""
    pitch = float(np.arcsin(np.clip(-R[2, 0], -1.0, 1.0)))
    if abs(R[2, 0]) < 1.0 - 1e-12:
        return float(np.arctan2(R[2, 1], R[2, 2])), pitch, float(np.arctan2(R[1, 0], R[0, 0]))
    return 0.0, pitch, float(np.arctan2(-R[0, 1], R[1, 1]))


def _payload_elements(root: ET.Element, parent_link: str, payload: dict) -> list[ET.Element]:
    """A ``<link>`` holding the payload's body and the fixed ``<joint>`` placing it at its frame."""
    names = {el.get("name") for el in root if el.tag in ("link", "joint")}
    name = "payload"
    while name in names or f"{name}_joint" in names:
        name = f"dynid_{name}"
    values = np.array(
        [payload["params"][k] for k in ("m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")]
    )
    link = ET.Element("link", {"name": name})
    link.append(_inertial(values))
    joint = ET.Element("joint", {"name": f"{name}_joint", "type": "fixed"})
    R = np.asarray(payload["frame_rotation"], dtype=np.float64)
    xyz = np.asarray(payload["frame_translation"], dtype=np.float64)
    ET.SubElement(
        joint, "origin", {"xyz": " ".join(_num(a) for a in xyz), "rpy": " ".join(_num(a) for a in _rpy(R))}
    )
    ET.SubElement(joint, "parent", {"link": parent_link})
    ET.SubElement(joint, "child", {"link": name})
    return [link, joint]


def write_urdf(
    root: ET.Element, match: TemplateMatch, robot, params, comment: str, payload: dict | None = None
) -> str:
    """The template's text with the identified bodies and friction (see the module docstring).

    Parameters
    ----------
    root : Element
        The parsed template; changed in place.
    match : TemplateMatch
        How it holds the model's bodies (:func:`match_template`).
    robot : RobotModel
        The model's robot.
    params : SimParameters
        The values to write.
    comment : str
        Text of the comment put first inside ``<robot>``.
    payload : dict, optional
        A payload attached by ``dynid payload --out`` (the model's ``info["payload"]``): written as a link
        of its own, fixed at its frame, and taken out of the carrying link's body.

    Returns
    -------
    str
        The URDF (UTF-8 text with an XML declaration).

    Raises
    ------
    UsageError
        A body that, once the locked bodies' share is taken out, is no physical body.
    """
    links = {lk.get("name"): lk for lk in root.findall("link")}
    n = robot.n
    carried = np.zeros(10 * n)
    if payload is not None and payload.get("mass"):
        k = int(payload["link"]) - 1
        carried[10 * k : 10 * k + 10] = payload["link_params"]
    for i in range(n):
        body = params.standard[10 * i : 10 * i + 10] - match.locked_share[10 * i : 10 * i + 10]
        if carried[10 * i : 10 * i + 10].any():
            rest = body - carried[10 * i : 10 * i + 10]
            if rest[0] > 0 and is_consistent(rest)[0]:
                body = rest
            else:  # the arm's own body without the payload is none: keep them merged, as identified
                carried[:] = 0.0
                comment += (
                    f"\nThe payload is merged into the link of joint '{robot.joint_names[i]}': without it that "
                    "link's identified body is no physical body."
                )
        if not (body[0] > 0 and is_consistent(body)[0]):
            raise UsageError(
                f"the identified body of joint '{robot.joint_names[i]}' minus the locked joints' bodies of the "
                f"template ({', '.join(match.locked)}) is not a physical body; give a template without those "
                "joints (fixed instead)"
            )
        link = links.get(match.child_links[i])
        if link is None:
            raise UsageError(f"the template has no <link name='{match.child_links[i]}'>; fix the URDF")
        _replace_child(link, _inertial(body), "inertial")
        for other in match.fixed_links[i]:
            el = links.get(other)
            if el is not None and el.find("inertial") is not None:
                el.remove(el.find("inertial"))
        joint = match.joint_elements[i]
        dyn = ET.Element(
            "dynamics", {"damping": _num(params.damping[i]), "friction": _num(params.frictionloss[i])}
        )
        old = joint.find("dynamics")
        if old is not None:
            joint.remove(old)
        joint.append(dyn)
    if carried.any():
        assert payload is not None
        k = int(payload["link"]) - 1
        # after the carrying link, so that the description's own frames keep their order (its tool frame)
        at = len(root)
        for index, el in enumerate(root):
            if (
                el.tag == "joint"
                and el.find("parent") is not None
                and el.find("parent").get("link") == match.child_links[k]
            ):
                at = index + 1
        for offset, el in enumerate(_payload_elements(root, match.child_links[k], payload)):
            root.insert(at + offset, el)
    for old in [c for c in list(root) if c.tag is ET.Comment and "dynid export" in (c.text or "")]:
        root.remove(old)
    # XML forbids '--' inside a comment and a comment ending in '-' (a joint name or option may hold them)
    text = comment
    while "--" in text:
        text = text.replace("--", "- -")
    root.insert(0, ET.Comment(text + " " if text.endswith("-") else text))
    ET.indent(root, space="  ")
    return '<?xml version="1.0" encoding="utf-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


_AXES = {"X": "1 0 0", "Y": "0 1 0", "Z": "0 0 1"}


def robot_urdf(robot) -> str:
    """A URDF of a robot's canonical tree: one link per joint, the joints with their limits, the tool frame.

    For a robot with no URDF of its own (a modified-DH table).  It has no geometry; URDF has no
    acceleration limit and no gravity (Pinocchio and MuJoCo assume ``0 0 -9.81``), and the effort limit,
    which URDF requires, is written as 0 (unknown).

    Parameters
    ----------
    robot : RobotModel
        The robot.

    Returns
    -------
    str
        The URDF text.
    """
    import pinocchio as pin

    root = ET.Element("robot", {"name": robot.name})
    ET.SubElement(root, "link", {"name": "base_link"})
    links = ["base_link"]
    for i, joint in enumerate(robot.joints):
        link = f"{joint.name}_link"
        el = ET.SubElement(root, "link", {"name": link})
        body = np.asarray(robot.params[10 * i : 10 * i + 10], dtype=float)
        if body[0] > 0:
            el.append(_inertial(body))
        links.append(link)
        kind = "revolute" if joint.revolute else "prismatic"
        j = ET.SubElement(root, "joint", {"name": joint.name, "type": kind})
        ET.SubElement(j, "parent", {"link": links[joint.parent]})
        ET.SubElement(j, "child", {"link": link})
        rpy = pin.rpy.matrixToRpy(np.asarray(joint.rotation, dtype=float))
        ET.SubElement(
            j,
            "origin",
            {"xyz": " ".join(_num(v) for v in joint.translation), "rpy": " ".join(_num(v) for v in rpy)},
        )
        axis = _AXES.get(joint.kind[1]) if joint.kind[1] in _AXES else " ".join(_num(v) for v in joint.axis)
        ET.SubElement(j, "axis", {"xyz": axis})
        ET.SubElement(
            j,
            "limit",
            {
                "lower": _num(robot.q_min[i]),
                "upper": _num(robot.q_max[i]),
                "velocity": _num(robot.dq_max[i]),
                "effort": "0",
            },
        )
    ET.SubElement(root, "link", {"name": robot.tool_name})
    tool = ET.SubElement(root, "joint", {"name": f"{robot.tool_name}_joint", "type": "fixed"})
    ET.SubElement(tool, "parent", {"link": links[robot.tool_parent]})
    ET.SubElement(tool, "child", {"link": robot.tool_name})
    rpy = pin.rpy.matrixToRpy(np.asarray(robot.tool_rotation, dtype=float))
    ET.SubElement(
        tool,
        "origin",
        {"xyz": " ".join(_num(v) for v in robot.tool_translation), "rpy": " ".join(_num(v) for v in rpy)},
    )
    ET.indent(root, space="  ")
    return '<?xml version="1.0" encoding="utf-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
