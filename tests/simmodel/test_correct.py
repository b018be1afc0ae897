"""A simulator description corrected from data (dynid.simmodel.correct) on the ``rpr.urdf`` fixture.

Data are simulated from the file's own bodies with friction the file lacks (joints 1 and 2; joint 3
frictionless), or with heavier bodies than the file's and no friction, so the answer is known: the
correction recovers the friction (and keeps the file's masses), names the group that separates the file
from the robot, measures the closure to the noise floor (undefined on a joint already at it), and the
corrected file it writes holds the corrected values.  Each correction takes under a second.
"""

from __future__ import annotations

import numpy as np
import pytest

from dynid.exceptions import UsageError
from dynid.identify.columns import column_set
from dynid.sim.synthetic import random_fourier, synthetic_dataset
from dynid.simmodel.correct import GROUPS, _percent, correct_description, description_format
from dynid.simmodel.nominal import description_friction
from dynid.symbolic import load_robot
from tests.conftest import DATA

RPR = DATA / "rpr.urdf"
NOISE = 0.05
COULOMB = np.array([1.5, 4.0, 0.0])
VISCOUS = np.array([0.8, 3.0, 0.0])


@pytest.fixture(scope="module")
def robot():
    return load_robot(RPR)


def _runs(robot, *, params=None, coulomb=COULOMB, viscous=VISCOUS, armature=None, seed=5):
    """A training and a held-out run of the arm with these bodies, armature and friction (no offset)."""
    n = robot.n
    cols = column_set(robot, friction=True, armature=True)
    standard = robot.params if params is None else params
    armature = np.zeros(n) if armature is None else armature
    x = cols.P @ np.concatenate([standard, armature, coulomb, viscous, np.zeros(n)])
    rng = np.random.default_rng(seed)
    return tuple(
        synthetic_dataset(cols, x, random_fourier(robot, rng, periods=2, base_freq=0.2), rate=200, rng=rng, noise=NOISE)
        for _ in range(2)
    )


@pytest.fixture(scope="module")
def friction_runs(robot):
    return _runs(robot)


@pytest.fixture(scope="module")
def friction_fix(friction_runs, robot):
    train, held = friction_runs
    return correct_description(RPR, train, held, floor=np.full(robot.n, NOISE))


def test_the_format_is_read_from_the_suffix():
    assert description_format("a/b.urdf") == "urdf"
    assert description_format("B.URDF") == "urdf"
    assert description_format("scene.xml") == "mjcf"


def test_what_is_no_description_is_refused(friction_runs, tmp_path):
    with pytest.raises(UsageError, match="is not a simulator description"):
        correct_description(tmp_path / "model.json", *friction_runs)


def test_missing_friction_is_found_and_corrected(friction_fix):
    c = friction_fix
    assert c.format == "urdf"
    assert c.nominal["damping"] == [0.0, 0.0, 0.0] and c.nominal["frictionloss"] == [0.0, 0.0, 0.0]
    np.testing.assert_allclose(c.corrected["frictionloss"], COULOMB, atol=0.02)
    np.testing.assert_allclose(c.corrected["damping"], VISCOUS, atol=0.02)
    # the bodies were right: the masses stay the file's
    np.testing.assert_allclose(c.corrected["mass"], c.nominal["mass"], rtol=0.02)
    assert c.nominal["mass"] == [4.0, 2.5, 1.2]
    # a URDF carries no armature: none is fitted, the group does not apply
    assert c.corrected["armature"] == [0.0, 0.0, 0.0]
    groups = {g["group"]: g for g in c.groups}
    assert list(groups) == list(GROUPS)
    assert not groups["armature"]["applies"] and groups["armature"]["closure"] == 0.0
    assert groups["friction"]["closure"] == pytest.approx(1.0, abs=0.01)
    assert abs(groups["link bodies"]["closure"]) < 0.01
    # the file misses the friction by its size; corrected, it is at the noise
    assert np.all(c.rms_nominal[:2] > 1.0)
    np.testing.assert_allclose(c.rms_corrected, NOISE, rtol=0.1)
    assert c.closure_overall == pytest.approx(1.0, abs=0.01)
    np.testing.assert_allclose(c.closure[:2], 1.0, atol=0.01)
    assert np.isnan(c.closure[2])  # joint 3 was at the floor already: no gap to close
    np.testing.assert_array_equal(c.floor, NOISE)
    assert "friction offset" in {it["what"] for it in c.not_carried}
    assert c.finding().startswith("What separates the file from the robot: its friction (corrected alone, they close 100 %")


