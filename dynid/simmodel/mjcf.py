"""An MJCF built by MuJoCo from the exported URDF, with armature, damping and frictionloss set.

MuJoCo loads the URDF itself (``<mujoco><compiler fusestatic="false" discardvisual="true"
balanceinertia="false"/></mujoco>`` inside ``<robot>``; visual and collision elements are left out,
because MuJoCo's URDF importer cannot resolve ``package://`` meshes), the joint parameters are set on
the compiled ``mjModel`` (``dof_armature``, ``dof_damping``, ``dof_frictionloss``) and
``mj_saveLastXML`` writes the MJCF.  That writer rounds numbers to 6 significant digits, so the bodies'
placements, inertials and the joint parameters are then written again from the ``mjModel`` at full
precision (the reload check needs 1e-6 relative).  ``mujoco`` is an optional dependency
(``pip install dynid[mujoco]``).
"""

from __future__ import annotations

import os
import tempfile
import xml.etree.ElementTree as ET

import numpy as np

from dynid.exceptions import UsageError

__all__ = ["build_mjcf", "import_mujoco"]


def import_mujoco():
    """The ``mujoco`` module, or one sentence saying how to install it."""
    try:
        import mujoco
    except ImportError:
        raise UsageError(
            "--format mjcf needs the package mujoco, which is not installed; install it with "
            "'pip install dynid[mujoco]'"
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
