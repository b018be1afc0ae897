"""An MJCF built by MuJoCo from the exported URDF, with armature, damping and frictionloss set.

MuJoCo loads the URDF itself (``<mujoco><compiler fusestatic="false" discardvisual="true"
balanceinertia="false"/></mujoco>`` inside ``<robot>``; visual and collision elements are left out,
because MuJoCo's URDF importer cannot resolve ``package://`` meshes), the joint parameters are set on
the compiled ``mjModel`` (``dof_armature``, ``dof_damping``, ``dof_frictionloss``) and
``mj_saveLastXML`` writes the MJCF.  That writer rounds numbers to 6 significant digits, so the bodies'
placements, inertials and the joint parameters are then written again from the ``mjModel`` at full
precision (the reload check needs 1e-6 relative).  ``mujoco`` is an optional dependency
(``pip install dynid[mujoco]``).

An MJCF template (:func:`write_into_mjcf`) is changed in place through MuJoCo's ``MjSpec`` instead, so
its meshes, geoms, actuators and defaults stay: each moving joint's body gets the identified body (the
joint frame is the body frame moved to the joint's ``pos``; bodies welded below it lose their mass, as
Pinocchio merges them), each joint its armature, damping and frictionloss.
"""

from __future__ import annotations

import os
import tempfile
import xml.etree.ElementTree as ET

import numpy as np

from dynid._extras import install_hint
from dynid.exceptions import UsageError

__all__ = ["build_mjcf", "import_mujoco", "write_into_mjcf"]


def import_mujoco():
    """The ``mujoco`` module, or one sentence saying how to install it."""
    try:
        import mujoco
    except ImportError:
        raise UsageError(
            "--format mjcf needs the package mujoco, which is not installed; install it with "
            f"{install_hint('mujoco')}"
        ) from None
    return mujoco


def _nums(values) -> str:
    return " ".join(repr(float(v)) for v in np.asarray(values, dtype=float).ravel())


def build_mjcf(urdf_text: str, robot, params, comment: str) -> str:
    """The MJCF of an exported URDF, built by MuJoCo.

    Parameters
    ----------
    urdf_text : str
        The exported URDF (:func:`dynid.simmodel.urdf.write_urdf`).
    robot : RobotModel
        The model's robot (joint names, gravity).
    params : SimParameters
        Armature (kg m^2), damping (N m s/rad) and frictionloss (N m) per joint.
    comment : str
        Text of the comment put first inside ``<mujoco>``.

    Returns
    -------
    str
        The MJCF text.
    """
    mujoco = import_mujoco()
    root = ET.fromstring(urdf_text)
    for link in root.findall("link"):
        for tag in ("visual", "collision"):
            for el in link.findall(tag):
                link.remove(el)
    for old in root.findall("mujoco"):
        root.remove(old)
    for el in list(root):
        if el.tag is ET.Comment:
            root.remove(el)
    mj = ET.SubElement(root, "mujoco")
    ET.SubElement(
        mj, "compiler", {"fusestatic": "false", "discardvisual": "true", "balanceinertia": "false"}
    )
    try:
        m = mujoco.MjModel.from_xml_string(ET.tostring(root, encoding="unicode"))
    except ValueError as err:
        raise UsageError(f"MuJoCo cannot load the robot description ({err}); check the template URDF") from None
    for i, name in enumerate(robot.joint_names):
        jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)
        dof = int(m.jnt_dofadr[jid])
        m.dof_armature[dof] = params.armature[i]
        m.dof_damping[dof] = params.damping[i]
        m.dof_frictionloss[dof] = params.frictionloss[i]
    m.opt.gravity[:] = robot.gravity
    fd, tmp = tempfile.mkstemp(suffix=".xml")
    os.close(fd)
    try:
        mujoco.mj_saveLastXML(tmp, m)
        with open(tmp, encoding="utf-8") as handle:
            text = handle.read()
    finally:
        os.unlink(tmp)
    out = ET.fromstring(text)
    for body in out.iter("body"):
        bid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, body.get("name", ""))
        if bid < 0:
            continue
        body.set("pos", _nums(m.body_pos[bid]))
        body.set("quat", _nums(m.body_quat[bid]))
        inertial = body.find("inertial")
        if inertial is not None:
            inertial.set("pos", _nums(m.body_ipos[bid]))
            inertial.set("quat", _nums(m.body_iquat[bid]))
            inertial.set("mass", _nums(m.body_mass[bid]))
            inertial.set("diaginertia", _nums(m.body_inertia[bid]))
    for joint in out.iter("joint"):
        jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, joint.get("name", ""))
        if jid < 0:
            continue
        dof = int(m.jnt_dofadr[jid])
        joint.set("axis", _nums(m.jnt_axis[jid]))
        joint.set("pos", _nums(m.jnt_pos[jid]))
        if joint.get("range") is not None:
            joint.set("range", _nums(m.jnt_range[jid]))
        for attr, arr in (
            ("armature", m.dof_armature),
            ("damping", m.dof_damping),
            ("frictionloss", m.dof_frictionloss),
        ):
            joint.set(attr, _nums(arr[dof]))
    option = out.find("option")
    if option is None:
        option = ET.Element("option")
        out.insert(0, option)
    option.set("gravity", _nums(robot.gravity))
    out.insert(0, ET.Comment(comment))
    ET.indent(out, space="  ")
    return ET.tostring(out, encoding="unicode") + "\n"