def test_closure_is_measured_to_the_floor(friction_fix):
    """The overall closure is the gap closed over the gap above the floor, in noise variances."""
    c = friction_fix
    gap = c.rms_nominal**2 - c.floor**2
    closed = c.rms_nominal**2 - c.rms_corrected**2
    assert c.closure_overall == pytest.approx(float(np.sum(closed) / np.sum(np.maximum(gap, 0.0))), rel=1e-9)
    np.testing.assert_allclose(c.closure[:2], (closed / gap)[:2], rtol=1e-9)
    figures = c.figures()
    assert figures["closure"][2] is None and figures["closure"][0] == pytest.approx(c.closure[0])
    assert figures["out"] is None and figures["checks"] is None


def test_bodies_heavier_than_the_file_s_are_found(robot):
    params = np.asarray(robot.params, dtype=float).copy()
    params[10:20] *= 1.5  # link 2: half as heavy again (its whole body: a consistent one)
    train, held = _runs(robot, params=params, coulomb=np.zeros(3), viscous=np.zeros(3), seed=8)
    c = correct_description(RPR, train, held, floor=np.full(robot.n, NOISE))
    groups = {g["group"]: g["closure"] for g in c.groups}
    assert groups["link bodies"] > 0.95 and abs(groups["friction"]) < 0.05
    assert c.corrected["mass"][1] == pytest.approx(1.5 * 2.5, rel=0.05)
    assert "its link bodies" in c.finding()
    np.testing.assert_allclose(c.rms_corrected, NOISE, rtol=0.15)


def test_a_urdf_s_link_bodies_take_an_armature_it_cannot_carry(robot):
    """Joint 1 turns about the vertical: its armature is link 1's Izz to the data.  A URDF has no armature
    field, so the fit has no armature column and the link body takes it: the corrected file closes the gap."""
    zeros = np.zeros(3)
    train, held = _runs(robot, coulomb=zeros, viscous=zeros, armature=np.array([0.2, 0.0, 0.0]), seed=11)
    c = correct_description(RPR, train, held, floor=np.full(robot.n, NOISE))
    assert c.corrected["armature"] == [0.0, 0.0, 0.0]
    assert c.rms_nominal[0] > 5 * NOISE
    assert c.rms_corrected[0] == pytest.approx(NOISE, rel=0.1)
    assert {g["group"]: g["closure"] for g in c.groups}["link bodies"] > 0.95


def test_without_a_floor_the_gap_is_measured_to_zero(friction_runs, robot):
    c = correct_description(RPR, *friction_runs)
    np.testing.assert_array_equal(c.floor, 0.0)
    assert np.all(np.isfinite(c.closure))  # every joint has a gap above zero
    np.testing.assert_allclose(c.closure[:2], 1.0, atol=0.01)


def test_the_corrected_file_holds_the_corrected_values(friction_runs, robot, tmp_path):
    out = tmp_path / "rpr_fixed.urdf"
    c = correct_description(RPR, *friction_runs, out=out, floor=np.full(robot.n, NOISE))
    assert out.is_file() and c.export is not None and c.figures()["out"] == str(out)
    assert all(check["passed"] for check in c.export.checks)
    damping, loss = description_friction(out, robot.joint_names)
    np.testing.assert_allclose(damping, c.corrected["damping"], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(loss, c.corrected["frictionloss"], rtol=1e-9, atol=1e-12)
    again = load_robot(out)
    np.testing.assert_allclose([again.params[10 * j] for j in range(robot.n)], c.corrected["mass"], rtol=1e-9)
    # scored as a description, the corrected file is at the noise
    c2 = correct_description(out, *friction_runs, floor=np.full(robot.n, NOISE))
    np.testing.assert_allclose(c2.rms_nominal, c.rms_corrected, rtol=0.02)


def test_shares_read_as_whole_percentages():
    assert _percent(0.456) == "46 %"
    assert _percent(-0.001) == "0 %"  # not "-0 %"
    assert _percent(float("nan")) == "-"
