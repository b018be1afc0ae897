"""Quantised angles on an effect-free robot: no candidate significant that the verdict leaves unexplained.

The angles of a field recording are differentiated twice, so the encoder's quantisation error reaches the
baseline's prediction (and so the held-out residual) and every candidate column built from the states
(errors in the variables).  Elasticity and backlash, whose columns hold the second derivative of the
model's torque, cancel part of that error on held-out data as on training data: on an effect-free UR5
recorded as in the field (coloured torque noise, no dq logged) with 16-bit angles they gained about half a
noise variance, significant at adjusted p 1e-10 while closing a fifth of the gap, beside a verdict of
"none".  The diagnosis measures the gain a candidate makes on draws of the angles' error and takes it off
(:func:`dynid.diagnosis.screening.state_gain`).
"""

from __future__ import annotations

import numpy as np
import pytest

from dynid.diagnosis.field_cases import field_noise, run_field_case
from dynid.sim.sensors import NoiseModel

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def coarse_effect_free(ur5):
    noise = NoiseModel(**{**field_noise().to_dict(), "encoder_bits": 16})
    return run_field_case(ur5, [], level=3.0, seed=102, noise=noise)


def test_no_significant_candidate_is_left_unexplained(coarse_effect_free):
    d = coarse_effect_free["diagnosis"]
    assert d.verdict == ["none"]
    # The angles' error is large here: the excess test counts several tenths of a noise variance of it.
    assert float(np.max(d.excess["state_estimation"])) > 0.3
    loose = [r.candidate.key for r in d.ranking if r.significant and not r.accepted]
    assert loose == [], f"significant but unaccounted for: {loose}"


def test_the_state_estimation_gain_is_recorded_and_taken_off(coarse_effect_free):
    d = coarse_effect_free["diagnosis"]
    by_key = {r.candidate.key: r for r in d.ranking}
    # elasticity on joint 4 cancels part of the angles' error: that share is measured and taken off its gain
    r = by_key["elasticity@4"]
    footing = r.refit["footing"]
    share = footing[footing["decided_by"]]["state_estimation_gain"]
    assert share > 0.2
    assert r.gain < 0.2