def _welded(body) -> list:
    """Bodies welded to ``body`` (no joint of their own), recursively."""
    out = []
    for child in body.bodies:
        if len(child.joints) == 0:
            out.append(child)
            out.extend(_welded(child))
    return out


def write_into_mjcf(template, robot, params, comment: str) -> str:
    """The identified values written into an MJCF template (see the module docstring).

    Parameters
    ----------
    template : str or Path
        The MJCF to copy; its moving joints must be the model's (names, kinematics).
    robot : RobotModel
        The model's robot.
    params : SimParameters
        The values to write.
    comment : str
        Text of the comment put first inside ``<mujoco>``.

    Returns
    -------
    str
        The MJCF text.

    Raises
    ------
    UsageError
        A template MuJoCo cannot read, another robot, a body with several joints.
    """
    from dynid.symbolic.robot import load_robot

    mujoco = import_mujoco()
    try:
        spec = mujoco.MjSpec.from_file(str(template))
    except ValueError as err:
        raise UsageError(f"MuJoCo cannot read the template '{template}' ({err}); give a MuJoCo .xml") from None
    other = load_robot(template)
    if other.joint_names != robot.joint_names:
        raise UsageError(
            f"the template '{template}' has the moving joints {', '.join(other.joint_names)}; the model has "
            f"{', '.join(robot.joint_names)}; give the MJCF of the robot the model was identified for"
        )
    for a, b in zip(robot.joints, other.joints, strict=True):
        off = max(float(np.abs(a.rotation - b.rotation).max()), float(np.abs(a.translation - b.translation).max()))
        if off > 1e-6 or a.parent != b.parent:
            raise UsageError(
                f"the joint '{a.name}' sits elsewhere in the template '{template}' than in the model (placement "
                f"differs by {off:.3g}): the template describes another robot; give the MJCF of the same robot"
            )
    folder = os.path.dirname(os.path.abspath(str(template)))
    for attr in ("meshdir", "texturedir"):  # the copy is written elsewhere: its assets by absolute paths
        value = getattr(spec, attr, "") or ""
        setattr(spec, attr, os.path.normpath(os.path.join(folder, value)))
    if spec.compiler.inertiafromgeom == mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_TRUE:
        spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_AUTO
    for i, name in enumerate(robot.joint_names):
        joint = spec.joint(name)
        body = joint.parent
        if len(body.joints) != 1:
            raise UsageError(
                f"the body '{body.name}' of the template holds {len(body.joints)} joints; dynid writes one body "
                "per joint: give each joint a body of its own"
            )
        v = params.standard[10 * i : 10 * i + 10]
        m = float(v[0])
        c = v[1:4] / m
        Io = np.array([[v[4], v[5], v[7]], [v[5], v[6], v[8]], [v[7], v[8], v[9]]])
        Ic = Io - m * (float(c @ c) * np.eye(3) - np.outer(c, c))
        w, V = np.linalg.eigh(0.5 * (Ic + Ic.T))
        if np.linalg.det(V) < 0:
            V[:, 0] *= -1
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, V.flatten())
        body.explicitinertial = True
        body.mass = m
        body.ipos = c + np.asarray(joint.pos, dtype=float)
        body.iquat = quat
        body.inertia = w
        for welded in _welded(body):
            welded.explicitinertial = True
            welded.mass = 0.0
            welded.inertia = [0.0, 0.0, 0.0]
        joint.armature = float(params.armature[i])
        damping = np.array(joint.damping, dtype=float).ravel()  # MuJoCo 4: [linear, higher orders...]
        if damping.size > 1 and np.any(damping[1:] != 0):
            raise UsageError(
                f"the joint '{name}' of the template has nonlinear damping {damping.tolist()}; dynid writes a "
                "linear viscous coefficient: set the joint's damping to one value"
            )
        damping[0] = float(params.damping[i])
        joint.damping = damping if damping.size > 1 else float(damping[0])
        joint.frictionloss = float(params.frictionloss[i])
    try:
        model = spec.compile()
    except ValueError as err:
        raise UsageError(f"MuJoCo cannot compile the template with the identified values ({err})") from None
    root = ET.fromstring(spec.to_xml())
    for body in root.iter("body"):  # full precision again, from the compiled model
        name = body.get("name")
        if name is None or mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name) < 0:
            continue
        bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
        inertial = body.find("inertial")
        if inertial is not None:
            inertial.set("pos", _nums(model.body_ipos[bid]))
            inertial.set("quat", _nums(model.body_iquat[bid]))
            inertial.set("mass", _nums(model.body_mass[bid]))
            inertial.set("diaginertia", _nums(model.body_inertia[bid]))
            inertial.attrib.pop("fullinertia", None)
    for joint in root.iter("joint"):
        name = joint.get("name")
        if name in robot.joint_names:
            i = robot.joint_names.index(name)
            joint.set("armature", _nums(params.armature[i]))
            joint.set("damping", _nums(params.damping[i]))
            joint.set("frictionloss", _nums(params.frictionloss[i]))
    for old in [c for c in list(root) if c.tag is ET.Comment and "dynid export" in (c.text or "")]:
        root.remove(old)
    root.insert(0, ET.Comment(comment))
    return ET.tostring(root, encoding="unicode") + "\n"
