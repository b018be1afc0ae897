"""Robot models: built-in names, URDF files, modified-DH tables, limits and bad input."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

from dynid.exceptions import RobotModelError, ShapeError
from dynid.symbolic.robot import BUILTIN_ROBOTS, load_robot, mdh_placement, standard_from_com
from tests.conftest import DATA


@pytest.mark.parametrize(("name", "n"), [("ur5", 6), ("ur10", 6), ("panda", 7)])
def test_builtin_robots_load(name, n):
    robot = load_robot(name)
    assert robot.n == n
    assert robot.params.shape == (10 * n,)
    assert np.all(robot.q_min < robot.q_max)
    assert np.all(robot.dq_max > 0) and np.all(robot.ddq_max > 0)
    assert robot.pin_model.nq == n


def test_panda_is_the_arm_without_fingers(panda):
    assert panda.joint_names == tuple(f"panda_joint{i}" for i in range(1, 8))
    # Franka's datasheet limits.
    np.testing.assert_allclose(panda.dq_max, [2.175] * 4 + [2.61] * 3)
    np.testing.assert_allclose(panda.ddq_max, [15, 7.5, 10, 12.5, 15, 20, 20])
    assert panda.tool_name == "panda_hand_tcp"


def test_limits_can_be_overridden(ur5):
    slow = ur5.with_limits(dq_max=1.0, ddq_max=[1, 2, 3, 4, 5, 6])
    np.testing.assert_array_equal(slow.dq_max, np.ones(6))
    np.testing.assert_array_equal(slow.ddq_max, [1, 2, 3, 4, 5, 6])
    np.testing.assert_array_equal(slow.q_max, ur5.q_max)
    assert slow.key == ur5.key  # limits do not change the dynamics
    via_loader = load_robot("ur5", q_min=-1.0, q_max=1.0)
    np.testing.assert_array_equal(via_loader.q_max, np.ones(6))


def test_limit_override_with_the_wrong_count_is_refused(ur5):
    with pytest.raises(ShapeError, match="dq_max has 3 values; the robot 'ur5' has 6 joints"):
        ur5.with_limits(dq_max=[1, 2, 3])


def test_zero_velocity_limit_is_refused(ur5):
    with pytest.raises(RobotModelError, match="dq_max of joint 1 of the robot 'ur5' is 0"):
        ur5.with_limits(dq_max=0.0)


def test_prismatic_urdf_loads():
    robot = load_robot(DATA / "rpr.urdf")
    assert [j.kind for j in robot.joints] == ["RZ", "PZ", "RU"]
    np.testing.assert_allclose(robot.joints[2].axis, [0, 0.6, 0.8])
    assert robot.tool_name == "flange"
    np.testing.assert_allclose(robot.q_max, [2.9, 0.4, 3.0])


def _rpy(rotation: np.ndarray) -> np.ndarray:
    return pin.rpy.matrixToRpy(rotation)


def _v(*values: float) -> str:
    """Numbers as URDF attribute text, at full precision."""
    return " ".join(repr(float(v)) for v in values)


def _urdf_from_mdh(table: dict, inertials: list[tuple[float, np.ndarray, np.ndarray]]) -> str:
    """An equivalent URDF written independently of dynid's DH code (URDF rpy, explicit matrices)."""
    j = table["joints"]
    links = ['<link name="l0"/>']
    joints = []
    for i in range(len(j["alpha"])):
        ca, sa = math.cos(j["alpha"][i]), math.sin(j["alpha"][i])
        ct, st = math.cos(j["theta"][i]), math.sin(j["theta"][i])
        rx = np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]])
        rz = np.array([[ct, -st, 0], [st, ct, 0], [0, 0, 1]])
        rot = rx @ rz
        xyz = np.array([j["a"][i], -sa * j["d"][i], ca * j["d"][i]])
        m, com, inertia = inertials[i]
        ixx, ixy, ixz, iyy, iyz, izz = (inertia[r, c] for r, c in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)))
        links.append(
            f'<link name="l{i + 1}"><inertial><origin xyz="{_v(*com)}" rpy="0 0 0"/><mass value="{_v(m)}"/>'
            f'<inertia ixx="{_v(ixx)}" ixy="{_v(ixy)}" ixz="{_v(ixz)}" iyy="{_v(iyy)}" iyz="{_v(iyz)}" '
            f'izz="{_v(izz)}"/></inertial></link>'
        )
        kind = "revolute" if j.get("type", ["R"] * 10)[i] == "R" else "prismatic"
        joints.append(
            f'<joint name="j{i + 1}" type="{kind}"><parent link="l{i}"/><child link="l{i + 1}"/>'
            f'<origin xyz="{_v(*xyz)}" rpy="{_v(*_rpy(rot))}"/><axis xyz="0 0 1"/>'
            '<limit lower="-3" upper="3" velocity="2" effort="10"/></joint>'
        )
    return '<?xml version="1.0"?><robot name="mdh">' + "".join(links) + "".join(joints) + "</robot>"


