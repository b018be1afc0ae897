"""What an export loses, measured on held-out data (dynid.simmodel.shares.heldout_shares).

A model of the ``rpr.urdf`` arm identified on simulated data whose truth has an armature (which URDF
cannot carry), torque offsets (which no format carries) and, in one case, a Stribeck friction taken as an
effect term: each lost part's held-out RMS is the noise with that part's own torque added, computed here
from the simulated truth; the parts add up to the full prediction; the full model's RMS is what
``validate`` reports.  Identification of the 3-joint arm takes a fraction of a second.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from dynid.identify.columns import column_set
from dynid.identify.model import identify
from dynid.sim.synthetic import random_fourier, synthetic_dataset
from dynid.simmodel.parameters import simulator_parameters
from dynid.simmodel.shares import heldout_shares
from dynid.symbolic import load_robot
from dynid.validation.validate import validate
from tests.conftest import DATA

NOISE = 0.02
ARMATURE = np.array([0.2, 0.0, 0.05])
OFFSET = np.array([0.4, -0.3, 0.0])
FRICTION = "friction beyond Coulomb + viscous (offset, Stribeck, asymmetry, nonlinear)"


def _stribeck(q, dq):
    out = np.zeros_like(dq)
    out[:, 1] = 0.5 * np.sign(dq[:, 1]) * np.exp(-((dq[:, 1] / 0.05) ** 2))
    return out


@pytest.fixture(scope="module")
def arm():
    """(robot, train, held): runs of the arm with armature, Coulomb, viscous friction and offsets."""
    robot = load_robot(DATA / "rpr.urdf")
    cols = column_set(robot, friction=True, armature=True)
    x = cols.P @ np.concatenate([robot.params, ARMATURE, [1.0, 2.0, 0.5], [0.5, 1.0, 0.2], OFFSET])
    rng = np.random.default_rng(5)
    train, held = (
        synthetic_dataset(cols, x, random_fourier(robot, rng, periods=2, base_freq=0.2), rate=200, rng=rng, noise=NOISE)
        for _ in range(2)
    )
    return robot, train, held


@pytest.fixture(scope="module")
def model(arm):
    robot, train, _ = arm
    return identify(robot, train, method="irls", friction="linear", gmm="off")


def _rms(a):
    return np.sqrt(np.mean(np.asarray(a) ** 2, axis=0))


def test_the_full_model_s_rms_is_validate_s_and_the_parts_add_up(arm, model):
    _, _, held = arm
    h = heldout_shares(model, simulator_parameters(model), "mjcf", held)
    assert h["closure"] < 1e-9
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rms = validate(model, held).figures()["rms"]
    np.testing.assert_allclose(h["rms_full"], rms, rtol=1e-9)
    np.testing.assert_allclose(h["rms_full"], NOISE, rtol=0.1)  # the model is the truth's structure
    assert h["rms_full_mean"] == pytest.approx(np.mean(h["rms_full"]))
    assert h["rms_exported_mean"] == pytest.approx(np.mean(h["rms_exported"]))
    for part in h["parts"]:
        assert part["rise_mean"] == pytest.approx(np.mean(part["rms_without"]) - h["rms_full_mean"])


def test_mjcf_loses_the_offsets_alone(arm, model):
    """MJCF carries bodies, armature, Coulomb and viscous friction: the offsets are what it loses, and the
    held-out RMS without them is the noise and the offset together."""
    _, _, held = arm
    h = heldout_shares(model, simulator_parameters(model), "mjcf", held)
    names = [p["part"] for p in h["parts"]]
    assert FRICTION in names and not any("armature" in name for name in names)
    part = next(p for p in h["parts"] if p["part"] == FRICTION)
    expected = np.sqrt(OFFSET**2 + NOISE**2)
    np.testing.assert_allclose(part["rms_without"], expected, rtol=0.05)
    np.testing.assert_allclose(h["rms_exported"], expected, rtol=0.05)
    assert part["rise_mean"] > 0.2


def test_urdf_also_loses_the_armature(arm, model):
    """Without the armature field, the rigid part's loss is the armature torque: RMS of a_j ddq_j."""
    _, _, held = arm
    h = heldout_shares(model, simulator_parameters(model), "urdf", held)
    rigid = next(p for p in h["parts"] if p["part"].startswith("rigid body"))
    assert rigid["part"] == "rigid body: consistency projection, armature (no URDF field)"
    inertia = _rms(ARMATURE * held.ddq)
    np.testing.assert_allclose(rigid["rms_without"], np.sqrt(inertia**2 + NOISE**2), rtol=0.05)
    np.testing.assert_allclose(h["rms_exported"], np.sqrt(inertia**2 + OFFSET**2 + NOISE**2), rtol=0.05)
    mjcf = heldout_shares(model, simulator_parameters(model), "mjcf", held)
    assert h["rms_exported"][0] > 1.5 * mjcf["rms_exported"][0]  # joint 1's armature is the largest
    assert h["rms_exported"][1] == pytest.approx(mjcf["rms_exported"][1], rel=0.01)  # joint 2 has none


def test_an_effect_term_is_a_part_of_its_own(arm):
    """A Stribeck friction on joint 2 in the data, held by the model as an effect term: no simulator
    carries it, and without it joint 2's held-out error is the Stribeck torque's."""
    robot, _, _ = arm
    cols = column_set(robot, friction=True, armature=True)
    x = cols.P @ np.concatenate([robot.params, ARMATURE, [1.0, 2.0, 0.5], [0.5, 1.0, 0.2], np.zeros(3)])
    rng = np.random.default_rng(9)
    train, held = (
        synthetic_dataset(
            cols, x, random_fourier(robot, rng, periods=2, base_freq=0.2), rate=200, rng=rng, noise=NOISE, extra=_stribeck
        )
        for _ in range(2)
    )
    model = identify(robot, train, method="irls", friction="linear", gmm="off", effects="stribeck@2")
    h = heldout_shares(model, simulator_parameters(model), "mjcf", held)
    assert h["closure"] < 1e-9
    part = next(p for p in h["parts"] if p["part"].startswith("effect term"))
    assert part["part"] == "effect term stribeck@2"
    lost = _rms(_stribeck(held.q, held.dq))[1]
    assert lost > 5 * NOISE
    # without the term, joint 2 is left with what the term holds: part of the Stribeck torque (the rest
    # went to the joint's Coulomb friction, which the export carries), no more than all of it; the other
    # joints are unchanged
    assert 1.5 * h["rms_full"][1] < part["rms_without"][1] <= 1.05 * np.hypot(lost, NOISE)
    assert part["rise_mean"] > 0.01
    np.testing.assert_allclose(np.delete(part["rms_without"], 1), np.delete(h["rms_full"], 1), rtol=1e-9)
