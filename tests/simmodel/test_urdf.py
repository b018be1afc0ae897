"""URDF writing (dynid.simmodel.urdf): templates read, matched and filled, and a URDF of a modified-DH table.

On the small fixtures (``rpr.urdf``: revolute, prismatic and a tilted revolute joint, a fixed flange;
``rrpr_mdh.toml``): what is written reloads in Pinocchio and in dynid's loader with the bodies and friction
written (checked against Pinocchio's own inertia conversions), a fixed link's body is merged onto its
joint's link, the template's other content stays, attribute text is escaped, and what is no URDF of the
robot (missing file, broken XML, another root, other joints or placements, a body that is no physical body)
is refused in one sentence.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pinocchio as pin
import pytest

from dynid.exceptions import UsageError
from dynid.simmodel.urdf import _inertial, _rpy, match_template, read_template, robot_urdf, write_urdf
from dynid.symbolic import load_robot
from dynid.symbolic.robot import pin_model_from_urdf
from tests.conftest import DATA

RPR = DATA / "rpr.urdf"


@pytest.fixture(scope="module")
def rpr():
    return load_robot(RPR)


def _bodies(path) -> np.ndarray:
    """Standard parameters (10 n) of a URDF's joints as Pinocchio reads them (fixed links merged)."""
    model = pin_model_from_urdf(path)
    return np.concatenate([model.inertias[i].toDynamicParameters() for i in range(1, model.njoints)])


def _params(robot, scale=1.0):
    """Values to write: the robot's bodies with the masses (and so every parameter) scaled, and friction."""
    n = robot.n
    return SimpleNamespace(
        standard=scale * np.asarray(robot.params, dtype=float),
        damping=0.1 * np.arange(1, n + 1),
        frictionloss=0.5 + 0.25 * np.arange(n),
    )


def _parsed(path) -> ET.Element:
    """The root of a written file, its comments kept."""
    return ET.parse(path, parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))).getroot()


def _written(tmp_path, template, robot, params, comment=" dynid export (urdf) of a test. "):
    root = read_template(template)
    match = match_template(root, template, robot)
    out = tmp_path / "out.urdf"
    out.write_text(write_urdf(root, match, robot, params, comment), encoding="utf-8")
    return out


# ---------------------------------------------------------------------------- one body
def test_an_inertial_holds_the_centre_of_mass_and_the_inertia_about_it(rng):
    m, c = 2.5, np.array([0.1, -0.2, 0.05])
    A = rng.normal(size=(3, 3))
    Ic = A @ A.T + 0.1 * np.eye(3)  # any positive definite inertia about the centre of mass
    standard = pin.Inertia(m, c, Ic).toDynamicParameters()  # m, m c, inertia about the link frame
    el = _inertial(standard)
    assert float(el.find("mass").get("value")) == m
    np.testing.assert_allclose([float(v) for v in el.find("origin").get("xyz").split()], c, rtol=1e-12)
    assert el.find("origin").get("rpy") == "0 0 0"
    got = {k: float(v) for k, v in el.find("inertia").attrib.items()}
    for (i, j), key in {(0, 0): "ixx", (0, 1): "ixy", (0, 2): "ixz", (1, 1): "iyy", (1, 2): "iyz", (2, 2): "izz"}.items():
        assert got[key] == pytest.approx(Ic[i, j], rel=1e-12, abs=1e-14)


def test_rpy_inverts_the_urdf_rotation(rng):
    for _ in range(20):
        R = pin.rpy.rpyToMatrix(*rng.uniform(-math.pi, math.pi, 3))
        np.testing.assert_allclose(pin.rpy.rpyToMatrix(*_rpy(R)), R, atol=1e-12)
    for pitch in (math.pi / 2, -math.pi / 2):  # gimbal lock: roll and yaw are one angle
        R = pin.rpy.rpyToMatrix(0.3, pitch, -0.7)
        # (arcsin of R[2, 0] = -(1 - 2e-16) loses half the digits there: 3e-8 rad)
        np.testing.assert_allclose(pin.rpy.rpyToMatrix(*_rpy(R)), R, atol=1e-7)


# ---------------------------------------------------------------------------- templates
def test_a_template_is_read_with_its_comments_and_meshes_found_from_anywhere(tmp_path):
    text = RPR.read_text().replace(
        '<link name="flange"/>',
        '<link name="flange"><visual><geometry><mesh filename="meshes/f.stl"/></geometry></visual>'
        '<collision><geometry><mesh filename="package://arm/f.stl"/></geometry></collision></link>',
    )
    (tmp_path / "tpl").mkdir()
    path = tmp_path / "tpl" / "rpr.urdf"
    path.write_text(text)
    root = read_template(path)
    assert root.tag == "robot"
    assert [c.text for c in root if c.tag is ET.Comment] == []  # the comment before <robot> is outside it
    meshes = [m.get("filename") for m in root.iter("mesh")]
    assert meshes == [str((tmp_path / "tpl" / "meshes" / "f.stl").resolve()), "package://arm/f.stl"]