def _rnea_agree(a, b, rng, *, armature=True):
    ma, mb = a.pin_model, b.pin_model
    da, db = ma.createData(), mb.createData()
    if not armature:
        ma.armature[:] = 0
        mb.armature[:] = 0
    for _ in range(20):
        q, dq, ddq = rng.normal(size=(3, a.n))
        np.testing.assert_allclose(
            pin.rnea(ma, da, q, dq, ddq), pin.rnea(mb, db, q, dq, ddq), rtol=1e-10, atol=1e-10
        )


def test_mdh_table_and_equivalent_urdf_give_the_same_dynamics(tmp_path, rng):
    import tomllib

    path = DATA / "rrpr_mdh.toml"
    table = tomllib.loads(path.read_text())
    lk = table["links"]
    inertials = [
        (
            lk["m"][i],
            np.array([lk["cx"][i], lk["cy"][i], lk["cz"][i]]),
            np.array(
                [
                    [lk["Ixx"][i], lk["Ixy"][i], lk["Ixz"][i]],
                    [lk["Ixy"][i], lk["Iyy"][i], lk["Iyz"][i]],
                    [lk["Ixz"][i], lk["Iyz"][i], lk["Izz"][i]],
                ]
            ),
        )
        for i in range(4)
    ]
    urdf = tmp_path / "rrpr.urdf"
    urdf.write_text(_urdf_from_mdh(table, inertials))
    from_table = load_robot(path)
    from_urdf = load_robot(urdf)
    assert [j.kind for j in from_table.joints] == ["RZ", "RZ", "PZ", "RZ"]
    np.testing.assert_allclose(from_table.armature, [0.1, 0.08, 0.0, 0.01])
    _rnea_agree(from_table, from_urdf, rng, armature=False)


def test_panda_mdh_table_matches_the_urdf(tmp_path, panda, rng):
    """The Panda's modified-DH table (Gaz et al. 2019) gives the dynamics of its URDF."""
    d = [0.333, 0, 0.316, 0, 0.384, 0, 0]
    a = [0, 0, 0, 0.0825, -0.0825, 0, 0.088]
    alpha = [0, -math.pi / 2, math.pi / 2, math.pi / 2, -math.pi / 2, math.pi / 2, math.pi / 2]
    cols: dict[str, list[float]] = {
        k: [] for k in ("m", "cx", "cy", "cz", "Ixx", "Iyy", "Izz", "Ixy", "Ixz", "Iyz")
    }
    for i in range(7):
        inertia = panda.pin_model.inertias[i + 1]
        com, ic = inertia.lever, inertia.inertia
        for key, value in zip(
            cols,
            [inertia.mass, *com, ic[0, 0], ic[1, 1], ic[2, 2], ic[0, 1], ic[0, 2], ic[1, 2]],
            strict=True,
        ):
            cols[key].append(float(value))
    lines = ["[joints]", f"alpha = {alpha}", f"a = {a}", f"d = {d}", f"theta = {[0.0] * 7}", "[links]"]
    lines += [f"{k} = {v}" for k, v in cols.items()]
    table = tmp_path / "panda_mdh.toml"
    table.write_text("\n".join(lines) + "\n")
    _rnea_agree(load_robot(table), panda, rng, armature=False)


