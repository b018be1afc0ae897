"""Pinocchio's algorithms on CasADi symbols against numeric Pinocchio, on random states."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from dynid.exceptions import CompilerNotFoundError
from dynid.symbolic import load_robot, robot_functions
from dynid.symbolic.build import find_compiler
from tests.conftest import DATA

ROBOTS = ["ur5", "panda", str(DATA / "rpr.urdf"), str(DATA / "rrpr_mdh.toml")]


def _states(robot, rng, m=25):
    q = rng.uniform(robot.q_min, robot.q_max, size=(m, robot.n))
    dq = rng.normal(size=(m, robot.n))
    ddq = rng.normal(size=(m, robot.n)) * 3
    return q, dq, ddq


@pytest.fixture(scope="module", params=ROBOTS, ids=["ur5", "panda", "rpr_urdf", "rrpr_mdh"])
def robot(request):
    base = load_robot(request.param)
    # Give every joint a rotor inertia, so that the armature is exercised everywhere.
    return base.with_params(armature=np.linspace(0.05, 0.2, base.n))


def test_regressor_times_parameters_is_rnea(robot, rng):
    funcs = robot_functions(robot)
    model, data = robot.pin_model, robot.pin_model.createData()
    q, dq, ddq = _states(robot, rng)
    Y = funcs.regressor_numeric(q, dq, ddq)
    assert Y.shape == (len(q), robot.n, 10 * robot.n)
    for k in range(len(q)):
        expected = pin.rnea(model, data, q[k], dq[k], ddq[k])
        # Pinocchio's rnea adds armature * ddq; the regressor does not.
        np.testing.assert_allclose(
            Y[k] @ robot.params + robot.armature * ddq[k], expected, rtol=1e-11, atol=1e-11
        )


def test_regressor_equals_numeric_pinocchio_regressor(robot, rng):
    funcs = robot_functions(robot)
    model, data = robot.pin_model, robot.pin_model.createData()
    q, dq, ddq = _states(robot, rng)
    Y = funcs.regressor_numeric(q, dq, ddq)
    for k in range(len(q)):
        expected = pin.computeJointTorqueRegressor(model, data, q[k], dq[k], ddq[k])
        np.testing.assert_allclose(Y[k], expected, rtol=1e-12, atol=1e-12)


def test_dynamics_functions_match_numeric_pinocchio(robot, rng):
    funcs = robot_functions(robot)
    model, data = robot.pin_model, robot.pin_model.createData()
    q, dq, ddq = _states(robot, rng, m=10)
    tau = funcs.evaluate("rnea", q, dq, ddq)
    g = funcs.evaluate("gravity", q)
    M = funcs.evaluate("mass_matrix", q)
    acc = funcs.evaluate("aba", q, dq, tau)
    for k in range(len(q)):
        np.testing.assert_allclose(tau[k], pin.rnea(model, data, q[k], dq[k], ddq[k]), atol=1e-10)
        np.testing.assert_allclose(g[k], pin.computeGeneralizedGravity(model, data, q[k]), atol=1e-10)
        Mk = pin.crba(model, data, q[k])
        Mk = np.triu(Mk) + np.triu(Mk, 1).T
        np.testing.assert_allclose(M[k], Mk, atol=1e-10)
        np.testing.assert_allclose(acc[k], ddq[k], atol=1e-8)  # aba inverts rnea


def test_forward_kinematics_of_the_tool_frame(rng):
    robot = load_robot("ur5")
    funcs = robot_functions(robot)
    from dynid.symbolic.robot import example_robot_data_dir

    full = pin.buildModelFromUrdf(str(example_robot_data_dir() / "ur_description/urdf/ur5_robot.urdf"))
    data = full.createData()
    q = rng.uniform(-3, 3, size=(10, 6))
    p, R = funcs.evaluate("fk", q)
    for k in range(len(q)):
        pin.framesForwardKinematics(full, data, q[k])
        frame = data.oMf[full.getFrameId("tool0")]
        np.testing.assert_allclose(p[k], frame.translation, atol=1e-12)
        np.testing.assert_allclose(R[k], frame.rotation, atol=1e-12)


def test_friction_and_armature_columns(rng):
    robot = load_robot("ur5")
    funcs = robot_functions(robot)
    dq = rng.normal(size=6)
    F = np.asarray(funcs.friction_columns(dq))
    assert F.shape == (6, 18)
    fc, fv, fo = rng.uniform(0.1, 1, size=(3, 6))
    np.testing.assert_allclose(F @ np.concatenate([fc, fv, fo]), fc * np.sign(dq) + fv * dq + fo, atol=1e-14)
    ddq = rng.normal(size=6)
    np.testing.assert_allclose(np.asarray(funcs.armature_columns(ddq)), np.diag(ddq))


def test_functions_are_named_with_named_inputs():
    funcs = robot_functions(load_robot("ur5"))
    assert funcs.regressor.name() == "regressor"
    assert funcs.regressor.name_in() == ["q", "dq", "ddq"]
    assert funcs.regressor.name_out() == ["Y"]
    assert funcs.fk.name_out() == ["p", "R"]


def test_second_request_is_served_from_the_cache():
    robot = load_robot("ur5")
    first = robot_functions(robot).folder
    mtime = (first / "regressor.casadi").stat().st_mtime_ns
    again = robot_functions(load_robot("ur5"), progress=None)
    assert again.folder == first
    assert (first / "regressor.casadi").stat().st_mtime_ns == mtime  # not regenerated


def test_a_missing_compiler_is_reported_clearly(monkeypatch, tmp_path):
    monkeypatch.setenv("PATH", str(tmp_path))
    monkeypatch.delenv("CXX", raising=False)
    with pytest.raises(CompilerNotFoundError, match=r"no C\+\+ compiler was found .*apt-get install g\+\+"):
        find_compiler("c++")
    monkeypatch.delenv("CC", raising=False)
    with pytest.raises(CompilerNotFoundError, match=r"no C compiler was found .*apt-get install gcc"):
        find_compiler("c")