@pytest.mark.parametrize(
    ("content", "pattern"),
    [
        (None, "does not exist"),
        ("<robot name='x'><link name='a'></robot>", "not well-formed XML"),
        ("<mujoco model='x'/>", r"root element <mujoco>, not <robot>"),
    ],
)
def test_what_is_no_urdf_is_refused(tmp_path, content, pattern):
    path = tmp_path / "t.urdf"
    if content is not None:
        path.write_text(content)
    with pytest.raises(UsageError, match=pattern):
        read_template(path)


def test_a_template_is_matched_to_its_own_robot(rpr):
    m = match_template(read_template(RPR), RPR, rpr)
    assert [j.get("name") for j in m.joint_elements] == ["j1", "j2", "j3"]
    assert m.child_links == ["link1", "link2", "link3"]
    assert m.fixed_links == [[], [], ["flange"]]
    assert m.locked == []
    np.testing.assert_allclose(m.template_params, rpr.params, rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(m.locked_share, 0.0)
    np.testing.assert_array_equal(m.template_armature, 0.0)


@pytest.mark.parametrize(
    ("old", "new", "pattern"),
    [
        ('joint name="j2"', 'joint name="jx"', "has no joint 'j2'"),
        (
            '<origin xyz="0 0 0.1" rpy="0.3 0 0"/>',
            '<origin xyz="0 0 0.1001" rpy="0.3 0 0"/>',
            r"sits elsewhere .*\(its offset differs by 0.0001 m\)",
        ),
        (  # the same placement on another link
            '<parent link="link2"/><child link="link3"/>',
            '<parent link="link1"/><child link="link3"/>',
            r"j3.*sits elsewhere.*\(its parent differs\)",
        ),
        pytest.param(
            '<axis xyz="0 0 1"/>\n    <limit lower="-2.9"',
            '<axis xyz="1 0 0"/>\n    <limit lower="-2.9"',
            r"j1' turns about another axis.*template revolute about \(1, 0, 0\), model revolute about \(0, 0, 1\)",
            id="j1 about x, not z",
        ),
        pytest.param(
            '<axis xyz="0 0.6 0.8"/>',
            '<axis xyz="0 0.8 0.6"/>',
            "j3' turns about another axis",
            id="j3 about another unaligned axis",
        ),
    ],
)
def test_a_template_of_another_robot_is_refused(tmp_path, rpr, old, new, pattern):
    text = RPR.read_text()
    assert old in text
    path = tmp_path / "other.urdf"
    path.write_text(text.replace(old, new))
    with pytest.raises(UsageError, match=pattern):
        match_template(read_template(path), path, rpr)


def test_a_template_with_a_sub_micrometre_offset_is_its_own_robot(tmp_path):
    """A CAD file's offset of 5e-8 m where 0 was meant: the loader snaps it to 0, and the file itself is still
    the template of the robot it describes (the match allowed 1e-9 m and refused the user's own URDF)."""
    text = RPR.read_text()
    old = '<origin xyz="0 0 0.1" rpy="0.3 0 0"/>'
    assert old in text
    path = tmp_path / "cad.urdf"
    path.write_text(text.replace(old, '<origin xyz="5e-08 0 0.1" rpy="0.3 0 0"/>'))
    robot = load_robot(path)
    assert any(np.array_equal(j.translation, [0.0, 0.0, 0.1]) for j in robot.joints)  # snapped
    m = match_template(read_template(path), path, robot)
    assert [j.get("name") for j in m.joint_elements] == ["j1", "j2", "j3"]


# ---------------------------------------------------------------------------- writing
def test_the_written_bodies_and_friction_reload_in_pinocchio_and_dynid(tmp_path, rpr):
    params = _params(rpr, scale=1.3)
    out = _written(tmp_path, RPR, rpr, params)
    np.testing.assert_allclose(_bodies(out), params.standard, rtol=1e-12, atol=1e-14)
    model = pin_model_from_urdf(out)
    np.testing.assert_allclose(model.damping, params.damping)
    np.testing.assert_allclose(model.friction, params.frictionloss)
    again = load_robot(out)
    assert again.joint_names == rpr.joint_names
    np.testing.assert_allclose(again.params, params.standard, rtol=1e-12, atol=1e-14)
    # the template's kinematics and limits are kept
    for a, b in zip(again.joints, rpr.joints, strict=True):
        np.testing.assert_allclose(a.translation, b.translation, atol=1e-12)
        np.testing.assert_allclose(a.rotation, b.rotation, atol=1e-12)
    np.testing.assert_allclose(again.q_max, rpr.q_max)
    first = _parsed(out)[0]
    assert first.tag is ET.Comment and "dynid export" in first.text
    assert out.read_text().startswith('<?xml version="1.0" encoding="utf-8"?>')


def test_a_second_export_replaces_the_first_comment(tmp_path, rpr):
    once = _written(tmp_path, RPR, rpr, _params(rpr))
    (tmp_path / "again").mkdir()
    twice = _written(tmp_path / "again", once, rpr, _params(rpr, 1.1), comment=" dynid export (urdf) again. ")
    comments = [c.text for c in _parsed(twice) if c.tag is ET.Comment]
    assert comments == [" dynid export (urdf) again. "]
    joints = ET.parse(twice).getroot().findall("joint")
    assert all(len(j.findall("dynamics")) == 1 for j in joints if j.get("type") != "fixed")


def test_a_fixed_link_s_body_goes_onto_its_joint_s_link(tmp_path):
    """A flange with a body of its own: dynid merges it into link 3; the file gets the merged body on
    link 3 and none on the flange, and reads back as the same robot."""
    flange = (
        '<link name="flange"><inertial><origin xyz="0.0 0.01 0.02" rpy="0 0 0"/><mass value="0.3"/>'
        '<inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.0005"/></inertial></link>'
    )
    template = tmp_path / "tpl.urdf"
    template.write_text(RPR.read_text().replace('<link name="flange"/>', flange))
    robot = load_robot(template)
    assert robot.params[20] == pytest.approx(1.2 + 0.3)  # merged
    params = _params(robot, scale=0.9)
    out = _written(tmp_path, template, robot, params)
    links = {lk.get("name"): lk for lk in ET.parse(out).getroot().findall("link")}
    assert links["flange"].find("inertial") is None
    assert float(links["link3"].find("inertial/mass").get("value")) == pytest.approx(0.9 * 1.5)
    np.testing.assert_allclose(_bodies(out), params.standard, rtol=1e-12, atol=1e-14)


def test_a_body_that_is_no_physical_body_is_refused(tmp_path, rpr):
    params = _params(rpr)
    params.standard = params.standard.copy()
    params.standard[10] = -1.0  # joint 2's body: a negative mass
    root = read_template(RPR)
    with pytest.raises(UsageError, match=r"the identified body of joint 'j2'.*is not a physical body"):
        write_urdf(root, match_template(root, RPR, rpr), rpr, params, "x")
    params.standard = np.asarray(rpr.params, dtype=float).copy()
    params.standard[24:27] = [1.0, 0.0, 0.0]  # joint 3: Ixx, Ixy, Iyy of 1, 0, 0 with Izz tiny: no body
    with pytest.raises(UsageError, match="joint 'j3'"):
        write_urdf(root, match_template(root, RPR, rpr), rpr, params, "x")


@pytest.mark.parametrize("comment", [" written with --format urdf ", " joint a---b ", " ends in a hyphen -"])
def test_a_comment_with_hyphens_still_gives_well_formed_xml(tmp_path, rpr, comment):
    """XML forbids '--' in a comment and a comment ending in '-': a joint name or option may hold them."""
    out = _written(tmp_path, RPR, rpr, _params(rpr), comment=comment)
    ET.parse(out)
    text = out.read_text()
    body = text[text.index("<!--") + 4 : text.index("-->")]
    assert "--" not in body and not body.endswith("-")
    assert body.replace("- -", "--").replace("- -", "--").strip() == comment.strip()


# ---------------------------------------------------------------------------- a URDF of a table robot
def test_a_table_robot_gets_a_urdf_with_its_kinematics_bodies_and_limits(tmp_path):
    robot = load_robot(DATA / "rrpr_mdh.toml")
    path = tmp_path / "rrpr.urdf"
    path.write_text(robot_urdf(robot), encoding="utf-8")
    model = pin_model_from_urdf(path)
    assert list(model.names)[1:] == list(robot.joint_names)
    for i, joint in enumerate(robot.joints, start=1):
        np.testing.assert_allclose(model.jointPlacements[i].translation, joint.translation, atol=1e-12)
        np.testing.assert_allclose(model.jointPlacements[i].rotation, joint.rotation, atol=1e-12)
        assert model.parents[i] == joint.parent
    np.testing.assert_allclose(_bodies(path), robot.params, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(model.lowerPositionLimit, robot.q_min)
    np.testing.assert_allclose(model.upperPositionLimit, robot.q_max)
    np.testing.assert_allclose(model.velocityLimit, robot.dq_max)
    kinds = {j.get("name"): j.get("type") for j in ET.parse(path).getroot().iter("joint")}
    assert kinds == {"joint_1": "revolute", "joint_2": "revolute", "joint_3": "prismatic", "joint_4": "revolute",
                     f"{robot.tool_name}_joint": "fixed"}
    # the same robot through dynid's loader, and its own URDF is a template of it
    again = load_robot(path)
    np.testing.assert_allclose(again.params, robot.params, rtol=1e-12, atol=1e-14)
    m = match_template(read_template(path), path, robot)
    assert m.child_links == [f"{name}_link" for name in robot.joint_names]
    # the tool frame sits where the robot's is
    fid = model.getFrameId(robot.tool_name)
    np.testing.assert_allclose(model.frames[fid].placement.translation, robot.tool_translation, atol=1e-12)


def test_the_robot_s_name_is_escaped(tmp_path):
    robot = replace(load_robot(DATA / "rrpr_mdh.toml"), name='arm & "co" <1>')
    text = robot_urdf(robot)
    assert 'name="arm &amp; &quot;co&quot; &lt;1&gt;"' in text
    assert ET.fromstring(text.split("\n", 1)[1]).get("name") == 'arm & "co" <1>'