def test_a_table_with_rounded_right_angles_is_the_exact_arm(tmp_path):
    """alpha written as 1.5708 (a datasheet's rounding) is snapped, with a warning, to the exact arm's
    placements: the same joints and the same base parameters (without the snap, Ixy2R = Ixy2 - 3.67e-06*Ixy3)."""
    from dynid.exceptions import RobotModelWarning
    from dynid.symbolic import base_parameters, robot_functions

    exact_path = DATA / "rrpr_mdh.toml"
    text = exact_path.read_text()
    rounded = text.replace("-1.5707963267948966", "-1.5708").replace(" 1.5707963267948966", " 1.5708")
    assert rounded != text
    path = tmp_path / "rrpr_rounded.toml"
    path.write_text(rounded)
    with pytest.warns(RobotModelWarning, match=r"places joint\(s\) joint_2, joint_3 within 0.0001 rad of a right angle"):
        robot = load_robot(path)
    exact = load_robot(exact_path)
    for a, b in zip(robot.joints, exact.joints, strict=True):
        assert np.array_equal(a.rotation, b.rotation) and np.array_equal(a.translation, b.translation)
    assert base_parameters(robot_functions(robot)).expressions == base_parameters(robot_functions(exact)).expressions


def test_mdh_placement_is_craigs_convention():
    rot, trans = mdh_placement(alpha=0.3, a=0.2, d=0.5, theta=0.4)
    c, s = math.cos(0.3), math.sin(0.3)
    np.testing.assert_allclose(trans, [0.2, -s * 0.5, c * 0.5], atol=1e-15)
    np.testing.assert_allclose(rot[:, 2], [0, -s, c], atol=1e-15)


def test_standard_from_com_matches_pinocchio(rng):
    m, com = 2.3, rng.normal(size=3) * 0.1
    a = rng.normal(size=(3, 3))
    ic = a @ a.T + np.eye(3) * 0.1
    expected = pin.Inertia(m, com, ic).toDynamicParameters()
    np.testing.assert_allclose(standard_from_com(m, com, ic), expected, rtol=1e-12, atol=1e-14)


def test_key_depends_on_content_not_on_limits(ur5):
    heavier = ur5.with_params(params=ur5.params * 1.01)
    assert heavier.key != ur5.key
    assert load_robot("ur5").key == ur5.key


# ----------------------------------------------------------------------------- bad input
def test_unknown_robot_name_lists_the_known_ones():
    with pytest.raises(
        RobotModelError, match=r"unknown robot 'ur6'; give a built-in name \(ur5, ur10, panda\)"
    ):
        load_robot("ur6")
    assert set(BUILTIN_ROBOTS) == {"ur5", "ur10", "panda"}


def test_missing_urdf(tmp_path):
    with pytest.raises(RobotModelError, match=r"the URDF file '.*nowhere.urdf' does not exist"):
        load_robot(tmp_path / "nowhere.urdf")


def test_malformed_urdf(tmp_path):
    bad = tmp_path / "bad.urdf"
    bad.write_text("<robot name='x'><link name='a'></robot")
    with pytest.raises(
        RobotModelError, match=r"the URDF file '.*bad.urdf' could not be read .*well-formed URDF"
    ):
        load_robot(bad)


def test_urdf_without_movable_joint(tmp_path):
    still = tmp_path / "still.urdf"
    still.write_text('<?xml version="1.0"?><robot name="s"><link name="a"/></robot>')
    with pytest.raises(RobotModelError, match="has no movable joint"):
        load_robot(still)


def test_mdh_table_with_a_missing_column(tmp_path):
    text = (DATA / "rrpr_mdh.toml").read_text().replace("cy  = [-0.02, 0.0, 0.03, 0.0]\n", "")
    table = tmp_path / "no_cy.toml"
    table.write_text(text)
    with pytest.raises(RobotModelError, match=r"the table '.*no_cy.toml' has no column 'links.cy'"):
        load_robot(table)


def test_mdh_table_with_a_short_column(tmp_path):
    text = (DATA / "rrpr_mdh.toml").read_text().replace("m   = [5.0, 3.5, 2.0, 0.8]", "m = [5.0, 3.5]")
    table = tmp_path / "short.toml"
    table.write_text(text)
    with pytest.raises(
        RobotModelError, match=r"column 'links.m' of the table .* has 2 values; the table has 4 joints"
    ):
        load_robot(table)


def test_mdh_table_with_bad_toml(tmp_path):
    table = tmp_path / "broken.toml"
    table.write_text("[joints\nalpha = [0")
    with pytest.raises(RobotModelError, match="is not valid TOML"):
        load_robot(table)


def test_state_of_the_wrong_size(ur5):
    with pytest.raises(ShapeError, match=r"q has 7 columns; the robot 'ur5' has 6 joints"):
        ur5.check_state("q", np.zeros((10, 7)))
    with pytest.raises(ShapeError, match=r"q has 5 values; the robot 'ur5' has 6 joints"):
        ur5.check_state("q", np.zeros(5), batch=False)


def _ur5_text() -> str:
    from dynid.symbolic.robot import example_robot_data_dir

    return (example_robot_data_dir() / "ur_description" / "urdf" / "ur5_robot.urdf").read_text()


def test_a_zero_joint_axis_is_refused_in_one_sentence(tmp_path):
    path = tmp_path / "axis0.urdf"
    path.write_text(_ur5_text().replace('<axis xyz="0 0 1"/>', '<axis xyz="0 0 0"/>', 1))
    with pytest.raises(RobotModelError, match=r"has the axis xyz=\"0 0 0\"; give a non-zero direction"):
        load_robot(path)


def test_continuous_joints_are_identified_as_revolute_joints_of_one_turn_and_export_as_they_were(tmp_path):
    """A URDF of continuous joints (Pinocchio: a cosine and a sine per angle) loads with one angle per
    joint, a range of a turn each way and a warning; its model has the revolute file's dynamics, and the
    export writes the joints back as continuous and passes its reload check."""
    import warnings

    from dynid.exceptions import RobotModelWarning
    from dynid.identify.columns import column_set
    from dynid.identify.model import identify
    from dynid.sim.synthetic import random_fourier, synthetic_dataset, true_parameters
    from dynid.simmodel import export_model
    from dynid.symbolic.robot import CONTINUOUS_RANGE

    text = _ur5_text()
    revolute = tmp_path / "ur5.urdf"
    revolute.write_text(text)
    continuous = tmp_path / "ur5_continuous.urdf"
    continuous.write_text(text.replace('type="revolute"', 'type="continuous"'))
    with pytest.warns(RobotModelWarning, match=r"continuous joint\(s\) shoulder_pan_joint, .*one turn each way"):
        robot = load_robot(continuous)
    same = load_robot(revolute)
    assert robot.n == same.n == 6
    np.testing.assert_array_equal(robot.q_max, CONTINUOUS_RANGE)
    np.testing.assert_array_equal(robot.dq_max, same.dq_max)
    rng = np.random.default_rng(0)
    q, dq, ddq = (rng.uniform(-1, 1, (4, 6)) for _ in range(3))
    a, b = robot.pin_model, same.pin_model
    da, db = a.createData(), b.createData()
    for k in range(4):
        np.testing.assert_allclose(
            pin.rnea(a, da, q[k], dq[k], ddq[k]), pin.rnea(b, db, q[k], dq[k], ddq[k]), rtol=1e-12, atol=1e-12
        )
    cols = column_set(robot)
    data = synthetic_dataset(
        cols, true_parameters(cols, rng), random_fourier(robot, rng), rate=100, rng=rng, noise=0.05
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = identify(robot, data, method="ols", friction="linear", gmm="off")
        result = export_model(model, "urdf", tmp_path / "out.urdf")
    assert all(c["passed"] for c in result.checks)
    assert (tmp_path / "out.urdf").read_text().count('type="continuous"') == 6
